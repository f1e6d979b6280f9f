"""Faults: killed writers, failure records through jobs and tables, corrupted cache entries."""

import json
import logging
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from phiscene import cli, tables
from phiscene.errors import InputError, PhisceneError
from phiscene.failures import FORMAT, FailedInput, failure_record, find_failures, read_failure
from phiscene.meshes import save_mesh
from phiscene.metrics.evaluate import FORMAT as METRICS_FORMAT
from phiscene.proxies import ProxyParams, decompose, proxy_for_mesh, read_proxies, write_proxies
from phiscene.runner import job
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.sdf_grid import GridParams, build_grid, clear_memory_cache, sdf_grid
from phiscene.topology.graph import SupportEdge, SupportGraph, save
from phiscene.transforms import make_pose


@pytest.fixture(autouse=True)
def _restore_logging(keep_logging):
    """Every test here runs code that reconfigures logging (see conftest.keep_logging)."""


@pytest.fixture
def scene_file(tmp_path):
    mesh = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes" / "cube.glb")
    return save_scene(Scene([SceneObject("cube", mesh, make_pose(translation=[0, 0, 0.05]))]),
                      tmp_path / "scene" / "scene.json")


# -- a writer killed mid-write ---------------------------------------------------------------------------------------
KILLED_WRITER = """
import pathlib, sys, time
import phiscene.atomic as atomic
from phiscene.scene import load_scene, save_scene
stage = sys.argv[3]
if stage == "write":  # the temporary file is half written when the process dies
    def write_text(self, text):
        with open(self, "w") as fh:
            fh.write(text[: len(text) // 2]); fh.flush()
            print("ready", flush=True); time.sleep(60)
    pathlib.Path.write_text = write_text
else:  # the temporary file is complete, the rename has not happened
    def replace(src, dst):
        print("ready", flush=True); time.sleep(60)
    atomic.os.replace = replace
save_scene(load_scene(sys.argv[1]), sys.argv[2])
"""


@pytest.mark.parametrize("stage", ["write", "rename"])
@pytest.mark.parametrize("existing", [False, True])
def test_killed_writer_leaves_no_output(scene_file, tmp_path, stage, existing):
    target = tmp_path / "out" / "scene.json"
    if existing:  # an older complete output stays exactly as it was
        target.parent.mkdir()
        target.write_text("old complete output\n")
    proc = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(scene_file), str(target), stage],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        temps = [p for p in target.parent.iterdir() if p.name.startswith(".scene.json.")]
        assert len(temps) == 1 and temps[0].stat().st_size > 0  # the write was under way
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    if existing:
        assert target.read_text() == "old complete output\n"
    else:
        assert not target.exists()
    # the leftover is a hidden temporary that no rule names as an output
    assert [p.name for p in target.parent.iterdir() if p.name != "scene.json"][0].startswith(".scene.json.")


# -- failure records through the job wrapper -------------------------------------------------------------------------
def test_scene_error_becomes_a_failure_record_and_propagates(tmp_path, scene_file):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "phiscene.scene/1", "objects": [{"id": "a", "mesh": "x.glb"}]}')
    out = [tmp_path / "m" / "scene.json", tmp_path / "m" / "assembly.json"]
    with job("ground a", tmp_path / "a.log", failure_outputs=out):
        load_scene(bad)
    for p in out:
        rec = json.loads(p.read_text())
        assert rec["format"] == FORMAT and rec["failed"] is True and rec["status"] == "failed"
        assert rec["job"] == rec["failed_in"] == "ground a"
        assert rec["error"] == f"{bad}: objects[0].pose: required field is missing"
    # the next job reads the record as its input: it records the same root cause, and so on down the line
    metric = tmp_path / "metric.json"
    with job("metrics a", tmp_path / "b.log", failure_outputs=[metric]):
        load_scene(out[0])
    rec = read_failure(metric)
    assert rec["job"] == "metrics a" and rec["failed_in"] == "ground a" and "pose" in rec["error"]
    with pytest.raises(FailedInput, match="upstream job 'ground a' failed"):
        load_scene(metric)
    with pytest.raises(FailedInput):  # a record at a .npz path is recognised by its content
        read_proxies(_copy(metric, tmp_path / "p.npz"))
    assert find_failures(tmp_path) == sorted([*out, metric, tmp_path / "p.npz"])


def _copy(src, dst):
    dst.write_bytes(src.read_bytes())
    return dst


def test_bugs_still_fail_loudly(tmp_path):
    out = tmp_path / "x.json"
    with pytest.raises(ZeroDivisionError):
        with job("buggy", tmp_path / "l.log", failure_outputs=[out]):
            _ = 1 / 0
    assert not out.exists()
    # without failure outputs (tables, benchmark) a phiscene error is still a one-line exit 1
    with pytest.raises(SystemExit) as exc:
        with job("table", tmp_path / "t.log"):
            raise InputError("f.json", "objects", "bad")
    assert exc.value.code == 1 and not out.exists()
    # a setup problem (not the scene's fault) fails the job even where failure records are allowed

    class NoApiKey(PhisceneError):
        per_scene = False

    with pytest.raises(SystemExit):
        with job("topology", tmp_path / "k.log", failure_outputs=[out]):
            raise NoApiKey("topology.mllm: environment variable GEMINI_API_KEY is not set")
    assert not out.exists()


def test_corrupt_proxies_file_is_an_input_error(tmp_path):
    path = tmp_path / "p.npz"
    path.write_bytes(b"PK\x03\x04 truncated zip")
    with pytest.raises(InputError, match="p.npz: not a readable proxies file"):
        read_proxies(path)


def test_failures_command_lists_records(tmp_path, capsys):
    (tmp_path / "metrics").mkdir()
    (tmp_path / "metrics" / "ok.json").write_text('{"pen_depth": 0}')
    rec = tmp_path / "metrics" / "bad.json"
    rec.write_text(json.dumps(failure_record("proxies s1", "s1/scene.json: objects[0].mesh: not found")))
    assert cli.main(["failures", str(tmp_path), "--why"]) == 0
    assert capsys.readouterr().out == f"{rec}: proxies s1: s1/scene.json: objects[0].mesh: not found\n"


# -- tables count failed scenes --------------------------------------------------------------------------------------
def _metric(path, record=None, **sections):
    """A metrics file with the given sections (or ``record``, a failure record)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = record if record is not None else {"format": METRICS_FORMAT, "sections": sorted(sections), **sections}
    path.write_text(json.dumps(data))
    return path


def _graph(path, edges):
    ids = sorted({t for _, t in edges})
    return save(SupportGraph(objects=["ground", *ids], edges=[SupportEdge(a, b) for a, b in edges], order=ids),
                path)


def test_tables_count_failed_scenes(tmp_path):
    rec = failure_record("metrics", "scene.json: objects[0].mesh: cannot read mesh")
    phys = {k: 0.0 for k in tables.PHYS_COLUMNS}
    pose = {k: 0.0 for k in tables.POSE_COLUMNS}
    files = {"good": [_metric(tmp_path / "g0.json", physical={**phys, "pen_depth": 1.0}, pose_gt=pose),
                      _metric(tmp_path / "g1.json", physical={**phys, "pen_depth": 3.0}, pose_gt=pose)],
             "flaky": [_metric(tmp_path / "f0.json", physical={**phys, "pen_depth": 5.0}, pose_gt=pose),
                       _metric(tmp_path / "f1.json", rec)]}
    df = tables.physical_table(files)
    assert df.loc["good", "pen_depth"] == 2.0 and df.loc["flaky", "pen_depth"] == 5.0  # means over successes
    assert df["n_scenes"].tolist() == [2, 2] and df["n_failed"].tolist() == [0, 1]
    md = tables.to_markdown(df, tables.PHYS_COLUMNS)
    assert "| flaky †" in md and "| good " in md and "good †" not in md
    assert "flaky: 1 of 2" in md
    # all scenes failed: NaN means, still a row
    df = tables.physical_table({"dead": [_metric(tmp_path / "d.json", rec)]})
    assert np.isnan(df.loc["dead", "pen_depth"]) and df.loc["dead", "n_failed"] == 1
    # a joined table averages both sections over the same scenes
    drift = {"drift_trans": 1.0, "drift_rot": 1.0}
    df = tables.crosssim_table({"m": [_metric(tmp_path / "c0.json", physical=drift, mujoco=drift),
                                      _metric(tmp_path / "c1.json", rec)]})
    assert df.loc["m", "drift_trans_bullet"] == 1.0 and df.loc["m", "n_failed"] == 1
    # a file made for other tables is a clear error, not a KeyError
    with pytest.raises(InputError, match="g0.json.*no 'mujoco' section"):
        tables.crosssim_table({"good": files["good"]})
    # the topology table scores the graphs; a backend's failure record is a failed scene
    gt = [_graph(tmp_path / "gt0.json", [("ground", "a"), ("a", "b"), ("ground", "c"), ("c", "d")]),
          _graph(tmp_path / "gt1.json", [("ground", "a")])]
    pred0 = _graph(tmp_path / "p0.json", [("ground", "a"), ("a", "b"), ("ground", "c"), ("ground", "d")])
    (tmp_path / "p1.json").write_text(json.dumps(rec))
    topo = tables.topology_table({"b": [pred0, tmp_path / "p1.json"]}, gt)
    assert topo.loc["b", "recall"] == 0.75 and topo.loc["b", "precision"] == 0.75
    assert topo.loc["b", "n_failed"] == 1 and topo.loc["b", "n_scenes"] == 2


# -- corrupted cache entries are detected by their hash and rebuilt ------------------------------------------------
def _mesh(tmp_path):
    return save_mesh(trimesh.creation.cylinder(radius=0.05, height=0.1, sections=12), tmp_path / "cyl.glb")


@pytest.mark.parametrize("damage", ["garbage", "truncated", "values"])
def test_corrupted_proxy_cache_entry_is_rebuilt(tmp_path, caplog, damage):
    mesh_file, params, cache = _mesh(tmp_path), ProxyParams(backend="convex"), tmp_path / "cache"
    first = proxy_for_mesh(mesh_file, params, cache)
    (entry,) = (cache / "proxies").glob("*.npz")
    if damage == "garbage":
        entry.write_bytes(b"\x00" * 100)
    elif damage == "truncated":
        entry.write_bytes(entry.read_bytes()[:150])
    else:  # a well-formed archive under the right key whose hull was altered: only the content hash can tell
        px = read_proxies(entry)["_"]
        px.hulls[0] = px.hulls[0] * 1.5
        write_proxies(entry, {"_": px})
        assert read_proxies(entry)["_"].meta["mesh_hash"] == first.meta["mesh_hash"]
    with caplog.at_level(logging.WARNING, logger="phiscene.proxies"):
        again = proxy_for_mesh(mesh_file, params, cache)
    assert "rebuilding" in caplog.text
    # oracle: the decomposition computed from scratch
    fresh = decompose(trimesh.load(mesh_file, force="mesh"), params)
    np.testing.assert_allclose(again.hulls[0], fresh[0])
    # the entry was rewritten and is trusted again
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="phiscene.proxies"):
        np.testing.assert_allclose(proxy_for_mesh(mesh_file, params, cache).hulls[0], fresh[0])
    assert "rebuilding" not in caplog.text


@pytest.mark.parametrize("damage", ["garbage", "values"])
def test_corrupted_sdf_grid_cache_entry_is_rebuilt(tmp_path, caplog, damage):
    mesh = trimesh.creation.box([0.1, 0.2, 0.05])
    params, cache = GridParams(resolution=12, error_samples=256), tmp_path / "cache"
    clear_memory_cache()
    built = sdf_grid(mesh, params, cache)
    (entry,) = (cache / "sdf_grids").glob("*.npz")
    if damage == "garbage":
        entry.write_bytes(b"not a zip at all")
    else:  # same keys, one node value flipped: well-formed, but not what was built
        with np.load(entry) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["values"] = arrays["values"].copy()
        arrays["values"][3, 3, 3] *= -1
        with open(entry, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    clear_memory_cache()
    with caplog.at_level(logging.WARNING, logger="phiscene.sdf_grid"):
        again = sdf_grid(mesh, params, cache)
    assert "rebuilding" in caplog.text
    np.testing.assert_array_equal(again.values, build_grid(mesh, params).values)
    np.testing.assert_array_equal(again.values, built.values)
    clear_memory_cache()


def test_damaged_hull_obj_is_rewritten(tmp_path, caplog):
    from phiscene.sim.bullet import hulls_obj_file

    hulls = [np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)]
    path = hulls_obj_file(hulls, tmp_path)
    good = path.read_bytes()
    assert hulls_obj_file(hulls, tmp_path) == path  # same hulls, same file
    path.write_bytes(good[: len(good) // 2])  # truncated by a crash
    assert hulls_obj_file(hulls, tmp_path) == path and path.read_bytes() == good
    assert "damaged" in caplog.text
    other = hulls_obj_file([hulls[0] * 2], tmp_path)
    assert other != path  # other vertices, other name (pybullet caches shapes by file name)
