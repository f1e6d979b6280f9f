"""Snakemake script: reference alignment (mask IoU against the reference segmentation, pose change) of one scene."""

from pathlib import Path

from phiscene.pipeline import run_alignment_metrics
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"alignment {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_alignment_metrics(sm.input.scene, sm.input.initial, Path(sm.input.camera).parent, sm.output[0],
                          dict(sm.params.alignment))
