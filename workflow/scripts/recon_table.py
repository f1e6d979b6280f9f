"""Snakemake script: reconstruction table (paper Tab. 1, MIDI-3D protocol) as CSV + Markdown."""

from phiscene.runner import job
from phiscene.tables import RECON_COLUMNS, recon_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("recon table", sm.log[0], sm.threads):
    files = {m: list(sm.input[m]) for m in sm.params.methods}
    write_table(recon_table(files), sm.output.csv, sm.output.md, title="Reconstruction against ground truth",
                directions=RECON_COLUMNS)
