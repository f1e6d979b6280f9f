"""Hollow, double-walled reconstructions (phiscene.solid) against the solid they stand for.

The oracle of every test is a mesh whose solid is known: a double-walled sphere stands for the ball of its outer
sphere, so its signed distance must equal the outer sphere's alone (an independent, single-shell computation), its
proxies must cover that ball, and a ball put inside its cavity is inside it.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from phiscene.proxies import ProxyParams, decompose_route, fidelity
from phiscene.sdf import SignedDistance, winding_number_exact
from phiscene.solid import ShellParams, inner_faces, outer_shell, solid_surface


def double_wall(radius: float = 0.1, wall: float = 0.004, hole: float = 0.0, subdivisions: int = 4):
    """A sphere shell as a 3D foundation model writes it: outer sphere outward, inner sphere facing the cavity.

    ``hole`` > 0 removes a cap of that angular radius (rad) around +z from both walls (the walls' opening).
    Returns the mesh and the outer sphere (with the same hole), the oracle.
    """
    outer = trimesh.creation.icosphere(subdivisions, radius)
    inner = trimesh.creation.icosphere(subdivisions, radius - wall)
    inner.invert()
    if hole > 0:
        for m in (outer, inner):
            m.update_faces(m.triangles_center[:, 2] < np.cos(hole) * np.linalg.norm(m.triangles_center, axis=1))
            m.remove_unreferenced_vertices()
    return trimesh.util.concatenate([outer, inner]), outer


def test_double_wall_sphere_is_the_ball_of_its_outer_wall():
    mesh, outer = double_wall()
    centre = np.zeros((1, 3))
    assert abs(winding_number_exact(mesh.triangles, centre)[0]) < 1e-9  # the cavity is "outside" the raw mesh
    shell = outer_shell(mesh)
    assert len(shell.faces) == len(outer.faces)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.12, 0.12, size=(2000, 3))
    got = SignedDistance(mesh)(pts)
    want = SignedDistance(outer)(pts)  # the oracle: the outer sphere alone
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert got[np.linalg.norm(pts, axis=1) < 0.09].max() < 0  # the whole cavity is inside


def test_walls_meeting_around_a_small_opening_are_still_a_solid():
    # a 2.4 cm opening on a 20 cm sphere: less than seal x the longest axis, so the cavity is sealed
    mesh, outer = double_wall(hole=0.12)
    inner = inner_faces(mesh)
    assert inner.sum() == len(mesh.faces) - len(outer.faces)
    assert SignedDistance(mesh)(np.zeros((1, 3)))[0] < -0.09


@pytest.mark.parametrize("hole", [np.pi / 2, 1.2])
def test_a_bowl_or_cup_open_to_the_outside_keeps_its_cavity_outside(hole):
    mesh, _ = double_wall(hole=hole)
    assert not inner_faces(mesh).any()
    assert outer_shell(mesh) is mesh


def test_solids_overlaps_and_inward_meshes_are_unchanged():
    T = trimesh.transformations.translation_matrix
    box = trimesh.creation.box([1.0, 0.5, 0.2])
    overlap = trimesh.util.concatenate([trimesh.creation.box([1, 1, 1]),
                                        trimesh.creation.box([1, 1, 1], transform=T([0.5, 0, 0]))])
    inward = trimesh.creation.icosphere(3, 1.0)
    inward.invert()
    for m in (box, overlap, inward):
        assert outer_shell(m) is m


def test_a_mesh_not_hollow_is_its_own_shell_whoever_asked_first():
    # the shells are remembered by content: the same mesh as another object (the same file loaded again, an asset
    # and its saved copy) must still get itself back, not the object first seen, or ``outer_shell(m) is m`` fails
    # for it and its proxies take the route of hollow meshes
    box = trimesh.creation.box([0.3, 0.2, 0.1])
    twin = trimesh.Trimesh(box.vertices.copy(), box.faces.copy(), process=False)
    assert outer_shell(box) is box
    assert outer_shell(twin) is twin
    fruit, _ = double_wall(radius=0.05, wall=0.002, subdivisions=3)  # hollow: a shell of its own either way
    again = trimesh.Trimesh(fruit.vertices.copy(), fruit.faces.copy(), process=False)
    a, b = outer_shell(fruit), outer_shell(again)
    assert a is not fruit and b is not again and np.array_equal(a.faces, b.faces)


def test_proxies_of_a_mesh_do_not_depend_on_what_was_decomposed_before(tmp_path):
    # oracle: the same mesh decomposed in a fresh cache gives the same route and hulls as the first time, also when
    # it is another object with that content and the first one's shell is still remembered in this process
    from phiscene.meshes import save_mesh
    from phiscene.proxies import proxy_for_mesh

    mesh = trimesh.creation.annulus(0.05, 0.08, 0.04)  # not convex, not hollow: decomposed
    params = ProxyParams(max_hulls=4, mcts_iterations=10, mcts_nodes=8, resolution=300)
    first = proxy_for_mesh(save_mesh(mesh, tmp_path / "a.obj"), params, tmp_path / "cache_a")
    second = proxy_for_mesh(save_mesh(mesh, tmp_path / "b.obj"), params, tmp_path / "cache_b")
    assert first.meta["route"] == second.meta["route"] == "decomposed"
    assert len(first.hulls) == len(second.hulls) and all(np.array_equal(x, y) for x, y in zip(first.hulls,
                                                                                             second.hulls))


def test_shell_params_rejects_bad_values():
    with pytest.raises(ValueError):
        ShellParams.from_dict({"resolution": 4})
    with pytest.raises(ValueError):
        ShellParams.from_dict({"seal": 0.6})


def test_solid_surface_of_a_double_wall_is_closed_and_on_the_outer_sphere():
    mesh, _ = double_wall()
    surface = solid_surface(mesh, 32)
    assert surface.is_watertight
    r = np.linalg.norm(surface.vertices, axis=1)
    cell = 0.2 / 32
    assert np.all(np.abs(r - 0.1) < cell)  # no inner wall: every vertex within a cell of the outer sphere


def test_a_double_wall_is_decomposed_as_its_solid_and_covered():
    fruit, outer = double_wall(radius=0.05, wall=0.002, subdivisions=5)
    fruit.apply_scale([1.0, 1.0, 1.6])  # an ellipsoid flattened below: a pear-like solid
    fruit.vertices[fruit.vertices[:, 2] < -0.06, 2] *= 0.5
    hulls, route = decompose_route(fruit, ProxyParams(convex_tolerance=0.0, max_hulls=8, mcts_iterations=10,
                                                      mcts_nodes=8, resolution=300))
    assert route == "solid"
    _, outside, _ = fidelity(fruit, hulls)
    diag = float(np.linalg.norm(fruit.extents))
    assert outside <= ProxyParams().solid_tolerance * diag
    # the hulls fill the solid (inside the outer wall alone, the oracle), not the 2 mm wall (6 % of it): on a
    # regular grid, the points inside the union of the hulls against those inside the outer wall
    solid = outer.copy()
    solid.vertices = fruit.vertices[: len(outer.vertices)]
    axes = [np.linspace(lo, hi, 40) for lo, hi in zip(*fruit.bounds)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    want = SignedDistance(solid)(grid) < 0
    got = np.zeros(len(grid), dtype=bool)
    for h in hulls:
        hull = trimesh.convex.convex_hull(h)
        got |= (grid @ hull.face_normals.T - np.einsum("ij,ij->i", hull.face_normals, hull.triangles[:, 0])).max(1) < 0
    assert (got & want).sum() >= 0.97 * want.sum()
    assert got.sum() <= 1.1 * want.sum()


def test_penetration_into_the_cavity_of_a_hollow_object_is_measured():
    from phiscene.meshes import sample_surface
    from phiscene.metrics.physical import worst_pair_distance
    from phiscene.sdf import signed_distance_for

    hollow, _ = double_wall()
    ball = trimesh.creation.icosphere(3, 0.02)  # a 2 cm ball at the centre of the 10 cm shell: 8 cm deep
    w = worst_pair_distance(sample_surface(ball, 512, 0), signed_distance_for(ball),
                            sample_surface(hollow, 512, 0), signed_distance_for(hollow))
    assert w == pytest.approx(-0.08, abs=0.004)


def test_cavity_share_of_a_double_wall_is_the_ball_inside_its_inner_wall():
    from phiscene.solid import ShellParams, cavity_share

    mesh, _ = double_wall(radius=0.1, wall=0.004)
    params = ShellParams()
    share = cavity_share(mesh, params)
    # the cavity is the ball inside the inner wall less the voxels the inner wall passes through (a band about
    # one voxel deep); the solid is the ball of the outer wall (the voxels it encloses or passes through)
    h = 0.2 / params.resolution
    lo, hi = ((0.096 - 1.5 * h) / (0.1 + 0.5 * h)) ** 3, (0.096 / 0.1) ** 3
    assert lo <= share <= hi
    assert cavity_share(trimesh.creation.icosphere(4, 0.1), params) == 0.0  # a solid ball: no cavity


def test_inner_face_masks_are_kept_on_disk_and_a_bad_file_is_recomputed(tmp_path, monkeypatch):
    import phiscene.solid as solid

    mesh, _ = double_wall(wall=0.005)
    expected = inner_faces(mesh)
    assert expected.any()
    solid.use_disk_cache(tmp_path)
    try:
        solid._CACHE.clear()
        first = outer_shell(mesh)
        files = list((tmp_path / "shells").glob("*.npy"))
        assert len(files) == 1
        np.testing.assert_array_equal(np.asarray(first.faces), np.asarray(mesh.faces)[~expected])

        # a fresh process (memory cache empty) reads the mask instead of classifying again
        solid._CACHE.clear()
        monkeypatch.setattr(solid, "inner_faces", lambda *a, **k: pytest.fail("classified again"))
        np.testing.assert_array_equal(np.asarray(outer_shell(mesh).faces), np.asarray(first.faces))

        # a truncated file is not this mesh's: recomputed and rewritten
        monkeypatch.undo()
        files[0].write_bytes(files[0].read_bytes()[:-8])
        solid._CACHE.clear()
        np.testing.assert_array_equal(np.asarray(outer_shell(mesh).faces), np.asarray(first.faces))
        assert solid._read_mask(files[0], len(mesh.faces)) is not None
    finally:
        solid.use_disk_cache(None)
        solid._CACHE.clear()


def test_a_solid_that_cannot_cover_the_mesh_is_not_decomposed(monkeypatch):
    """A double-walled ball with a fin 1 mm thick reaching 8 cm out of it: the solid's grid (40 cells across, 7 mm
    cells) loses the fin, so the fin's tip lies about 8 cm outside the convex hull of the solid's surface, and no
    decomposition of that surface can cover it (tolerance 2 % of the diagonal, 7 mm). The solid route is given up
    before the decomposition runs on it: the decomposition (here a stand-in returning the convex hull of what it
    is given) runs once, on the closed wrap of the mesh's outer shell."""
    import phiscene.proxies as proxies

    ball, _ = double_wall(radius=0.1, wall=0.004, subdivisions=3)
    fin = trimesh.creation.box((0.16, 0.001, 0.06))
    fin.apply_translation((0.1, 0.0, 0.0))  # from the ball's centre out to x = 0.18
    mesh = trimesh.util.concatenate([ball, fin])
    shell = outer_shell(mesh)
    assert solid_surface(shell, ProxyParams().solid_resolution).bounds[1, 0] < 0.11  # the grid lost the fin
    calls = []
    monkeypatch.setattr(proxies, "_decompose",
                        lambda m, p, closed=False: calls.append((len(m.faces), closed)) or [m.convex_hull.vertices])
    hulls, route = decompose_route(mesh, ProxyParams(convex_tolerance=0.0))
    assert not shell.is_watertight  # the shell (the ball's outer wall and the fin) is wrapped for CoACD
    assert route == "decomposed" and len(calls) == 1 and calls[0][1]
    _, outside, _ = fidelity(mesh, hulls)
    assert outside <= ProxyParams().solid_tolerance * float(np.linalg.norm(mesh.extents))


def test_a_solid_route_lost_is_not_tried_again_by_the_finer_decomposition(monkeypatch, tmp_path):
    """The ball with a fin above loses its solid route whatever the hull cap (the fin lies outside the solid's
    convex hull). With a stand-in decomposition that uses its whole cap and reaches far beyond the mesh, the
    first set (2 hulls) is refined (8); the refinement does not try the solid route again, and gives the hulls
    that trying it gives (the oracle: the same refinement with the solid route tried)."""
    import phiscene.proxies as proxies

    ball, _ = double_wall(radius=0.1, wall=0.004, subdivisions=3)
    fin = trimesh.creation.box((0.16, 0.001, 0.06))
    fin.apply_translation((0.1, 0.0, 0.0))
    path = tmp_path / "finned.obj"
    trimesh.util.concatenate([ball, fin]).export(path)
    fat = trimesh.creation.box((0.5, 0.5, 0.5)).vertices  # reaches 0.15 m and more beyond the 0.1 m ball
    monkeypatch.setattr(proxies, "_decompose", lambda m, p, closed=False: [fat + 1e-3 * k for k in range(p.max_hulls)])
    tried = []
    real_solid = proxies._decompose_solid
    monkeypatch.setattr(proxies, "_decompose_solid", lambda *a: tried.append(a[3].max_hulls) or real_solid(*a))
    params = ProxyParams(convex_tolerance=0.0, max_hulls=2, refine_max_hulls=8)
    px = proxies.proxy_for_mesh(path, params, tmp_path / "cache")
    assert tried == [2]  # the first decomposition only
    assert px.meta["refined"]["hulls"] == 2 and len(px.hulls) == 8 and px.meta["solid"] == "skipped"
    first = proxies._decomposition(proxies.load_mesh(path), px.meta["mesh_hash"], params, tmp_path / "cache")
    assert first.meta["solid"] == "lost"
    oracle, route = decompose_route(proxies.load_mesh(path), ProxyParams(convex_tolerance=0.0, max_hulls=8))
    assert tried == [2, 8] and route == "decomposed"
    assert [h.tolist() for h in oracle] == [h.tolist() for h in px.hulls]
