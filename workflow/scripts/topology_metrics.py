"""Snakemake script: support-edge precision/recall/F1 of one predicted graph."""

from phiscene.pipeline import run_topology_metrics
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"topology metrics {sm.wildcards.backend} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_topology_metrics(sm.input.predicted, sm.input.gt, sm.output[0])
