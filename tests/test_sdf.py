"""Exact signed distance (phiscene.sdf) against analytic SDFs and independent inside/outside oracles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from phiscene.sdf import (
    SignedDistance,
    WindingParams,
    WindingTree,
    sign_box,
    signed_distance,
    signed_distance_for,
    winding_number_exact,
)

RANDOM_URDFS = Path(__import__("pybullet_data").getDataPath()) / "random_urdfs"


def box_sdf(points: np.ndarray, half: np.ndarray, center=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Closed-form SDF of an axis-aligned box."""
    q = np.abs(points - np.asarray(center)) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def open3d_parity_sign(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """open3d's own signed distance (ray parity), the method phiscene.sdf replaces."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    return scene.compute_signed_distance(o3d.core.Tensor(points.astype(np.float32)), nsamples=3).numpy()


def test_unit_box_matches_closed_form():
    rng = np.random.default_rng(0)
    mesh = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    pts = rng.uniform(-0.8, 0.8, size=(4000, 3))
    got = signed_distance(mesh, pts)
    want = box_sdf(pts, np.full(3, 0.5))
    assert (want < 0).sum() > 300 and (want > 0).sum() > 300  # both sides exercised
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_scaled_moved_box_far_from_origin():
    # float64 accuracy does not depend on where the mesh sits (open3d's BVH works in float32)
    rng = np.random.default_rng(1)
    center, half = np.array([120.0, -45.0, 3.0]), np.array([0.02, 0.05, 0.01])
    mesh = trimesh.creation.box(extents=2 * half)
    mesh.apply_translation(center)
    pts = center + rng.uniform(-0.1, 0.1, size=(2000, 3))
    np.testing.assert_allclose(signed_distance(mesh, pts), box_sdf(pts, half, center), atol=1e-9)


def test_sphere_within_tessellation_error():
    rng = np.random.default_rng(2)
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    # the mesh lies between radius 1 - eps (face planes) and 1 (vertices)
    eps = 1.0 - np.abs(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles[:, 0])).min()
    pts = rng.normal(size=(3000, 3))
    pts *= (rng.uniform(0.0, 2.0, size=3000) / np.linalg.norm(pts, axis=1))[:, None]
    got = signed_distance(mesh, pts)
    want = np.linalg.norm(pts, axis=1) - 1.0
    assert eps < 2e-3
    clear = np.abs(want) > eps
    assert np.abs(got - want)[clear].max() <= eps + 1e-9
    assert np.abs(got - want).max() <= 2 * eps + 1e-9
    assert np.all(np.sign(got[clear]) == np.sign(want[clear]))


def test_unsigned_distance_matches_trimesh_closest_point():
    rng = np.random.default_rng(3)
    mesh = trimesh.load(RANDOM_URDFS / "000" / "000.obj", force="mesh", process=False)
    lo, hi = mesh.bounds
    pts = rng.uniform(lo - 1.0, hi + 1.0, size=(1500, 3))
    _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
    np.testing.assert_allclose(SignedDistance(mesh).unsigned(pts), dist, atol=1e-9)


def two_overlapping_boxes() -> tuple[trimesh.Trimesh, list[trimesh.Trimesh]]:
    """Two closed boxes concatenated without a boolean union; they overlap in [0.6, 1]^3-ish."""
    a = trimesh.creation.box(bounds=[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    b = trimesh.creation.box(bounds=[[0.6, 0.3, 0.2], [1.6, 1.3, 1.2]])
    return trimesh.util.concatenate([a, b]), [a, b]


def test_overlapping_shells_inside_where_parity_fails():
    mesh, (a, b) = two_overlapping_boxes()
    rng = np.random.default_rng(4)
    pts = rng.uniform(-0.2, 1.8, size=(6000, 3))
    in_a = np.all((pts > 0.0) & (pts < 1.0), axis=1)
    in_b = np.all((pts > [0.6, 0.3, 0.2]) & (pts < [1.6, 1.3, 1.2]), axis=1)
    sd = signed_distance(mesh, pts)
    # analytic oracle: inside the union; the distance is to the nearest face of either box
    want = np.where(in_a | in_b, -1.0, 1.0) * np.minimum(np.abs(box_sdf(pts, np.full(3, 0.5), np.full(3, 0.5))),
                                                         np.abs(box_sdf(pts, np.full(3, 0.5), [1.1, 0.8, 0.7])))
    np.testing.assert_allclose(sd, want, atol=1e-9)
    both = in_a & in_b
    assert both.sum() > 100
    assert np.all(sd[both] < 0)
    assert np.all(SignedDistance(mesh).winding(pts[both]) == pytest.approx(2.0, abs=1e-6))
    # open3d's ray parity counts two crossings out of the overlap: outside
    parity = open3d_parity_sign(mesh, pts)
    assert np.mean(parity[both] > 0) > 0.9
    assert np.all((parity > 0)[~(in_a | in_b)])


def test_touching_shells():
    # a stack of two boxes sharing the face z = 1: a point just below or above it is inside
    a = trimesh.creation.box(bounds=[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    b = trimesh.creation.box(bounds=[[0.2, 0.2, 1.0], [0.8, 0.8, 2.0]])
    mesh = trimesh.util.concatenate([a, b])
    xy = np.random.default_rng(5).uniform(0.3, 0.7, size=(200, 2))
    for z, inside in ((0.99, True), (1.01, True), (0.5, True), (1.5, True), (2.01, False)):
        pts = np.column_stack([xy, np.full(len(xy), z)])
        sd = signed_distance(mesh, pts)
        assert np.all((sd < 0) == inside), z
    # beside the upper box, above the lower one: outside
    pts = np.column_stack([np.full(50, 0.1), np.linspace(0.1, 0.9, 50), np.full(50, 1.3)])
    assert np.all(signed_distance(mesh, pts) > 0)


@pytest.mark.parametrize("name", ["000", "018", "024"])
def test_random_urdfs_matches_shell_oracle_where_parity_does_not(name):
    """pybullet's random_urdfs meshes are overlapping closed shells; the oracle is trimesh's
    containment test on each shell alone (a single closed shell has a well-defined inside)."""
    mesh = trimesh.load(RANDOM_URDFS / name / f"{name}.obj", force="mesh", process=False)
    merged = mesh.copy()
    merged.merge_vertices()
    shells = merged.split(only_watertight=True)
    assert len(shells) > 1
    rng = np.random.default_rng(6)
    lo, hi = mesh.bounds
    pts = np.concatenate([rng.uniform(lo, hi, size=(1500, 3)),
                          mesh.sample(1500, seed=7) + rng.normal(0.0, 0.02 * np.linalg.norm(hi - lo), (1500, 3))])
    oracle = np.zeros(len(pts), dtype=bool)
    for s in shells:
        oracle |= s.contains(pts)
    sdf = SignedDistance(mesh)
    sd = sdf(pts)
    decided = np.abs(sd) > 1e-6 * np.linalg.norm(hi - lo)  # containment is ambiguous on the surface
    assert np.array_equal((sd < 0)[decided], oracle[decided])
    parity = open3d_parity_sign(mesh, pts)
    assert ((parity < 0) != oracle)[decided].sum() >= 10


def test_hierarchy_close_to_exact_and_same_sign():
    mesh = trimesh.load(RANDOM_URDFS / "000" / "000.obj", force="mesh", process=False).subdivide()
    tri = np.asarray(mesh.triangles)
    lo, hi = mesh.bounds
    rng = np.random.default_rng(8)
    pts = np.concatenate([rng.uniform(lo, hi, size=(600, 3)),
                          mesh.sample(600, seed=9) + rng.normal(0.0, 1e-3 * np.linalg.norm(hi - lo), (600, 3))])
    exact = winding_number_exact(tri, pts)
    tree = WindingTree(tri)
    approx = tree.approximate(pts)
    assert np.abs(approx - exact).max() < 0.1 < WindingParams().exact_band
    assert np.array_equal(tree(pts) > 0.5, exact > 0.5)
    # near the threshold the exact recomputation matches the brute-force oracle
    band = np.abs(exact - 0.5) < WindingParams().exact_band
    np.testing.assert_allclose(tree(pts)[band], exact[band], atol=1e-9)


def test_open_mesh_interior_still_inside():
    # a sphere with a hole: the winding number degrades gracefully (parity would be arbitrary)
    mesh = trimesh.creation.icosphere(subdivisions=3)
    keep = mesh.triangles_center[:, 2] < 0.9  # cut a cap off the top
    holed = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)
    pts = np.array([[0.0, 0.0, 0.0], [0.3, 0.2, -0.4], [0.0, 0.0, 0.5], [0.0, 0.0, 1.5], [2.0, 0.0, 0.0]])
    sd = signed_distance(holed, pts)
    assert list(sd < 0) == [True, True, True, False, False]


def test_points_outside_sign_box_are_outside_without_winding():
    mesh = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    sdf = SignedDistance(mesh)
    box = sign_box(mesh)
    assert np.all(box[0] < -0.5) and np.all(box[0] > -0.5 - 1e-5)
    pts = np.array([[0.5 + 1e-3, 0.0, 0.0], [0.0, 0.0, -0.5 - 1e-4]])
    assert np.all(sdf(pts) > 0)
    # a surface point stays inside the padded box, so it is classified by its winding number
    assert np.all(np.abs(sdf(np.array([[0.5, 0.1, 0.2]]))) < 1e-12)


def test_cache_and_input_checks():
    a = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    b = a.copy()
    c = trimesh.creation.box(extents=[1.0, 1.0, 2.0])
    assert signed_distance_for(a) is signed_distance_for(b)
    assert signed_distance_for(a) is not signed_distance_for(c)
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        signed_distance(a, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="NaN"):
        signed_distance(a, np.array([[0.0, np.nan, 0.0]]))
    assert signed_distance(a, np.zeros((0, 3))).shape == (0,)
    with pytest.raises(ValueError, match="unknown winding"):
        WindingParams.from_dict({"leafsize": 4})
