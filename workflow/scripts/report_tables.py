"""Snakemake script: the paper's tables as an HTML page (or the report front page's fragment)."""

from phiscene.plugins import load_plugins
from phiscene.report import tables_html
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("report tables " + " ".join(sm.params.tables), sm.log[0], sm.threads):
    load_plugins(sm.config.get("plugins"))  # table kinds registered by config plugins, in this process
    tables_html({t: sm.input[f"csv_{t}"] for t in sm.params.tables}, sm.output[0],
                title=sm.params.title, markdown={t: sm.input[f"md_{t}"] for t in sm.params.tables},
                fragment=sm.params.fragment, kinds=sm.params.names["kinds"], titles=sm.params.names["titles"])
