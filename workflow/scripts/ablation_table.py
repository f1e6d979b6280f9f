"""Snakemake script: ablation table (paper Tab. 6): reference alignment + physical metrics per method."""

from phiscene.runner import job
from phiscene.tables import ABLATION_COLUMNS, ablation_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("ablation table", sm.log[0], sm.threads):
    physical = {m: list(sm.input[m]) for m in sm.params.methods}
    alignment = {m: list(sm.input[f"alignment_{m}"]) for m in sm.params.methods}
    write_table(ablation_table(physical, alignment), sm.output.csv, sm.output.md,
                title="Ablation: ordering, joint vs sequential, settling stages", directions=ABLATION_COLUMNS)
