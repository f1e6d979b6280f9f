"""Snakemake script: interactive offline 3D viewer page of one method scene."""

from phiscene.report import scene_viewer
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"report viewer {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    scene_viewer(sm.input.scene, sm.output[0], sm.params.title, color_by=sm.params.color_by)
