"""Snakemake script: before/after renders of one scene with its support graph beside them."""

from phiscene.report import scene_panel
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"report scene {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    scene_panel(sm.input.initial, sm.input.method, sm.input.camera, sm.input.topology, sm.output[0],
                title=sm.params.title, labels=("initial", sm.params.method))
