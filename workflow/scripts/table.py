"""Snakemake script: one table (CSV + Markdown, or its per-scene CSV) of a registered kind (phiscene.table_registry)."""

from phiscene.plugins import load_plugins
from phiscene.runner import job
from phiscene.table_registry import TableInputs, table_kind, write_kind_table, write_scene_rows

sm = snakemake  # noqa: F821 (injected by Snakemake)
spec = sm.params.spec
with job(f"{sm.wildcards.table} table", sm.log[0], sm.threads):
    load_plugins(sm.config.get("plugins"))  # registrations of config plugins, in this job's process
    rows = list(spec["rows"])
    inputs = TableInputs(files={r: list(sm.input[r]) for r in rows}, scenes=list(spec["scenes"]),
                         gt_files=list(sm.input.get("gt_topology", [])), benchmark_dir=spec["benchmarks"],
                         logs={r: list(sm.input[f"log_{r}"]) for r in rows if f"log_{r}" in sm.input.keys()})
    kind = table_kind(spec["kind"])
    if "csv" in sm.output.keys():
        write_kind_table(kind, inputs, sm.output.csv, sm.output.md, heading=spec["heading"])
    else:
        write_scene_rows(kind, inputs, sm.output[0])
