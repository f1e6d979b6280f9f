"""Snakemake script: build one benchmark scene (ground truth, initial scene, reference renders)."""

from pathlib import Path

from phiscene.bench.build import build_scene
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"benchmark {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    out_dir = Path(sm.output.gt).parent.parent
    build_scene(out_dir=out_dir, suite=sm.params.generator, index=int(sm.params.index), params=dict(sm.params.bench),
                cache_dir=Path(sm.params.cache_dir))
