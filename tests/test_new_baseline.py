"""Adding a baseline is one rule file + one config entry: its row appears in the tables."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]

RULE = '''
rule baseline_identity:
    input:
        scene="results/scenes/{suite}/{scene}/initial/scene.json",
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("identity")),
    log:
        "results/logs/methods/{method}/{suite}/{scene}.log",
    conda:
        ENV
    script:
        "../../scripts/identity.py"
'''
SCRIPT = '''
from phiscene.pipeline import run_reference
from phiscene.runner import job

with job("identity", snakemake.log[0]):
    run_reference(snakemake.input.scene, snakemake.output.scene)
'''
CONFIG = '''
suites: {contact: {n_scenes: 1}}
proxies: {backend: convex}
methods: {identity_baseline: {kind: identity}}
tables: {phys: {suite: contact, methods: [initial, identity_baseline]}}
'''


@pytest.mark.workflow
def test_one_rule_file_adds_a_table_row(tmp_path):
    work = tmp_path / "wf"
    work.mkdir()
    for item in ("Snakefile", "config", "workflow", "envs"):
        src = ROOT / item
        (shutil.copytree if src.is_dir() else shutil.copy)(src, work / item)
    (work / "workflow/rules/baselines/identity.smk").write_text(RULE)
    (work / "workflow/scripts/identity.py").write_text(SCRIPT)
    (work / "mine.yaml").write_text(CONFIG)
    res = subprocess.run([sys.executable, "-m", "snakemake", "-j2", "results/tables/phys.csv",
                          "--configfile", "mine.yaml"], cwd=work, capture_output=True, text=True, timeout=600,
                         env={**os.environ, "PYTHONHASHSEED": "0"})
    assert res.returncode == 0, res.stderr[-3000:]
    phys = pd.read_csv(work / "results/tables/phys.csv", index_col=0)
    assert list(phys.index) == ["initial", "identity_baseline"]
    # oracle: the identity baseline returns the initial scene, so every metric is equal
    cols = ["pen_depth", "float_dist", "drift_trans", "drift_rot"]
    pd.testing.assert_series_equal(phys.loc["initial", cols], phys.loc["identity_baseline", cols], check_names=False)


def test_unknown_kind_is_a_clear_error(tmp_path):
    (tmp_path / "bad.yaml").write_text("methods: {mystery: {kind: no_such_kind}}\n")
    res = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--configfile", str(tmp_path / "bad.yaml")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert res.returncode != 0
    assert "methods.mystery.kind: unknown kind 'no_such_kind'" in res.stdout + res.stderr
