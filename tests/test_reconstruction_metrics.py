"""Reconstruction metrics: chamfer, F-score, normalisation, ICP, box IoU, scene alignment, whole scenes.

Oracles: closed-form distances of shifted grids, brute-force nearest neighbours
(``scipy.spatial.distance.cdist``), known rigid and similarity transforms,
box volumes computed by hand.
"""

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import cdist
from scipy.spatial.transform import Rotation

from phiscene.errors import InputError
from phiscene.meshes import save_mesh
from phiscene.metrics.reconstruction import (
    ReconParams,
    align_paper,
    apply_transform,
    bbox_iou,
    chamfer_and_fscore,
    chamfer_distance,
    fscore,
    icp,
    nearest_distances,
    normalize_to_unit_box,
    reconstruction_metrics,
    reconstruction_metrics_file,
    similarity_prealign,
)
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.transforms import make_pose, rotation_z

FAST = ReconParams(points=4096, object_points=1024)


def grid(n: int, spacing: float) -> np.ndarray:
    """(n^3, 3) regular grid."""
    ax = np.arange(n) * spacing
    return np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), axis=-1).reshape(-1, 3)


def asymmetric_cloud(n: int, seed: int) -> np.ndarray:
    """Random anisotropic, non-symmetric points (a skewed blob plus an off-centre lobe)."""
    rng = np.random.default_rng(seed)
    body = rng.normal(size=(n, 3)) * [0.5, 0.25, 0.1]
    lobe = rng.normal(size=(n // 4, 3)) * 0.05 + [0.4, 0.2, 0.15]
    return np.vstack([body, lobe])


# ----------------------------------------------------------------------------- chamfer / F-score


def test_identical_clouds_have_zero_chamfer_and_unit_fscore():
    a = asymmetric_cloud(500, 0)
    assert chamfer_distance(a, a) == 0.0
    assert fscore(a, a, 0.1) == pytest.approx(1.0, abs=1e-7)


@pytest.mark.parametrize("d", [0.03, 0.125, 0.25])  # 0.125 = tau exactly (binary-exact): the test is strict
def test_two_single_points(d):
    a, b = np.zeros((1, 3)), np.array([[0.0, d, 0.0]])
    assert chamfer_distance(a, b) == pytest.approx(2 * d**2, rel=1e-12)
    assert fscore(a, b, 0.125) == pytest.approx(1.0 if d < 0.125 else 0.0, abs=1e-7)


def test_grid_shifted_by_half_spacing():
    # every point of either grid has its nearest neighbour exactly h/2 away (along the shift axis)
    h = 0.04
    a = grid(8, h)
    b = a + [h / 2, 0.0, 0.0]
    np.testing.assert_allclose(nearest_distances(a, b), h / 2, rtol=1e-12)
    assert chamfer_distance(a, b) == pytest.approx(2 * (h / 2) ** 2, rel=1e-10)
    assert fscore(a, b, tau=0.6 * h) == pytest.approx(1.0, abs=1e-7)
    assert fscore(a, b, tau=0.4 * h) == 0.0


def test_fscore_known_precision_and_recall():
    # half of the prediction is far from the GT: P = 1/2, R = 1 -> F = 2/3
    b = grid(6, 0.05)
    a = np.vstack([b, b + [10.0, 0.0, 0.0]])
    assert fscore(a, b, 0.1) == pytest.approx(2 / 3, abs=1e-7)
    assert fscore(b, a, 0.1) == pytest.approx(2 / 3, abs=1e-7)  # now P = 1, R = 1/2
    # a point exactly tau away does not count, on either side
    one, two = np.zeros((1, 3)), np.array([[0.0, 0.125, 0.0], [0.0, 0.0, 0.0]])
    assert fscore(one, two, 0.125) == pytest.approx(2 / 3, abs=1e-7)
    assert fscore(two, one, 0.125) == pytest.approx(2 / 3, abs=1e-7)


def test_nearest_distances_match_brute_force():
    rng = np.random.default_rng(3)
    a, b = rng.uniform(-1, 1, size=(700, 3)), rng.normal(size=(450, 3))
    ref_ab, ref_ba = cdist(a, b).min(axis=1), cdist(b, a).min(axis=1)
    np.testing.assert_allclose(nearest_distances(a, b), ref_ab, rtol=1e-12, atol=1e-14)
    assert chamfer_distance(a, b) == pytest.approx(np.mean(ref_ab**2) + np.mean(ref_ba**2), rel=1e-12)
    p, r = np.mean(ref_ab < 0.1), np.mean(ref_ba < 0.1)
    assert fscore(a, b, 0.1) == pytest.approx(2 * p * r / (p + r + 1e-8), rel=1e-12)
    assert chamfer_and_fscore(a, b, 0.1) == (chamfer_distance(a, b), fscore(a, b, 0.1))


def test_bad_point_arrays_are_refused():
    with pytest.raises(ValueError, match="shape"):
        chamfer_distance(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        fscore(np.full((2, 3), np.nan), np.zeros((4, 3)))


# ----------------------------------------------------------------------------- normalisation


def test_normalize_maps_each_axis_exactly_onto_the_box():
    p = asymmetric_cloud(400, 1) * [3.0, 0.2, 7.0] + [5.0, -2.0, 1.0]
    n = normalize_to_unit_box(p)
    np.testing.assert_array_equal(n.min(axis=0), [-0.95] * 3)
    np.testing.assert_array_equal(n.max(axis=0), [0.95] * 3)
    # per-axis affine invariance: any positive per-axis scale and shift gives the same result
    np.testing.assert_allclose(normalize_to_unit_box(p * [0.1, 4.0, 2.0] - 3.0), n, atol=1e-12)
    # a flat axis keeps scale 1 and maps to -bound (MIDI's convention)
    flat = p.copy()
    flat[:, 2] = 4.0
    np.testing.assert_array_equal(normalize_to_unit_box(flat, 0.5)[:, 2], -0.5)


# ----------------------------------------------------------------------------- ICP


def test_icp_recovers_a_known_rigid_transform():
    src = asymmetric_cloud(2000, 2)
    t = make_pose(Rotation.from_rotvec([0.04, -0.06, 0.09]).as_matrix(), [0.05, -0.03, 0.02])
    tgt = apply_transform(t, src)
    found = icp(src, tgt, np.eye(4), max_iterations=50)
    np.testing.assert_allclose(found, t, atol=1e-4)
    # with a good initial guess a larger motion is recovered too, and init is part of the result
    big = make_pose(rotation_z(1.2), [1.0, 2.0, 0.5])
    tgt2 = apply_transform(big, src)
    init = make_pose(rotation_z(1.15), [0.97, 2.02, 0.5])
    np.testing.assert_allclose(icp(src, tgt2, init), big, atol=1e-4)


# ----------------------------------------------------------------------------- boxes


def test_bbox_iou_of_known_boxes():
    unit = np.array([[0, 0, 0], [1, 1, 1]], dtype=float)
    assert bbox_iou(unit, unit) == pytest.approx(1.0, abs=1e-7)
    assert bbox_iou(unit, unit + [2, 0, 0]) == 0.0
    assert bbox_iou(unit, unit + [1, 0, 0]) == 0.0  # touching faces
    assert bbox_iou(unit, unit + [0.5, 0, 0]) == pytest.approx(1 / 3, abs=1e-7)
    inner = np.array([[0.25, 0.25, 0.25], [0.75, 0.75, 0.75]])
    assert bbox_iou(unit, inner) == pytest.approx(0.125, abs=1e-7)
    other = np.array([[0.5, -1, 0.2], [3, 0.5, 0.6]])
    assert bbox_iou(unit, other) == bbox_iou(other, unit)
    # 0.5 * 0.5 * 0.4 overlap; volumes 1 and 2.5 * 1.5 * 0.4
    assert bbox_iou(unit, other) == pytest.approx(0.1 / (1 + 1.5 - 0.1), abs=1e-7)
    with pytest.raises(ValueError, match="min <= max"):
        bbox_iou(unit[::-1], unit)


# ----------------------------------------------------------------------------- scene alignment


def test_similarity_prealign_scale_ignores_axis_order():
    # a 90 degree turn swaps the x and y extents; sorting them keeps the scale exact
    src = asymmetric_cloud(500, 4)
    t = make_pose(rotation_z(np.pi / 2), [3.0, -1.0, 0.5], 1.7)
    tgt = apply_transform(t, src)
    pre = similarity_prealign(src, tgt)
    assert np.cbrt(np.linalg.det(pre[:3, :3])) == pytest.approx(1.7, rel=1e-12)
    np.testing.assert_allclose(apply_transform(pre, src).mean(axis=0), tgt.mean(axis=0), atol=1e-12)


def test_paper_alignment_undoes_a_similarity():
    src = asymmetric_cloud(1500, 5)
    # without rotation the extents scale exactly, so the alignment is exact
    t = make_pose(None, [0.3, -0.2, 0.1], 1.3)
    tgt = apply_transform(t, src)
    np.testing.assert_allclose(align_paper(src, tgt, FAST), t, atol=1e-9)
    # a small rotation changes the box extents a little: the scale is then approximate and the
    # rigid ICP cannot remove the rest, but the result is far better than ICP alone
    t = make_pose(Rotation.from_rotvec([0.0, 0.02, 0.05]).as_matrix(), [0.3, -0.2, 0.1], 1.3)
    tgt = apply_transform(t, src)
    found = align_paper(src, tgt, FAST)
    assert np.cbrt(np.linalg.det(found[:3, :3])) == pytest.approx(1.3, rel=0.01)
    icp_only = chamfer_distance(apply_transform(icp(src, tgt), src), tgt)
    assert chamfer_distance(apply_transform(found, src), tgt) < 0.01 * icp_only


# ----------------------------------------------------------------------------- whole scenes


def _meshes(root):
    wedge = trimesh.Trimesh([[0, 0, 0], [0.4, 0, 0], [0, 0.2, 0], [0, 0, 0.3]],
                            [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return {
        "box": save_mesh(trimesh.creation.box([0.6, 0.4, 0.3]), root / "meshes" / "box.glb"),
        "cyl": save_mesh(trimesh.creation.cylinder(0.15, 0.5, sections=24), root / "meshes" / "cyl.glb"),
        "cone": save_mesh(trimesh.creation.cone(0.2, 0.4, sections=24), root / "meshes" / "cone.glb"),
        "wedge": save_mesh(wedge, root / "meshes" / "wedge.obj"),
    }


def make_scene(root, name: str, world: np.ndarray | None = None, drop: tuple = ()) -> Scene:
    """A 6-object room-like scene, every pose premultiplied by ``world`` (identity); saved and reloaded."""
    world = np.eye(4) if world is None else world
    m = _meshes(root)
    layout = [("table", "box", make_pose(rotation_z(0.2), [0, 0, 0.15])),
              ("lamp", "cyl", make_pose(None, [1.2, 0.3, 0.25])),
              ("plant", "cone", make_pose(rotation_z(0.7), [-1.0, 0.8, 0.0], 1.5)),
              ("stool", "wedge", make_pose(rotation_z(-0.4), [0.4, -1.1, 0.0], 2.0)),
              ("shelf", "box", make_pose(rotation_z(1.3), [-1.5, -0.9, 0.15], 0.8)),
              ("vase", "cyl", make_pose(None, [0.1, 0.05, 0.55], 0.4))]
    objs = [SceneObject(oid, m[mesh], world @ pose) for oid, mesh, pose in layout if oid not in drop]
    return load_scene(save_scene(Scene(objs), root / name / "scene.json"))


def test_scene_against_itself_is_perfect(tmp_path):
    gt = make_scene(tmp_path, "gt")
    r = reconstruction_metrics(gt, gt, FAST)
    for k in ("scene_cd", "scene_cd_icp", "object_cd"):
        assert r[k] == pytest.approx(0.0, abs=1e-20), k
    for k in ("scene_fscore", "scene_fscore_icp", "object_fscore", "bbox_iou", "bbox_iou_raw"):
        assert r[k] == pytest.approx(1.0, abs=1e-6), k
    assert r["scene_scale"] == pytest.approx(1.0, abs=1e-12)
    assert (r["n_objects"], r["n_missing"], r["n_extra"]) == (6, 0, 0)
    assert set(r["objects"]) == set(gt.ids)


def test_similarity_moved_scene(tmp_path):
    # the prediction is the GT under a pure similarity: the paper's alignment undoes it exactly,
    # ICP alone cannot fix the scale, and per-object normalisation removes scale + shift per object
    gt = make_scene(tmp_path, "gt")
    world = make_pose(None, [0.3, -0.2, 0.1], 1.25)
    pred = make_scene(tmp_path, "pred", world=world)
    r = reconstruction_metrics(pred, gt, FAST)
    assert r["scene_scale"] == pytest.approx(1 / 1.25, rel=1e-6)
    assert r["scene_cd"] < 1e-8
    assert r["scene_fscore"] == pytest.approx(1.0, abs=1e-6)
    assert r["bbox_iou"] == pytest.approx(1.0, abs=1e-5)
    assert r["object_cd"] < 1e-10
    assert r["scene_cd_icp"] > 1e-3
    # raw boxes: each object is 1.25x larger and shifted, so IoU is at most 1 / 1.25^3
    assert r["bbox_iou_raw"] < 1 / 1.25**3


def test_missing_and_extra_objects(tmp_path):
    gt = make_scene(tmp_path, "gt", drop=("vase",))
    pred = make_scene(tmp_path, "pred", drop=("lamp",))
    r = reconstruction_metrics(pred, gt, FAST)
    assert (r["n_objects"], r["n_missing"], r["n_extra"]) == (4, 1, 1)
    assert set(r["objects"]) == {"table", "plant", "stool", "shelf"}
    assert r["scene_fscore"] < 1.0  # the missing lamp costs recall at scene level
    only = make_scene(tmp_path, "only", drop=("table", "lamp", "plant", "stool", "shelf"))
    with pytest.raises(InputError, match="no object id in common"):
        reconstruction_metrics(only, gt, FAST)


def test_file_entry_point_is_deterministic(tmp_path):
    gt = make_scene(tmp_path, "gt")
    pred = make_scene(tmp_path, "pred", world=make_pose(rotation_z(0.03), [0.05, 0.0, 0.0]))
    params = {"points": 2048, "object_points": 512, "seed": 7}
    a = reconstruction_metrics_file(pred.source, gt.source, tmp_path / "m.json", params)
    b = reconstruction_metrics_file(pred.source, gt.source, tmp_path / "m2.json", params)
    assert (tmp_path / "m.json").read_text() == (tmp_path / "m2.json").read_text()
    assert a == b
    assert 0 < a["scene_cd_icp"] < 1e-3 and a["bbox_iou"] > a["bbox_iou_raw"] - 1e-9


def test_params_from_dict():
    assert ReconParams.from_dict(None) == ReconParams()
    assert ReconParams.from_dict({"tau": 0.05}).tau == 0.05
    with pytest.raises(ValueError, match="unknown reconstruction metric parameters"):
        ReconParams.from_dict({"n_points": 10})
    with pytest.raises(ValueError, match="tau"):
        ReconParams.from_dict({"tau": 0})
