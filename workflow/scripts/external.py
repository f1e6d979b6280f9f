"""Snakemake script: import another method's prediction of one scene as a method row."""

from phiscene.pipeline import run_external
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"import {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_external(pred_dir=sm.input.prediction, initial_path=sm.input.initial, out_scene=sm.output.scene,
                 out_log=sm.output.log_json, params=dict(sm.params.settings))
