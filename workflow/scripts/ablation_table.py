"""Snakemake script: ablation table (paper Tab. 6): reference alignment + physical metrics per method."""

from phiscene.runner import job
from phiscene.tables import ABLATION_COLUMNS, ablation_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("ablation table", sm.log[0], sm.threads):
    files = {m: list(sm.input[m]) for m in sm.params.methods}
    write_table(ablation_table(files), sm.output.csv, sm.output.md,
                title="Ablation: ordering, joint vs sequential, settling stages", directions=ABLATION_COLUMNS)
