"""Snakemake script: simulation-ready export (GLB, URDF, MJCF, support graph) of one scene + round-trip check."""

from pathlib import Path

from phiscene.io.export import run_export
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"export {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_export(scene_path=sm.input.scene, proxies_path=sm.input.proxies, out_dir=Path(sm.output.manifest).parent,
               sim=dict(sm.params.sim), mujoco=dict(sm.params.mujoco), topology_path=sm.input.topology,
               physical=dict(sm.params.physical), cache_dir=sm.params.cache_dir)
