"""Snakemake script: import one REST3D page-asset scene (levelled) as a benchmark scene."""

from pathlib import Path

from phiscene.io.rest3d import run_rest3d_scene
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"rest3d {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    run_rest3d_scene(source=dict(sm.params.source), scene=sm.wildcards.scene,
                     out_dir=Path(sm.output.initial).parent.parent)
