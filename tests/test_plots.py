"""Tests of the report figures (phiscene.plots) and the offline 3D viewer (phiscene.viewer)."""

from __future__ import annotations

import base64
import json
import re
import struct

import numpy as np
import pandas as pd
import pytest
import trimesh
from PIL import Image

from phiscene import plots
from phiscene.atomic import write_json
from phiscene.errors import InputError
from phiscene.failures import record_for, write_failure
from phiscene.meshes import save_mesh
from phiscene.metrics.evaluate import FORMAT as METRICS_FORMAT
from phiscene.render import RenderParams, camera_for, project, scene_bounds, segmentation_colors
from phiscene.scene import Scene, SceneObject
from phiscene.topology.graph import SupportEdge, SupportGraph, save
from phiscene.transforms import make_pose
from phiscene.viewer import Z_UP_TO_Y_UP, scene_viewer_html


def _png_size(path) -> tuple[int, int]:
    with Image.open(path) as im:
        assert im.format == "PNG"
        return im.size


def _twice(fn, tmp_path, name: str, *args, **kwargs) -> bytes:
    """Call ``fn(*args, out, **kwargs)`` into two files; assert identical bytes; return them."""
    a = fn(*args, tmp_path / f"a_{name}", **kwargs)
    b = fn(*args, tmp_path / f"b_{name}", **kwargs)
    assert a == tmp_path / f"a_{name}" and a.stat().st_size > 1000
    assert a.read_bytes() == b.read_bytes()
    return a.read_bytes()


@pytest.fixture(scope="module")
def boxes(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plots")
    colors = segmentation_colors(3)
    objs = []
    for k, (size, centre) in enumerate([((0.2, 0.2, 0.1), (0, 0, 0.05)), ((0.1, 0.1, 0.1), (0, 0, 0.15)),
                                        ((0.12, 0.12, 0.12), (0.3, 0.1, 0.06))]):
        path = save_mesh(trimesh.creation.box(extents=size), tmp / f"b{k}.glb")
        objs.append(SceneObject(f"obj_{k + 1:02d}", path.resolve(), make_pose(translation=centre),
                                description=f"box <{k}>", color=colors[k], meta={"rgb": [200, 60 * k, 40]}))
    scene = Scene(objs)
    write_json(tmp / "camera.json", camera_for(scene, RenderParams(width=120, height=90)))
    return tmp, scene


def test_method_bars(tmp_path):
    df = pd.DataFrame({"method": ["gt", "initial", "ours"], "pen_depth": [1e-5, 1e-2, 2e-5],
                       "drift_rot": [0.01, 5.0, 0.1], "f1": [1.0, 0.5, float("nan")]}).set_index("method")
    csv = tmp_path / "t.csv"
    df.to_csv(csv)
    _twice(plots.method_bars, tmp_path, "bars.png", csv, columns=["pen_depth", "drift_rot", "f1"])
    assert _png_size(tmp_path / "a_bars.png") == (3 * 320, 300)
    _twice(plots.method_bars, tmp_path, "bars5.png", csv, columns=["pen_depth"] * 5, log=True)
    assert _png_size(tmp_path / "a_bars5.png") == (4 * 320, 2 * 300)
    svg = plots.method_bars(csv, tmp_path / "bars.svg", ["pen_depth"]).read_text()
    assert "<svg" in svg and "<dc:date>" not in svg
    with pytest.raises(InputError, match="t.csv.*recall.*no such column"):
        plots.method_bars(csv, tmp_path / "x.png", ["recall"])
    assert not (tmp_path / "x.png").exists()


def test_drift_distribution(tmp_path):
    rng = np.random.default_rng(0)
    files = {}
    for m, scale in (("gt", 1e-4), ("initial", 3e-2), ("ours", 2e-4)):
        files[m] = []
        for k in range(6):
            f = tmp_path / m / f"scene_{k:03d}.json"
            rot = 0.0 if (m, k) == ("gt", 0) else float(rng.uniform())  # one zero: symmetric-log axis
            write_json(f, {"format": METRICS_FORMAT, "sections": ["mujoco"],
                           "mujoco": {"drift_trans": float(scale * rng.uniform(0.5, 2)), "drift_rot": rot}})
            files[m].append(f)
    write_failure([tmp_path / "failed.json"], record_for("metrics ours", InputError("x.json", None, "bad")))
    files["ours"].append(tmp_path / "failed.json")  # a failed scene is left out, not an error
    _twice(plots.drift_distribution, tmp_path, "drift.png", files, section="mujoco")
    assert _png_size(tmp_path / "a_drift.png") == (2 * 320, 360)
    write_json(tmp_path / "bad.json",
               {"format": METRICS_FORMAT, "sections": ["mujoco"], "mujoco": {"drift_trans": 0.1}})
    with pytest.raises(InputError, match="bad.json.*mujoco.drift_rot"):
        plots.drift_distribution({"x": [tmp_path / "bad.json"]}, tmp_path / "y.png", section="mujoco")
    with pytest.raises(InputError, match="bad.json.*no 'physical' section"):
        plots.drift_distribution({"x": [tmp_path / "bad.json"]}, tmp_path / "y.png")


def _graph(tmp_path) -> SupportGraph:
    # kept edges hold a cycle obj_02 -> obj_03 -> obj_02 (an unfinalised graph); obj_04 sits on obj_03;
    # a dropped edge runs against a kept one
    g = SupportGraph(objects=["ground", "obj_01", "obj_02", "obj_03", "obj_04"], backend="test",
                     edges=[SupportEdge("ground", "obj_01"), SupportEdge("obj_01", "obj_02"),
                            SupportEdge("obj_02", "obj_03", "leans_on"), SupportEdge("obj_03", "obj_02"),
                            SupportEdge("obj_03", "obj_04", "contains")],
                     dropped_edges=[SupportEdge("obj_04", "obj_03", confidence=0.2)])
    save(g, tmp_path / "topo.json")
    return g


def test_graph_layers_with_cycle(tmp_path):
    layers = plots.graph_layers(_graph(tmp_path))
    # ground 0; obj_01 on the ground; the cycle {obj_02, obj_03} above obj_01; obj_04 above the cycle
    assert layers == {"ground": 0, "obj_01": 1, "obj_02": 2, "obj_03": 2, "obj_04": 3}
    pos = plots.graph_positions(_graph(tmp_path))
    assert pos["ground"] == (0.0, 0.0) and pos["obj_04"][1] == 3.0
    assert sorted(x for x, y in pos.values() if y == 2) == [-0.5, 0.5]


def test_support_graph_figure(tmp_path):
    _graph(tmp_path)
    _twice(plots.support_graph_figure, tmp_path, "graph.png", tmp_path / "topo.json", title="cycle")
    assert _png_size(tmp_path / "a_graph.png") == (480, 120 * 5)
    # no edges at all, and a file that is not a topology
    save(SupportGraph(objects=["ground", "obj_01"], edges=[]), tmp_path / "empty.json")
    assert _png_size(plots.support_graph_figure(tmp_path / "empty.json", tmp_path / "e.png", "empty")) == (480, 360)
    write_json(tmp_path / "bad.json", {"format": "phiscene.topology/1", "objects": ["ground"],
                                       "edges": [{"from": "ground", "to": "obj_09"}]})
    with pytest.raises(InputError, match="bad.json"):
        plots.support_graph_figure(tmp_path / "bad.json", tmp_path / "b.png", "bad")


def test_orbit_camera(boxes):
    tmp, scene = boxes
    cam = json.loads((tmp / "camera.json").read_text())
    eye, target = np.asarray(cam["eye"]), np.asarray(cam["target"])
    swung = plots.orbit_camera(cam, 60.0)
    e2 = np.asarray(swung["eye"])
    assert np.allclose(swung["target"], target)
    assert np.linalg.norm(e2 - target) == pytest.approx(np.linalg.norm(eye - target))
    assert e2[2] == pytest.approx(eye[2])  # same elevation
    az = np.degrees(np.arctan2(*(e2 - target)[[1, 0]]) - np.arctan2(*(eye - target)[[1, 0]]))
    assert (az + 180) % 360 - 180 == pytest.approx(60.0)
    # with bounds, a far object stays in view
    far = scene.with_poses({"obj_03": make_pose(translation=(1.5, 0.0, 0.06))})
    framed = plots.orbit_camera(cam, 60.0, scene_bounds(far))
    uv = project(framed, far.get("obj_03").world_mesh().vertices)
    assert (uv >= -0.5).all() and (uv[:, 0] <= 119.5).all() and (uv[:, 1] <= 89.5).all()


def test_before_after(boxes, tmp_path):
    tmp, scene = boxes
    moved = scene.with_poses({"obj_03": make_pose(translation=(0.3, -0.2, 0.06))})
    data = _twice(plots.before_after, tmp_path, "ba.png", scene, moved, tmp / "camera.json")
    assert _png_size(tmp_path / "a_ba.png") == (2 * 120 + 18, 2 * (90 + 22) + 18)
    img = np.asarray(Image.open(tmp_path / "a_ba.png").convert("RGB")).astype(int)
    left, right = img[6 + 22:6 + 22 + 90, 6:126], img[6 + 22:6 + 22 + 90, 132:252]
    assert np.abs(left - right).sum() > 0  # the moved object shows
    assert data[:8] == b"\x89PNG\r\n\x1a\n"


def _glb_json(page: str) -> dict:
    glb = base64.b64decode(re.search(r'base64_data="([^"]+)"', page).group(1))
    n = struct.unpack("<I", glb[12:16])[0]
    return json.loads(glb[20:20 + n])


def test_viewer_is_offline_and_complete(boxes, tmp_path):
    tmp, scene = boxes
    scene.camera = tmp / "camera.json"
    out = scene_viewer_html(scene, tmp_path / "v.html", "boxes & <things>")
    page = out.read_text()
    assert out.read_bytes() == scene_viewer_html(scene, tmp_path / "w.html", "boxes & <things>").read_bytes()
    assert not re.search(r"<script[^>]*\bsrc\s*=", page, re.I)
    assert not re.search(r"""(?:src|href)\s*=\s*["']?(?:https?:)?//""", page, re.I)
    assert "<title>boxes &amp; &lt;things&gt;</title>" in page and "THREE.GLTFLoader" in page
    for o in scene.objects:
        assert f'data-object="{o.id}"' in page
    gltf = _glb_json(page)
    names = {n.get("name") for n in gltf["nodes"]}
    assert set(scene.ids) | {"ground"} <= names
    colors = {tuple(round(c * 255) for c in m["pbrMetallicRoughness"]["baseColorFactor"][:3])
              for m in gltf["materials"]}
    assert {tuple(o.color) for o in scene.objects} <= colors
    # y-up: the camera node sits at the reference eye rotated into glTF's frame
    cam_node = next(n for n in gltf["nodes"] if "camera" in n)
    eye_gltf = np.asarray(cam_node["matrix"]).reshape(4, 4).T[:3, 3]
    eye = np.asarray(json.loads((tmp / "camera.json").read_text())["eye"])
    assert np.allclose(eye_gltf, Z_UP_TO_Y_UP[:3, :3] @ eye, atol=1e-9)
    # y-up geometry: obj_02 spans world z 0.1..0.2 and y -0.05..0.05 -> glTF y 0.1..0.2, z -0.05..0.05
    node = next(n for n in gltf["nodes"] if n.get("name") == "obj_02")
    acc = gltf["accessors"][gltf["meshes"][node["mesh"]]["primitives"][0]["attributes"]["POSITION"]]
    assert np.allclose(acc["min"], [-0.05, 0.1, -0.05], atol=1e-6)
    assert np.allclose(acc["max"], [0.05, 0.2, 0.05], atol=1e-6)
    # natural colours on request
    page = scene_viewer_html(scene, tmp_path / "n.html", "natural", color_by="rgb").read_text()
    colors = {tuple(round(c * 255) for c in m["pbrMetallicRoughness"]["baseColorFactor"][:3])
              for m in _glb_json(page)["materials"]}
    assert {tuple(o.meta["rgb"]) for o in scene.objects} <= colors
