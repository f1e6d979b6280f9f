"""Real-size meshes (tens of thousands of faces, not watertight) through the proxies in bounded time."""

import time

import numpy as np
import pytest
import trimesh

from phiscene.proxies import ProxyParams, capped_hull, decimated, decompose_route, fidelity, hull_excess


def open_dense(mesh: trimesh.Trimesh, faces: int = 30000) -> trimesh.Trimesh:
    """``mesh`` subdivided to at least ``faces`` faces, with every 23rd face removed (not watertight)."""
    m = mesh.copy()
    while len(m.faces) < faces:
        m = m.subdivide()
    m.update_faces(np.arange(len(m.faces)) % 23 != 5)
    m.remove_unreferenced_vertices()
    return m


def table_mesh() -> trimesh.Trimesh:
    """A table: a 1.0 x 0.6 x 0.04 m top on four 0.7 m legs (clearly not convex)."""
    T = trimesh.transformations.translation_matrix
    parts = [trimesh.creation.box([1.0, 0.6, 0.04], transform=T([0, 0, 0.72]))]
    parts += [trimesh.creation.box([0.05, 0.05, 0.7], transform=T([sx * 0.45, sy * 0.25, 0.35]))
              for sx in (-1, 1) for sy in (-1, 1)]
    return trimesh.util.concatenate(parts)


def test_fruit_like_mesh_takes_one_hull_quickly():
    fruit = open_dense(trimesh.creation.icosphere(4, 0.05).apply_scale([1.0, 1.0, 1.25]))
    assert len(fruit.faces) >= 30000 and not fruit.is_watertight
    t0 = time.perf_counter()
    hulls, route = decompose_route(fruit, ProxyParams())
    assert route == "single_hull" and len(hulls) == 1
    assert time.perf_counter() - t0 < 10.0
    # the mesh's convex hull (thousands of vertices) capped at the vertex budget: within 0.5 % of the diagonal of
    # every mesh point (fidelity's own plane test) and within 1 % of the full hull's volume
    full = fruit.convex_hull
    assert len(full.vertices) > 2 * ProxyParams().max_hull_vertices
    assert len(hulls[0]) <= ProxyParams().max_hull_vertices * 1.05
    assert fidelity(fruit, hulls)[1] < 0.005 * np.linalg.norm(fruit.extents)
    assert trimesh.convex.convex_hull(hulls[0]).volume == pytest.approx(full.volume, rel=0.01)


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
