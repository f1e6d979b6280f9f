"""Snakemake script: physical metrics (penetration, floating, post-simulation drift) of one scene."""

from phiscene.pipeline import run_physical_metrics
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"physical metrics {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_physical_metrics(sm.input.scene, sm.input.proxies, sm.output[0], dict(sm.params.physical),
                         dict(sm.params.sim), sm.params.cache_dir)
