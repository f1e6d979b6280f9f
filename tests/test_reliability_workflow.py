"""The workflow under faults and reruns: a broken scene is reported in the tables; reruns are byte-identical.

One 2-scene run (tests/data/two_scenes.yaml, cheap settings: convex proxies, small
scenes, the phys table's gt / initial / phi_scene rows) is shared by both tests.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
TARGET = "results/tables/phys.csv"
METHODS = ["gt", "initial", "phi_scene"]
CHEAP = {"benchmark": {"n_objects": [2, 3], "render": {"width": 64, "height": 48}},
         "proxies": {"backend": "convex"},
         "metrics": {"physical": {"samples": 512}},
         "assembly": {"penetration_params": {"n_active": 512, "n_context": 512}},
         # every table on the suite shows only these methods, so the phys table pulls in no other method's job
         "tables": {"phys": {"methods": METHODS}, "crosssim": {"methods": METHODS},
                    "ablation": {"methods": ["initial", "phi_scene"]}}}

pytestmark = pytest.mark.workflow


def snakemake(workdir: Path, *extra: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(workdir), "-j2",
           *extra, TARGET, "--configfile", str(ROOT / "tests/data/two_scenes.yaml"), str(workdir.parent / "cheap.yaml")]
    return subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=900)


def metric_files(workdir: Path) -> dict[str, bytes]:
    root = workdir / "results" / "metrics"
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*.json"))}


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    base = tmp_path_factory.mktemp("reliability")
    (base / "cheap.yaml").write_text(yaml.safe_dump(CHEAP))
    work = base / "a"
    work.mkdir()
    res = snakemake(work)
    assert res.returncode == 0, res.stderr[-4000:]
    # a snapshot for the tests that follow (one of them damages this run)
    shutil.copytree(work / "results" / "scenes", base / "scenes")
    return {"work": work, "base": base, "csv": (work / TARGET).read_bytes(), "metrics": metric_files(work)}


def test_rerun_from_scratch_is_byte_identical(first_run):
    # The benchmark build is byte-deterministic on its own (test_bench); here every later stage runs again
    # from nothing (fresh proxy and SDF caches) on the same benchmark scenes.
    work = first_run["base"] / "b"
    shutil.copytree(first_run["base"] / "scenes", work / "results" / "scenes")
    res = snakemake(work)
    assert res.returncode == 0, res.stderr[-4000:]
    assert (work / TARGET).read_bytes() == first_run["csv"]
    again = metric_files(work)
    assert again.keys() == first_run["metrics"].keys() and len(again) == 2 * len(METHODS)
    for name, data in again.items():
        assert data == first_run["metrics"][name], name


def test_broken_scene_is_reported_not_dropped(first_run):
    work = first_run["work"]
    scene = work / "results/scenes/contact/scene_001/initial/scene.json"
    # after the benchmark was built, the initial scene's second object gets a corrupt mesh
    data = json.loads(scene.read_text())
    data["objects"][1]["mesh"] = "../meshes/corrupt.glb"
    (scene.parent.parent / "meshes" / "corrupt.glb").write_bytes(b"glTF\x02\x00\x00\x00 truncated")
    scene.write_text(json.dumps(data))
    res = snakemake(work, "--keep-going")
    assert res.returncode == 0, res.stderr[-4000:]

    phys = pd.read_csv(work / TARGET, index_col=0)
    assert list(phys.index) == METHODS
    # proxies are per scene, so every row loses scene_001; none of them drops it silently
    assert (phys["n_scenes"] == 2).all() and (phys["n_failed"] == 1).all()
    for m in METHODS:
        ok = json.loads((work / f"results/metrics/{m}/contact/scene_000.json").read_text())
        for col in ("pen_depth", "float_dist", "drift_trans", "drift_rot"):
            assert phys.loc[m, col] == pytest.approx(ok["physical"][col], rel=1e-5, abs=1e-12), (m, col)
        rec = json.loads((work / f"results/metrics/{m}/contact/scene_001.json").read_text())
        assert rec["failed"] is True and rec["status"] == "failed"
    md = (work / "results/tables/phys.md").read_text()
    assert "phi_scene †" in md and "phi_scene: 1 of 2" in md
    rec = json.loads((work / "results/metrics/phi_scene/contact/scene_001.json").read_text())
    assert "initial/scene.json: objects[1].mesh: cannot read mesh" in rec["error"]
    log = (work / "results/logs/proxies/contact/scene_001.log").read_text()
    assert sum(" ERROR " in line for line in log.splitlines()) == 1 and "Traceback" not in log
    # the scene that is fine was not recomputed
    assert "scene_000" not in "".join(line for line in res.stderr.splitlines() if line.startswith("    wildcards"))
