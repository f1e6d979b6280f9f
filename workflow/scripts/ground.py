"""Snakemake script: phi-Scene grounding (SDF penetration resolution + sequential settling) of one scene."""

from phiscene.pipeline import run_ground
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"{sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_ground(scene_path=sm.input.scene, topology_path=sm.input.topology, proxies_path=sm.input.proxies,
               out_scene=sm.output.scene, out_log=sm.output.log_json, assembly=dict(sm.params.assembly),
               sim=dict(sm.params.sim), cache_dir=sm.params.cache_dir, camera_path=sm.input.get("camera"))
