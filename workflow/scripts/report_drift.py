"""Snakemake script: per-scene drift distribution of every method of a table."""

from phiscene.plots import drift_distribution
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"report drift {sm.wildcards.engine}", sm.log[0], sm.threads):
    drift_distribution({m: list(sm.input[m]) for m in sm.params.methods}, sm.output[0], seed=sm.params.seed,
                       section=sm.params.section)
