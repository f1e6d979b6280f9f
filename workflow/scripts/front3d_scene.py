"""Snakemake script: import one 3D-FRONT test room (MIDI-3D layout) as a benchmark scene."""

from pathlib import Path

from phiscene.io.front3d import run_front3d_scene
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"front3d {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    run_front3d_scene(source=dict(sm.params.source), scene=sm.wildcards.scene, out_dir=Path(sm.output.gt).parent.parent)
