"""The Snakemake workflow: lint clean, and a real 2-scene run from an empty results/ folder."""

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def run(args, cwd, env=None):
    env = {**os.environ, "PYTHONHASHSEED": "0", **(env or {})}
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
    """Two contact scenes end to end, with the example plugin (tests/plugins/seam_plugin.py): its drift simulator,
    table kind and baseline are each one registry entry (plus config), and the workflow builds them."""
    target = ["results/tables/phys.csv", "results/tables/topology.csv", "results/tables/crosssim.csv",
              "results/tables/faithfulness.csv", "results/report/tables/faithfulness.html"]
    config = ["--configfile", str(ROOT / "tests/data/two_scenes.yaml"), str(ROOT / "tests/data/seam_plugin.yaml")]
    env = {"PYTHONPATH": os.pathsep.join([str(ROOT / "tests/plugins"), os.environ.get("PYTHONPATH", "")])}
    res = run(["-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path), *config, "-j2", *target], ROOT, env)
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
    _check_plugin_outputs(tmp_path)
    # nothing to do on a second call: the DAG is complete and up to date
    res2 = run(["-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path), *config, "-j2", "-n", *target], ROOT,
               env)
    assert res2.returncode == 0 and "Nothing to be done" in res2.stdout + res2.stderr


def _check_plugin_outputs(root):
    """The plugin's simulator column, table (+ report page) and baseline, against independent oracles."""
    import json

    from phiscene.scene import load_scene

    cross = pd.read_csv(root / "results/tables/crosssim.csv", index_col=0)
    coarse = cross["drift_trans_bullet_coarse"]
    # ground truth rests in the coarse pybullet world too; the penetrating initial scene does not
    assert coarse.notna().all() and coarse["gt"] < coarse["initial"]
    faith = pd.read_csv(root / "results/tables/faithfulness.csv", index_col=0)
    assert list(faith.index) == ["initial", "dropped", "phi_scene"]
    assert faith.loc["initial", "displacement_mean"] == 0.0  # the input compared with itself
    for method in faith.index:  # the table's means are the means of the metrics files' values
        files = [root / f"results/metrics/{method}/contact/scene_{i:03d}.json" for i in range(2)]
        values = [json.loads(f.read_text())["pose_gt"]["gt_translation_mean"] for f in files]
        assert faith.loc[method, "gt_translation_mean"] == pytest.approx(sum(values) / 2, rel=1e-5)
    assert "Faithfulness to the input (plugin)" in (root / "results/report/tables/faithfulness.html").read_text()
    for i in range(2):
        initial = load_scene(root / f"results/scenes/contact/scene_{i:03d}/initial/scene.json")
        dropped = load_scene(root / f"results/methods/dropped/contact/scene_{i:03d}/scene.json")
        for a, b in zip(initial.objects, dropped.objects):
            assert b.world_mesh().vertices[:, 2].min() == pytest.approx(dropped.ground_height, abs=1e-6)
            assert a.pose[:2, 3] == pytest.approx(b.pose[:2, 3])


@pytest.mark.parametrize("ray, hidden", [(False, 0.0), (True, 0.0), (False, 0.5)])
def test_grounding_reads_the_camera_only_when_a_method_uses_it(tmp_path, ray, hidden):
    """`assembly.faithful.ray` (gaps closed along camera rays) or `hidden_share` > 0 (objects mostly unseen in the
    photo) makes the photo's camera an input of the grounding job; with both off, it is none (a suite without a
    camera, 3D-FRONT's, grounds as before)."""
    cfg = tmp_path / "ray.yaml"
    cfg.write_text(f"assembly:\n  faithful:\n    ray: {str(ray).lower()}\n    hidden_share: {hidden}\n")
    target = "results/methods/phi_scene/contact/scene_000/scene.json"
    res = run(["-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path), "-n", target, "--configfile", str(cfg)],
              ROOT)
    assert res.returncode == 0, res.stderr[-4000:]
    out = res.stdout + res.stderr
    block = out[out.index("rule phi_scene:"):]
    inputs = block[:block.index("output:")]
    assert ("results/scenes/contact/scene_000/reference/camera.json" in inputs) == (ray or hidden > 0)
