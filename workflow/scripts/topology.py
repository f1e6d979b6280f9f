"""Snakemake script: support graph and placement order of one scene."""

from phiscene.pipeline import run_topology
from phiscene.plugins import load_plugins
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"topology {sm.wildcards.backend} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    load_plugins(sm.config.get("plugins"))  # registrations of config plugins, in this job's process
    run_topology(scene_path=sm.input.scene, out_path=sm.output[0], backend=sm.params.backend,
                 params=dict(sm.params.settings), given_path=sm.input.get("given"), attached=dict(sm.params.attached),
                 cache_dir=sm.params.cache_dir)
