"""Snakemake script: import one scene of a folder-of-scenes suite (`sam3d`: a SAM 3D Objects run; `placed`: per-object
meshes placed in one frame), levelled and its walls estimated."""

from pathlib import Path

from phiscene.io import run_source_scene
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"{sm.params.source['kind']} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    run_source_scene(source=dict(sm.params.source), scene=sm.wildcards.scene,
                     out_dir=Path(sm.output.initial).parent.parent)
