"""Snakemake script: per-method bar chart of one table's metrics."""

from phiscene.plugins import load_plugins
from phiscene.report import bars_figure
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"report bars {sm.params.table}", sm.log[0], sm.threads):
    load_plugins(sm.config.get("plugins"))  # table kinds registered by config plugins, in this process
    bars_figure(sm.params.table, sm.input[0], sm.output[0], kind=sm.params.kind)
