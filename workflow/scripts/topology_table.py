"""Snakemake script: support-graph accuracy table (paper Tab. 7) as CSV + Markdown."""

from phiscene.runner import job
from phiscene.tables import TOPO_COLUMNS, topology_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("topology table", sm.log[0], sm.threads):
    files = {b: list(sm.input[b]) for b in sm.params.backends}
    write_table(topology_table(files, list(sm.input.gt_topology)), sm.output.csv, sm.output.md,
                title="Support graph accuracy", directions=TOPO_COLUMNS)
