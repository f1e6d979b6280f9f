"""Snakemake script: runtime per stage from the benchmark: TSVs of every compute job."""

from phiscene.runner import job
from phiscene.tables import runtime_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("runtime table", sm.log[0], sm.threads):
    write_table(runtime_table(sm.params.benchmarks), sm.output.csv, sm.output.md, title="Runtime per stage",
                directions={})
