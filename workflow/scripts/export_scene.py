"""Snakemake script: simulation-ready export (GLB, URDF, MJCF, support graph) of one scene + round-trip check."""

from pathlib import Path

from phiscene.io.export import run_export
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"export {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_export(sm.input.scene, sm.input.proxies, Path(sm.output.manifest).parent, dict(sm.params.sim),
               dict(sm.params.mujoco), sm.input.topology, dict(sm.params.physical), sm.params.cache_dir)
