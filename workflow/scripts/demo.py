"""Snakemake script: perturbation demo (a ball thrown into the exported scene) as an animated GIF."""

from phiscene.demo import run_demo
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"demo {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads, failure_outputs=sm.output):
    run_demo(index_path=sm.input.urdf, out_gif=sm.output.gif, out_json=sm.output.summary, params=dict(sm.params.demo),
             render=dict(sm.params.render))
