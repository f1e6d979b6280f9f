"""Snakemake script: cross-simulator drift table (paper Tab. 3): MuJoCo beside pybullet."""

from phiscene.runner import job
from phiscene.tables import CROSSSIM_COLUMNS, crosssim_table, write_table

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job("crosssim table", sm.log[0], sm.threads):
    files = {m: list(sm.input[m]) for m in sm.params.methods}
    write_table(crosssim_table(files), sm.output.csv, sm.output.md,
                title="Cross-simulator drift (MuJoCo; pybullet beside it)", directions=CROSSSIM_COLUMNS)
