"""Snakemake script: import one SAM 3D Objects run (levelled, walls estimated) as a scene of a `sam3d` suite."""

from pathlib import Path

from phiscene.io.sam3d import run_sam3d_scene
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"sam3d {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    run_sam3d_scene(source=dict(sm.params.source), scene=sm.wildcards.scene,
                    out_dir=Path(sm.output.initial).parent.parent)
