"""Real-size meshes (tens of thousands of faces, not watertight) through the proxies in bounded time."""

import time

import numpy as np
import pytest
import trimesh
from scenes import open_dense, table_mesh

from phiscene.proxies import ProxyParams, capped_hull, decimated, decompose_route, fidelity, hull_excess


def test_fruit_like_mesh_takes_one_hull_quickly():
    fruit = open_dense(trimesh.creation.icosphere(4, 0.05).apply_scale([1.0, 1.0, 1.25]))
    assert len(fruit.faces) >= 30000 and not fruit.is_watertight
    t0 = time.perf_counter()
    hulls, route = decompose_route(fruit, ProxyParams())
    assert route == "single_hull" and len(hulls) == 1
    assert time.perf_counter() - t0 < 10.0
    # the mesh's convex hull (thousands of vertices) capped at the vertex budget by a subset of its vertices: inside
    # the full hull (never beyond the mesh), within 0.5 % of the diagonal of every mesh point (fidelity's own plane
    # test) and within 2 % of the full hull's volume
    full = fruit.convex_hull
    assert len(full.vertices) > 2 * ProxyParams().max_hull_vertices
    assert len(hulls[0]) <= ProxyParams().max_hull_vertices
    assert full.contains(hulls[0] * 0.999).all()
    assert fidelity(fruit, hulls)[1] < 0.005 * np.linalg.norm(fruit.extents)
    assert trimesh.convex.convex_hull(hulls[0]).volume == pytest.approx(full.volume, rel=0.02)


def test_capped_hull_of_a_sphere_stays_on_the_sphere():
    sphere = trimesh.creation.icosphere(5, 1.0)  # 10242 vertices, all on its hull
    v = capped_hull(sphere, 256)
    assert len(v) <= 270
    # what is kept is the sphere: vertices within 2 % of the radius (a 256-vertex polytope is 0.6 % off between its
    # vertices), volume within 2 % of 4/3 pi r^3
    assert np.abs(np.linalg.norm(v, axis=1) - 1.0).max() < 0.02
    assert trimesh.convex.convex_hull(v).volume == pytest.approx(4.0 / 3.0 * np.pi, rel=0.02)
    # under the budget (or with no budget) the hull's own vertices, unchanged
    box = trimesh.creation.box((0.3, 0.2, 0.1))
    np.testing.assert_allclose(np.sort(capped_hull(box, 256), axis=0), np.sort(box.convex_hull.vertices, axis=0))
    assert len(capped_hull(sphere, 0)) == 10242


def test_table_is_decomposed_within_bounded_time_and_covers_the_mesh():
    table = open_dense(table_mesh())
    assert len(table.faces) >= 30000 and not table.is_watertight
    # the hull of a table on legs reaches far from its surface (under the top): ~ leg height / diagonal
    assert hull_excess(decimated(table, 2000)) > 0.1
    t0 = time.perf_counter()
    hulls, route = decompose_route(table, ProxyParams(mcts_iterations=10, mcts_nodes=8, resolution=300, max_hulls=8))
    elapsed = time.perf_counter() - t0
    assert route == "decomposed" and len(hulls) >= 2
    assert elapsed < 60.0, elapsed
    # the proxies cover the original (not the decimated) mesh within 2 % of its diagonal
    diag = float(np.linalg.norm(table.extents))
    assert fidelity(table, hulls)[1] < 0.02 * diag
    # and they do not fill the space under the top: a point 0.3 m below the top's centre is inside no hull
    probe = np.array([0.0, 0.0, 0.4])
    assert not any(trimesh.convex.convex_hull(h).contains([probe])[0] for h in hulls)


def test_decimation_keeps_shape_and_budget():
    closed = trimesh.creation.icosphere(6, 0.1)  # 81920 faces
    small = decimated(closed, 2000)
    assert len(small.faces) <= 2100
    assert np.abs(np.linalg.norm(small.vertices, axis=1) - 0.1).max() < 5e-3  # still the sphere
    # open boundaries are kept, so a mesh with many holes keeps more faces, but far fewer than it had
    dense = open_dense(trimesh.creation.box([0.3, 0.2, 0.1]))
    small = decimated(dense, 2000)
    assert len(small.faces) < len(dense.faces) / 4
    np.testing.assert_allclose(small.bounds, dense.bounds, atol=2e-3)
    assert decimated(dense, 0) is dense


@pytest.mark.parametrize("bad", [{"max_faces": 50}, {"convex_tolerance": -0.1}, {"convex_tolerance": 1.5}])
def test_bad_budgets_rejected(bad):
    with pytest.raises(ValueError):
        ProxyParams.from_dict(bad)


def test_sdf_grid_of_a_dense_mesh_uses_a_decimated_copy_within_its_recorded_error():
    from phiscene.sdf import signed_distance_for
    from phiscene.sdf_grid import GridParams, build_grid, near_surface_points

    fruit = open_dense(trimesh.creation.icosphere(4, 0.05).apply_scale([1.0, 1.0, 1.25]))
    grid = build_grid(fruit, GridParams(error_samples=1024))
    # the recorded error is against the full mesh; check it independently at other points
    pts = near_surface_points(fruit, 0.01, 512, seed=7)
    err = np.abs(grid.query_numpy(pts) - signed_distance_for(fruit)(pts))
    assert err.max() <= grid.error["max_abs"] * 1.5 + 1e-4
    assert grid.error["max_abs"] < 0.01  # under 1 cm on a 13 cm fruit


def test_excess_is_how_far_the_proxies_reach_beyond_an_open_mesh():
    """An open tray (a 0.4 m square bottom, 0.05 m walls, no lid): its one convex hull closes the top, whose
    surface lies up to the depth from the mesh; the 95th percentile of that reach is the depth (over a fifth of
    the hull's surface is the lid's middle, the depth from the bottom). Two hulls for two boxes reach nowhere."""
    tray = trimesh.creation.box((0.4, 0.4, 0.05))
    tray.update_faces(tray.face_normals[:, 2] < 0.5)  # drop the lid: open, not watertight
    tray = open_dense(tray, 5000)
    assert not tray.is_watertight
    ratio, outside, excess = fidelity(tray, [np.asarray(tray.convex_hull.vertices)])
    assert np.isnan(ratio) and outside < 1e-9
    assert excess == pytest.approx(0.05, abs=2e-3)
    boxes = [trimesh.creation.box((0.2, 0.2, 0.2)),
             trimesh.creation.box((0.1, 0.1, 0.1)).apply_translation([0.3, 0, 0])]
    _, _, tight = fidelity(trimesh.util.concatenate(boxes), [np.asarray(b.vertices) for b in boxes])
    assert tight < 1e-9


def test_table_proxies_reach_no_farther_than_the_mesh():
    # CoACD remeshes a mesh that is no closed manifold (this table's top and legs overlap, and it has holes) on a
    # voxel grid, whose hulls bulge past the mesh; cut back to the mesh's convex hull, nothing of the proxies
    # lies beyond the mesh's bounding box (a table resting on its proxies stands on its legs' ends, not above them)
    table = open_dense(table_mesh())
    hulls, _ = decompose_route(table, ProxyParams(mcts_iterations=10, mcts_nodes=8, resolution=300, max_hulls=8))
    points = np.vstack(hulls)
    tol = 1e-6 * float(np.linalg.norm(table.extents))
    assert np.all(points >= table.bounds[0] - tol) and np.all(points <= table.bounds[1] + tol)


def test_fit_to_mesh_cuts_a_bulging_hull_back_to_the_mesh():
    from phiscene.proxies import clip_to_hull, fit_to_mesh

    cube = trimesh.creation.box((1.0, 1.0, 1.0))
    # a hull 5 % larger than the cube about its centre: cut back, it is the cube itself
    cut = fit_to_mesh([cube.vertices * 1.05], cube, 0)
    assert len(cut) == 1
    np.testing.assert_allclose(np.sort(cut[0], axis=0), np.sort(cube.vertices, axis=0), atol=1e-9)
    # a slab crossing the cube's top face: what remains is its part inside, the box [-0.5, 0.5]^2 x [0.2, 0.5]
    slab = trimesh.creation.box((0.6, 0.6, 0.6), transform=trimesh.transformations.translation_matrix([0, 0, 0.5]))
    part = clip_to_hull(slab.vertices, cube)
    np.testing.assert_allclose(part.min(axis=0), [-0.3, -0.3, 0.2], atol=1e-9)
    np.testing.assert_allclose(part.max(axis=0), [0.3, 0.3, 0.5], atol=1e-9)
    assert trimesh.convex.convex_hull(part).volume == pytest.approx(0.6 * 0.6 * 0.3, rel=1e-9)
    # a piece inside the mesh's hull is returned as it is (the very array), and one wholly beyond it is dropped
    inner = cube.vertices * 0.5
    assert np.array_equal(fit_to_mesh([inner], cube, 0)[0], inner)
    assert clip_to_hull(inner, cube) is inner
    beyond = cube.vertices * 0.2 + [2.0, 0.0, 0.0]
    assert clip_to_hull(beyond, cube) is None
    assert len(fit_to_mesh([inner, beyond], cube, 0)) == 1


def test_vertex_cap_keeps_points_of_the_hull():
    from phiscene.proxies import farthest_points, fit_to_mesh

    sphere = trimesh.creation.icosphere(5, 1.0)  # 10242 vertices on the unit sphere
    v = fit_to_mesh([sphere.vertices], sphere, 256)[0]
    # a subset of the hull's own vertices: on the sphere exactly (never beyond it, as a decimated hull would be)
    assert len(v) <= 256
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    # farthest-point sampling spreads them about as evenly as a Fibonacci lattice of as many points on the sphere
    # (an inscribed polytope close to the best one): volume within 1 % of that lattice's hull
    k = np.arange(len(v)) + 0.5
    z, phi = 1.0 - 2.0 * k / len(v), np.pi * (1.0 + 5.0**0.5) * k
    lattice = np.column_stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z])
    assert trimesh.convex.convex_hull(v).volume == pytest.approx(trimesh.convex.convex_hull(lattice).volume, rel=0.01)
    # the first pick is the point farthest from the mean, then the point farthest from it
    line = np.array([[0.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0], [10.0, 0, 0]])
    np.testing.assert_array_equal(farthest_points(line, 2), line[[0, 3]])
    assert farthest_points(line, 9) is line


def test_the_nearly_convex_decision_does_not_depend_on_the_units_of_the_mesh():
    """A SAM 3D Objects mesh comes in a [-0.5, 0.5]^3 frame with its size in its pose; the same object baked in metres
    must get the same proxies. Oracle: the decimated copy taken at 1/0.35 the size, scaled back, is the copy taken
    in metres (to float32 precision), and so are the excess and the route; the plain decimation is not (its
    quadric thresholds are absolute), which is what made a reconstructed pear's route flip."""
    from phiscene.proxies import decimated_unit_free

    rng = np.random.default_rng(0)
    pear = open_dense(trimesh.creation.icosphere(3, 0.045).apply_scale([1.0, 1.0, 1.4]), 20000)
    pear.vertices += rng.normal(0.0, 0.0015, pear.vertices.shape)  # a scan's noise: quadric errors differ
    scaled = pear.copy().apply_scale(1 / 0.35)
    a, b = decimated_unit_free(pear, 2000), decimated_unit_free(scaled, 2000)
    assert len(a.faces) == len(b.faces) < len(pear.faces)
    np.testing.assert_allclose(np.asarray(b.vertices) * 0.35, a.vertices, atol=1e-6 * np.linalg.norm(pear.extents))
    assert hull_excess(a) == pytest.approx(hull_excess(b), abs=1e-6)
    plain = decimated(pear, 2000), decimated(scaled, 2000)
    assert len(plain[0].faces) != len(plain[1].faces) or not np.allclose(
        np.asarray(plain[1].vertices) * 0.35, plain[0].vertices, atol=1e-4 * np.linalg.norm(pear.extents))
    params = ProxyParams(backend="coacd", max_faces=2000)
    (ha, ra), (hb, rb) = decompose_route(pear, params), decompose_route(scaled, params)
    assert ra == rb and len(ha) == len(hb)


def test_a_decimation_that_loses_part_of_the_mesh_is_redone_with_more_faces(monkeypatch):
    """Two 10 cm cubes 50 cm apart (centres), as one mesh of 6,144 faces; a decimation (stand-in) that merges the
    second cube away below 8,000 faces. The farthest sample of the lost cube is at most sqrt(0.5^2 + 2 * 0.1^2)
    = 0.52 m and at least 0.3 m from the kept one (the oracle of decimation_loss); with a 2 cm tolerance the
    decimation is redone at 4 x 2000 = 8000 faces, where nothing is lost, and the mesh (under that budget) is kept
    whole. With tolerance 0 it is decimated once."""
    import phiscene.proxies as proxies

    a = trimesh.creation.box((0.1, 0.1, 0.1)).subdivide().subdivide().subdivide().subdivide()
    b = a.copy()
    b.apply_translation((0.5, 0.0, 0.0))
    mesh = trimesh.util.concatenate([a, b])
    assert len(mesh.faces) == 6144
    budgets = []

    def fake(m, max_faces):
        budgets.append(max_faces)
        if len(m.faces) <= max_faces:
            return m
        return a if max_faces < 8000 else m

    monkeypatch.setattr(proxies, "decimated_unit_free", fake)
    assert 0.3 <= proxies.decimation_loss(mesh, a) <= 0.52
    assert proxies.decimation_loss(mesh, mesh) == 0.0
    assert proxies.decimated_faithfully(mesh, 2000, 0.02) is mesh and budgets == [2000, 8000]
    budgets.clear()
    assert proxies.decimated_faithfully(mesh, 2000, 0.0) is a and budgets == [2000]


def test_a_decomposition_that_fills_the_space_under_a_table_is_redone_with_more_hulls(tmp_path):
    """Two hulls for a table on four legs must join legs: the piece spanning them fills the space under the top,
    where a point 0.3 m below the top's centre lies in no part of the mesh, and reaches far beyond the mesh (the
    leg height against a 1.4 m diagonal). That set used its whole cap and reaches farther than ``refine_excess``
    of the diagonal, so it is decomposed again with ``refine_max_hulls``; the finer set leaves the probe outside
    and reaches less far, and the record keeps the first set's count and excess. Each set is cached on its own:
    asked again, nothing is decomposed."""
    from phiscene.proxies import proxy_for_mesh

    path = tmp_path / "table.obj"
    table_mesh().export(path)
    diag = float(np.linalg.norm(table_mesh().extents))
    probe = np.array([[0.0, 0.0, 0.4]])
    light = dict(mcts_iterations=10, mcts_nodes=8, resolution=300, max_hulls=2, refine_max_hulls=8)

    def inside(px):
        return any(trimesh.convex.convex_hull(h).contains(probe)[0] for h in px.hulls)

    coarse = proxy_for_mesh(path, ProxyParams(**light, refine_excess=0.0), tmp_path / "cache")
    assert len(coarse.hulls) == 2 and inside(coarse) and coarse.excess > 0.03 * diag
    assert "refined" not in coarse.meta
    fine = proxy_for_mesh(path, ProxyParams(**light), tmp_path / "cache")
    assert 2 < len(fine.hulls) <= 8 and not inside(fine) and fine.excess < coarse.excess
    assert fine.meta["refined"] == {"hulls": 2, "excess": coarse.excess, "kept": True}
    assert len(list((tmp_path / "cache" / "proxies").glob("*.npz"))) == 2
    again = proxy_for_mesh(path, ProxyParams(**light), tmp_path / "cache")
    assert [h.tolist() for h in again.hulls] == [h.tolist() for h in fine.hulls]
    # no second cap larger than the first: no second decomposition
    assert "refined" not in proxy_for_mesh(path, ProxyParams(**{**light, "refine_max_hulls": 2}),
                                           tmp_path / "cache").meta


def test_a_textured_glb_loads_the_geometry_trimesh_reads_with_its_materials(tmp_path):
    # load_mesh skips decoding textures; the oracle is trimesh's own load of the same file with them
    from PIL import Image

    from phiscene.meshes import load_mesh

    mesh = open_dense(trimesh.creation.icosphere(subdivisions=2, radius=0.1), 6000)
    uv = np.random.default_rng(0).random((len(mesh.vertices), 2))
    image = Image.fromarray(np.random.default_rng(1).integers(0, 255, (64, 64, 3), dtype=np.uint8))
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, image=image)
    path = tmp_path / "textured.glb"
    mesh.export(path)
    full = trimesh.load(path, force="mesh", process=False)
    assert isinstance(full.visual, trimesh.visual.TextureVisuals) and full.visual.material.baseColorTexture is not None
    loaded = load_mesh(path)
    np.testing.assert_array_equal(loaded.vertices, full.vertices)
    np.testing.assert_array_equal(loaded.faces, full.faces)


def test_pieces_cut_to_their_vertex_cap_after_coacd_decimates_to_its_own():
    # CoACD decimates its hulls to coacd_hull_vertices, then each piece keeps at most max_hull_vertices of its own
    # vertices (fit_to_mesh's farthest-point subset): the same decomposition as with both caps at the higher value,
    # each piece cut to a subset of that one's vertices, so inside it
    table = table_mesh()
    light = dict(mcts_iterations=10, mcts_nodes=8, resolution=300, max_hulls=4, max_faces=0, convex_tolerance=0.0,
                 solid_resolution=0)
    wide, route = decompose_route(table, ProxyParams(**light, max_hull_vertices=64))
    assert route == "decomposed" and any(len(h) > 16 for h in wide)
    cut, _ = decompose_route(table, ProxyParams(**light, max_hull_vertices=16, coacd_hull_vertices=64))
    assert len(cut) == len(wide)
    for small, big in zip(cut, wide):
        assert 4 <= len(small) <= 16
        rows = {tuple(np.round(v, 12)) for v in big}
        assert all(tuple(np.round(v, 12)) in rows for v in small)
    with pytest.raises(ValueError, match="coacd_hull_vertices"):
        ProxyParams.from_dict({"coacd_hull_vertices": -1})
