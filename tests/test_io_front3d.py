"""3D-FRONT in MIDI-3D's test layout: a fixture room written in that layout, imported and measured."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from phiscene.baselines.external import import_external
from phiscene.errors import InputError
from phiscene.io.front3d import Front3dParams, import_front3d_room, scene_ids
from phiscene.metrics.reconstruction import reconstruction_metrics
from phiscene.render import segmentation_colors
from phiscene.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ["h0/LivingRoom-1", "h1/Bedroom-2", "h-2/Bedroom-3"]
NAMES = ["Table_aaa_1", "Chair_bbb_1", "Lighting_ccc_1", "Vase_ddd_1"]
H, W = 40, 50  # 2000 pixels: 0.1 % is 2 pixels


def y_up_box(extents, centre):
    m = trimesh.creation.box(extents)
    m.vertices += centre
    return m


def make_dataset(root: Path) -> Path:
    """One test room (the last of the list) in MIDI-3D's layout; y is up in the normalised scene frame."""
    (root / "midi_room_ids.json").parent.mkdir(parents=True, exist_ok=True)
    (root / "midi_room_ids.json").write_text(json.dumps(ROOMS))
    (root / "midi_furniture_ids.json").write_text(json.dumps([["Sofa_x_1"], ["Bed_y_1"], NAMES]))
    room = ROOMS[-1]
    rdir, sdir, gdir = (root / d / room for d in ("3D-FRONT-RENDER", "3D-FRONT-SURFACE", "3D-FRONT-SCENE"))
    for d in (rdir, sdir, gdir):
        d.mkdir(parents=True)
    shapes = {"Table_aaa_1": y_up_box((1.0, 0.7, 0.6), (0, 0.35, 0)),
              "Chair_bbb_1": y_up_box((0.4, 0.9, 0.4), (1.2, 0.45, 0)),
              "Lighting_ccc_1": y_up_box((0.3, 0.1, 0.3), (0, 2.4, 0)),
              "Vase_ddd_1": y_up_box((0.1, 0.3, 0.1), (0, 0.85, 0))}
    for k, (name, mesh) in enumerate(shapes.items()):
        pts, fidx = trimesh.sample.sample_surface(mesh, 3000, seed=k)
        np.save(sdir / f"{name}.npy", {"surface_points": pts, "surface_normals": mesh.face_normals[fidx]},
                allow_pickle=True)
    shapes["Chair_bbb_1"].export(gdir / "Chair_bbb_1.glb")  # the chair also has its GT mesh
    idmap = np.zeros((H, W), np.uint8)
    idmap[5:25, 5:25] = 1  # table: 400 px
    idmap[5:15, 30:40] = 2  # chair: 100 px
    idmap[30:40, 30:40] = 3  # lighting: dropped by label
    idmap[35, 5:7] = 4  # vase: 2 px = 0.1 % -> dropped
    Image.fromarray(idmap).save(rdir / "semantic_0000.png")
    rgb = np.random.default_rng(0).integers(0, 255, (H, W, 3), dtype=np.uint8)
    Image.fromarray(rgb).save(rdir / "render_0000.webp", lossless=True)
    return root


@pytest.fixture
def dataset(tmp_path):
    return make_dataset(tmp_path / "3d-front")


def test_test_split_is_the_last_rooms(dataset):
    assert scene_ids({"kind": "front3d", "root": str(dataset), "test_rooms": 2}) == ["h1_Bedroom_2", "h_2_Bedroom_3"]
    assert scene_ids({"kind": "front3d", "root": str(dataset)}) == ["h0_LivingRoom_1", "h1_Bedroom_2",
                                                                    "h_2_Bedroom_3"]
    with pytest.raises(ValueError, match="unknown front3d source keys"):
        scene_ids({"kind": "front3d", "root": str(dataset), "rooms": 3})


def test_room_import_filters_and_frames(dataset, tmp_path):
    params = Front3dParams(root=str(dataset), test_rooms=1)
    rec = import_front3d_room(params, "h_2_Bedroom_3", tmp_path / "scene")
    dropped = {o["name"]: o["dropped_because"] for o in rec["objects"] if not o["kept"]}
    assert dropped == {"Lighting_ccc_1": "label Lighting", "Vase_ddd_1": "mask 0.00100 of the image"}
    gt = load_scene(tmp_path / "scene/gt/scene.json")
    assert gt.ids == ["obj_01", "obj_02"]
    assert gt.get("obj_02").meta["front3d"]["label"] == "Chair"
    # chair from its GLB, y-up -> z-up: (x, y, z) -> (x, -z, y)
    np.testing.assert_allclose(gt.get("obj_02").world_mesh().bounds, [[1.0, -0.2, 0.0], [1.4, 0.2, 0.9]], atol=1e-6)
    # table from its surface points (splats): bounds within the splat size of the box
    splat = params.splat_size
    np.testing.assert_allclose(gt.get("obj_01").world_mesh().bounds, [[-0.5, -0.3, 0.0], [0.5, 0.3, 0.7]], atol=splat)
    assert abs(gt.ground_height) < splat
    topo = json.loads((tmp_path / "scene/gt/topology.json").read_text())
    assert [(e["from"], e["to"]) for e in topo["edges"]] == [("ground", "obj_01"), ("ground", "obj_02")]
    seg = np.asarray(Image.open(tmp_path / "scene/reference/segmentation.png").convert("RGB"))
    colors = segmentation_colors(len(NAMES))
    assert tuple(seg[10, 10]) == colors[0] == gt.get("obj_01").color
    assert tuple(seg[10, 35]) == colors[1]
    assert tuple(seg[35, 35]) == (0, 0, 0)  # the dropped lamp is not in the segmentation
    src = np.asarray(Image.open(dataset / "3D-FRONT-RENDER" / ROOMS[-1] / "render_0000.webp").convert("RGB"))
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "scene/reference/image.png")), src)
    initial = load_scene(tmp_path / "scene/initial/scene.json")
    assert initial.ids == gt.ids


def test_predictions_become_method_rows_with_known_metrics(dataset, tmp_path):
    """A prediction imported through baselines.external: the chair moved 0.3 m along x -> AABB IoU 0.1 / 0.7."""
    import_front3d_room(Front3dParams(root=str(dataset), test_rooms=1), "h_2_Bedroom_3", tmp_path / "scene")
    pred = tmp_path / "pred"
    pred.mkdir()
    shifted = np.eye(4)
    shifted[0, 3] = 0.3
    (pred / "poses.json").write_text(json.dumps({"obj_01": np.eye(4).tolist(), "obj_02": shifted.tolist()}))
    scene, _ = import_external(pred, tmp_path / "scene/initial/scene.json", tmp_path / "method/scene.json")
    gt = load_scene(tmp_path / "scene/gt/scene.json")
    m = reconstruction_metrics(scene, gt)
    np.testing.assert_allclose(m["objects"]["obj_02"]["bbox_iou_raw"], 0.1 / 0.7, atol=1e-6)  # GLB stores float32
    np.testing.assert_allclose(m["objects"]["obj_01"]["bbox_iou_raw"], 1.0, atol=1e-9)
    self_m = reconstruction_metrics(load_scene(tmp_path / "scene/initial/scene.json"), gt)
    assert self_m["scene_cd"] < 1e-9 and self_m["object_fscore"] > 1 - 1e-6


def test_bad_room_inputs(dataset, tmp_path):
    params = Front3dParams(root=str(dataset), test_rooms=1)
    with pytest.raises(InputError, match="no test room with scene id 'h1_Bedroom_2'"):
        import_front3d_room(params, "h1_Bedroom_2", tmp_path / "x")
    (dataset / "3D-FRONT-SURFACE" / ROOMS[-1] / "Table_aaa_1.npy").unlink()
    with pytest.raises(InputError, match="Table_aaa_1.npy: GT surface file not found"):
        import_front3d_room(params, "h_2_Bedroom_3", tmp_path / "x")


def test_workflow_accepts_a_front3d_suite(dataset, tmp_path):
    """Config + rules: the suite's scenes come from the room list, built by rule front3d_scene (dry run)."""
    cfg = tmp_path / "f3d.yaml"
    cfg.write_text(f"""
suites:
  f3d: {{source: {{kind: front3d, root: "{dataset}", test_rooms: 2}}}}
tables:
  recon: {{suite: f3d, methods: [gt, initial]}}
""")
    res = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory",
                          str(tmp_path), "-n", "-j1", "results/tables/recon.csv", "--configfile", str(cfg)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "front3d_scene" in res.stdout and "benchmark_scene" not in res.stdout
    for sid in ("h1_Bedroom_2", "h_2_Bedroom_3"):
        assert f"results/scenes/f3d/{sid}/gt/scene.json" in res.stdout
