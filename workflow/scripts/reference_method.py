"""Snakemake script: a reference method row (gt or initial) is the benchmark scene itself."""

from phiscene.pipeline import run_reference
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"{sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_reference(sm.input.scene, sm.output.scene)
