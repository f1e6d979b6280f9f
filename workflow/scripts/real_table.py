"""Snakemake script: the real-scene table (physical metrics, faithfulness to the input, settling and time)."""

from pathlib import Path

from phiscene.atomic import write_text
from phiscene.runner import job
from phiscene.tables import ATTACHED_NOTE, REAL_COLUMNS, real_scene_rows, real_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("real table", sm.log[0], sm.threads):
    files = {m: list(sm.input[m]) for m in sm.params.methods}
    logs = {m: list(sm.input[f"log_{m}"]) for m in sm.params.methods if f"log_{m}" in sm.input.keys()}
    scenes = list(sm.params.scenes)
    write_table(real_table(files, scenes, logs), sm.output.csv, sm.output.md, directions=REAL_COLUMNS,
                title="Real scenes: physical plausibility and faithfulness to the levelled input")
    write_text(sm.output.md, Path(sm.output.md).read_text() + "\n" + ATTACHED_NOTE + "\n")
    write_text(sm.output.scenes, real_scene_rows(files, scenes, logs).to_csv(float_format="%.6g"))
