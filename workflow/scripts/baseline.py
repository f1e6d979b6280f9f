"""Snakemake script: one of the paper's baselines (joint SDF, joint SDF + simulation, top-down lift) on one scene."""

from phiscene.pipeline import run_baseline
from phiscene.plugins import load_plugins
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"{sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    load_plugins(sm.config.get("plugins"))  # registrations of config plugins, in this job's process
    run_baseline(kind=sm.params.kind, scene_path=sm.input.scene, out_scene=sm.output.scene,
                 out_log=sm.output.log_json, params=dict(sm.params.settings), sim=dict(sm.params.sim),
                 cache_dir=sm.params.cache_dir, proxies_path=sm.input.get("proxies"),
                 topology_path=sm.input.get("topology"))
