"""Snakemake script: convex proxies of every object of a scene."""

from phiscene.pipeline import run_proxies
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"proxies {sm.wildcards.get('method', '')} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_proxies(scene_path=sm.input.scene, out_path=sm.output[0], params=dict(sm.params.proxies),
                cache_dir=sm.params.cache_dir)
