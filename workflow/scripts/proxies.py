"""Snakemake script: convex proxies of every object of a scene."""

from phiscene.pipeline import run_proxies
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"proxies {sm.wildcards.get('method', '')} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_proxies(sm.input.scene, sm.output[0], dict(sm.params.proxies), sm.params.cache_dir)
