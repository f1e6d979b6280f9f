"""The Snakemake workflow: lint clean, and a real 2-scene run from an empty results/ folder."""

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def run(args, cwd):
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    return subprocess.run(SNAKEMAKE + args, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


def test_lint_clean():
    res = run(["--lint"], ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Congratulations" in res.stdout + res.stderr or "lint" not in (res.stdout + res.stderr).lower(), res.stdout


@pytest.mark.parametrize("tool", ["ruff", "snakefmt"])
def test_lint_python_and_rules_formatted(tool):
    """`make lint`'s other two linters (settings in pyproject.toml): ruff on the sources, snakefmt on the rules."""
    args = ["check", "src", "tests", "workflow/scripts", "benchmarks", "tools"] if tool == "ruff" else \
        ["--check", "Snakefile", "workflow/rules"]
    res = subprocess.run([sys.executable, "-m", tool, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-4000:]


@pytest.mark.workflow
def test_two_scene_run(tmp_path):
    target = ["results/tables/phys.csv", "results/tables/topology.csv"]
    res = run(["-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path), "--configfile",
               str(ROOT / "tests/data/two_scenes.yaml"), "-j2", *target], ROOT)
    assert res.returncode == 0, res.stderr[-4000:]
    phys = pd.read_csv(tmp_path / target[0], index_col=0)
    assert list(phys.index) == ["gt", "initial", "phi_scene", "phi_scene_gt_topology"]
    assert (phys["n_scenes"] == 2).all()
    # ground truth is physical by construction; the degraded initial scene is not
    assert phys.loc["gt", "pen_depth"] < 1e-3 and phys.loc["gt", "drift_trans"] < 1e-3
    assert phys.loc["initial", "pen_depth"] > 5 * phys.loc["gt", "pen_depth"]
    assert phys.loc["phi_scene", "pen_depth"] < phys.loc["initial", "pen_depth"]
    topo = pd.read_csv(tmp_path / target[1], index_col=0)
    assert set(topo.index) == {"geometric", "height"}
    assert ((topo[["precision", "recall", "f1"]] >= 0) & (topo[["precision", "recall", "f1"]] <= 1)).all().all()
    for scene in ("scene_000", "scene_001"):
        assert (tmp_path / f"results/logs/benchmark/contact/{scene}.log").stat().st_size > 0
        assert (tmp_path / f"results/benchmarks/methods/phi_scene/contact/{scene}.tsv").exists()
    # nothing to do on a second call: the DAG is complete and up to date
    res2 = run(["-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path), "--configfile",
                str(ROOT / "tests/data/two_scenes.yaml"), "-j2", "-n", *target], ROOT)
    assert res2.returncode == 0 and "Nothing to be done" in res2.stdout + res2.stderr
