"""Snakemake script: post-simulation drift of one scene in MuJoCo (cross-simulator check)."""

from phiscene.pipeline import run_mujoco_metrics
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"MuJoCo drift {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_mujoco_metrics(sm.input.scene, sm.input.proxies, sm.output[0], dict(sm.params.physical), dict(sm.params.sim),
                       dict(sm.params.mujoco))
