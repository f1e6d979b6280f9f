"""Snakemake script: the physical plausibility table (paper Tab. 2) as CSV + Markdown."""

from phiscene.runner import job
from phiscene.tables import PHYS_COLUMNS, physical_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("phys table", sm.log[0], sm.threads):
    files = {m: list(sm.input[m]) for m in sm.params.methods}
    write_table(physical_table(files), sm.output.csv, sm.output.md, title="Physical plausibility",
                directions=PHYS_COLUMNS)
