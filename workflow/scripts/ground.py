"""Snakemake script: phi-Scene grounding (SDF penetration resolution + sequential settling) of one scene."""

from phiscene.pipeline import run_ground
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"{sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_ground(sm.input.scene, sm.input.topology, sm.input.proxies, sm.output.scene, sm.output.log_json,
               dict(sm.params.assembly), dict(sm.params.sim), sm.params.cache_dir)
