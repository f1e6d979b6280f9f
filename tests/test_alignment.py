"""Tests of the reference alignment metrics (phiscene.metrics.alignment).

The reference folder is made the way the benchmark builder makes it (camera_for, instance_labels,
labels_to_colors, save_png) from a small scene of boxes; oracles are exact mask IoUs of known
masks, the GT scene against its own reference, objects shifted by their own width or out of
view, and pose changes of known rigid motions.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from phiscene.atomic import write_json
from phiscene.errors import InputError
from phiscene.meshes import save_mesh
from phiscene.metrics.alignment import AlignmentParams, alignment_metrics, mask_iou
from phiscene.render import (
    RenderParams,
    camera_for,
    instance_labels,
    labels_to_colors,
    load_png,
    save_png,
    segmentation_colors,
)
from phiscene.scene import Scene, SceneObject, save_scene
from phiscene.transforms import make_pose, rotation_z

BOXES = [((0.20, 0.20, 0.10), (0.0, 0.0, 0.05)), ((0.10, 0.10, 0.10), (0.0, 0.0, 0.15)),
         ((0.12, 0.12, 0.12), (0.35, 0.10, 0.06)), ((0.10, 0.16, 0.08), (-0.30, 0.20, 0.04))]


def _scene(tmp, boxes=BOXES) -> Scene:
    colors = segmentation_colors(len(boxes))
    objs = []
    for k, (size, centre) in enumerate(boxes):
        path = save_mesh(trimesh.creation.box(extents=size), tmp / "meshes" / f"b{k}.glb")
        objs.append(SceneObject(f"obj_{k + 1:02d}", path.resolve(), make_pose(translation=centre),
                                color=colors[k], meta={"rgb": [120, 120 + 30 * k, 200]}))
    return Scene(objs)


def _write_reference(root, gt: Scene, camera: dict) -> None:
    """The benchmark's reference folder (see phiscene.bench.build._write_outputs) plus gt/scene.json."""
    labels = instance_labels(gt, camera)
    write_json(root / "reference" / "camera.json", camera)
    save_png(labels_to_colors(labels, [o.color for o in gt.objects]), root / "reference" / "segmentation.png")
    save_scene(gt, root / "gt" / "scene.json")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    root = tmp_path_factory.mktemp("align")
    gt = _scene(root)
    camera = camera_for(gt, RenderParams(width=160, height=120))
    _write_reference(root, gt, camera)
    return root, gt, camera


def _moved(scene: Scene, object_id: str, pose: np.ndarray) -> Scene:
    return scene.with_poses({object_id: pose})


def _camera_right(camera: dict) -> np.ndarray:
    """Horizontal world direction that points right in the image."""
    right = np.asarray(camera["camera_to_world"], dtype=float)[:3, 0]
    right[2] = 0.0
    return right / np.linalg.norm(right)


def test_mask_iou_of_known_masks():
    a = np.zeros((8, 8), dtype=bool)
    a[0:4, 0:4] = True
    assert mask_iou(a, a) == 1.0
    b = np.zeros_like(a)
    b[4:8, 4:8] = True
    assert mask_iou(a, b) == 0.0
    c = np.zeros_like(a)
    c[0:4, 2:6] = True  # half of a: intersection 8, union 24
    assert mask_iou(a, c) == pytest.approx(1 / 3)
    assert mask_iou(c, a) == pytest.approx(1 / 3)
    assert mask_iou(np.zeros_like(a), np.zeros_like(a)) == 1.0
    with pytest.raises(ValueError, match="shapes differ"):
        mask_iou(a, a[:4])


def test_gt_scene_matches_its_reference(bench):
    root, gt, _ = bench
    for reference in ("segmentation", "gt_render"):
        r = alignment_metrics(gt, gt, root / "reference", AlignmentParams(reference=reference))
        assert r["mask_iou"] > 0.98
        assert r["n_scored"] == len(gt.objects) and r["unmatched_reference_pixels"] == 0
        assert r["pose_change_trans"] == 0.0 and r["pose_change_rot"] == pytest.approx(0.0, abs=1e-6)
        for v in r["objects"].values():
            assert v["pixels_reference"] > 20 and v["pixels_render"] == v["pixels_reference"]


def test_degraded_scene_is_less_aligned(bench):
    from phiscene.bench.degrade import DegradeParams, degrade_scene

    root, gt, _ = bench
    initial = degrade_scene(gt, DegradeParams(), [7, 2])
    r = alignment_metrics(initial, gt, root / "reference", AlignmentParams())
    assert r["mask_iou"] < 0.95
    assert r["pose_change_trans"] > 0 and r["pose_change_rot"] > 0
    # both reference sources agree
    r2 = alignment_metrics(initial, gt, root / "reference", AlignmentParams(reference="gt_render"))
    assert r2["mask_iou"] == pytest.approx(r["mask_iou"], abs=1e-12)


def test_object_shifted_by_its_width_loses_its_mask(bench):
    root, gt, camera = bench
    o = gt.get("obj_03")
    width = 0.12 * np.sqrt(2)  # the cube's horizontal diagonal: its image width for any view azimuth
    pose = make_pose(translation=o.pose[:3, 3] + width * _camera_right(camera))
    r = alignment_metrics(_moved(gt, "obj_03", pose), gt, root / "reference", AlignmentParams())
    assert r["objects"]["obj_03"]["mask_iou"] < 0.05
    assert r["objects"]["obj_03"]["pose_change_trans"] == pytest.approx(width)
    assert r["objects"]["obj_01"]["mask_iou"] > 0.98


def test_object_out_of_view_scores_zero(bench):
    root, gt, _ = bench
    o = gt.get("obj_04")
    pose = make_pose(translation=o.pose[:3, 3] + [0.0, 0.0, 50.0])
    r = alignment_metrics(_moved(gt, "obj_04", pose), gt, root / "reference", AlignmentParams())
    v = r["objects"]["obj_04"]
    assert v["pixels_render"] == 0 and v["mask_iou"] == 0.0
    others = [r["objects"][k]["mask_iou"] for k in ("obj_01", "obj_02", "obj_03")]
    assert r["mask_iou"] == pytest.approx((sum(others) + 0.0) / 4)


def test_object_absent_from_both_is_skipped(tmp_path):
    gt = _scene(tmp_path)
    camera = camera_for(Scene(gt.objects[:3]), RenderParams(width=160, height=120))
    hidden = gt.with_poses({"obj_04": make_pose(translation=(0.0, 0.0, 50.0))})
    _write_reference(tmp_path, hidden, camera)
    r = alignment_metrics(hidden, hidden, tmp_path / "reference", AlignmentParams())
    assert r["objects"]["obj_04"]["mask_iou"] is None
    assert r["n_scored"] == 3 and r["mask_iou"] > 0.98


def test_pose_change_of_known_motions(bench):
    root, gt, _ = bench
    # obj_02: rotated 30 deg about z about its centre and moved by (0.03, -0.04, 0): 5 cm, 30 deg
    o = gt.get("obj_02")
    pose = make_pose(rotation_z(np.radians(30)), o.pose[:3, 3] + [0.03, -0.04, 0.0])
    r = alignment_metrics(_moved(gt, "obj_02", pose), gt, root / "reference", AlignmentParams())
    v = r["objects"]["obj_02"]
    assert v["pose_change_trans"] == pytest.approx(0.05) and v["pose_change_rot"] == pytest.approx(30.0)
    assert r["pose_change_trans"] == pytest.approx(0.05 / 4) and r["pose_change_rot"] == pytest.approx(30.0 / 4)
    assert v["scale_ratio"] == pytest.approx(1.0)


def test_anchor_com_versus_origin(tmp_path):
    # a box whose centre of mass sits 0.1 m from its local origin, turned 90 deg about z about the origin:
    # the origin stays, the centre of mass moves by 0.1 * sqrt(2)
    mesh = trimesh.creation.box(extents=(0.05, 0.05, 0.05), transform=make_pose(translation=(0.1, 0.0, 0.025)))
    path = save_mesh(mesh, tmp_path / "off.glb")
    before = Scene([SceneObject("obj_01", path.resolve(), make_pose(), color=(255, 0, 0))])
    after = before.with_poses({"obj_01": make_pose(rotation_z(np.pi / 2))})
    camera = camera_for(before, RenderParams(width=80, height=60))
    _write_reference(tmp_path, before, camera)
    com = alignment_metrics(after, before, tmp_path / "reference", AlignmentParams(anchor="com"))
    origin = alignment_metrics(after, before, tmp_path / "reference", AlignmentParams(anchor="origin"))
    assert com["pose_change_trans"] == pytest.approx(0.1 * np.sqrt(2), rel=1e-6)
    assert origin["pose_change_trans"] == pytest.approx(0.0, abs=1e-12)
    assert com["pose_change_rot"] == pytest.approx(90.0) == origin["pose_change_rot"]


def test_colour_from_initial_scene_and_mismatches(bench):
    root, gt, _ = bench
    uncoloured = gt.with_poses({})
    for o in uncoloured.objects:
        o.color = None
    r = alignment_metrics(uncoloured, gt, root / "reference", AlignmentParams())
    assert r["mask_iou"] > 0.98
    wrong = gt.with_poses({})
    wrong.objects[0].color = (1, 2, 3)
    with pytest.raises(InputError, match=r"objects\[0\]\.color.*differs"):
        alignment_metrics(wrong, gt, root / "reference", AlignmentParams())
    with pytest.raises(InputError, match="ids differ"):
        alignment_metrics(Scene(gt.objects[:2]), gt, root / "reference", AlignmentParams())


def test_bad_reference_is_reported(bench, tmp_path):
    root, gt, camera = bench
    with pytest.raises(InputError, match="camera.json"):
        alignment_metrics(gt, gt, tmp_path, AlignmentParams())
    write_json(tmp_path / "camera.json", camera)
    with pytest.raises(InputError, match="segmentation.png.*not found"):
        alignment_metrics(gt, gt, tmp_path, AlignmentParams())
    save_png(load_png(root / "reference" / "segmentation.png")[:60], tmp_path / "segmentation.png")
    with pytest.raises(InputError, match="size 160x60 differs"):
        alignment_metrics(gt, gt, tmp_path, AlignmentParams())


def test_params_from_dict():
    assert AlignmentParams.from_dict(None) == AlignmentParams()
    p = AlignmentParams.from_dict({"reference": "gt_render", "anchor": "origin", "min_pixels": 5})
    assert (p.reference, p.anchor, p.min_pixels) == ("gt_render", "origin", 5)
    with pytest.raises(ValueError, match="unknown alignment parameters"):
        AlignmentParams.from_dict({"clip": True})
    with pytest.raises(ValueError, match="anchor"):
        AlignmentParams.from_dict({"anchor": "centroid"})


def test_instance_labels_are_the_first_box_each_pixel_ray_hits(tmp_path):
    """Oracle: the slab test of every pixel's ray (camera.json's pinhole model) against each axis-aligned box."""
    gt = _scene(tmp_path)
    camera = camera_for(gt, RenderParams(width=96, height=72))
    labels = instance_labels(gt, camera)
    c2w = np.linalg.inv(np.asarray(camera["world_to_camera"]))
    u, v = np.meshgrid(np.arange(96.0), np.arange(72.0))
    d = np.stack([(u - camera["cx"]) / camera["fx"], (v - camera["cy"]) / camera["fy"], np.ones_like(u)], -1)
    d = d.reshape(-1, 3) @ c2w[:3, :3].T
    o = c2w[:3, 3]
    first = np.full(len(d), np.inf)
    want = np.full(len(d), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ground = np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)
        for k, (size, centre) in enumerate(BOXES):
            lo, hi = np.asarray(centre) - np.asarray(size) / 2, np.asarray(centre) + np.asarray(size) / 2
            t1, t2 = (lo - o) / d, (hi - o) / d
            near, far = np.minimum(t1, t2).max(axis=1), np.maximum(t1, t2).min(axis=1)
            hit = (near <= far) & (far > 0) & (near < first) & (near < ground)
            first[hit], want[hit] = near[hit], k
    # at most a pixel whose ray grazes an edge (float32 rays) may go the other way
    assert (labels.ravel() != want).sum() <= 1
    assert set(np.unique(labels)) == {-1, 0, 1, 2, 3}
