"""Snakemake script: reconstruction metrics (MIDI-3D protocol) of one scene against ground truth."""

from phiscene.pipeline import run_recon_metrics
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"recon metrics {sm.wildcards.method} {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads,
         failure_outputs=sm.output):
    run_recon_metrics(sm.input.scene, sm.input.gt, sm.output[0], dict(sm.params.recon))
