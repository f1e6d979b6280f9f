"""Closed surfaces phiscene makes for CoACD (phiscene.solid.solid_surface's wrap, simplified_closed) and the
decomposition that takes them without CoACD's manifold preprocessing.

Oracles: the analytic offset of a flat square sheet (a slab of twice the offset, the sheet's size plus the offset
on each side), the radius of a sphere, and what a bowl is (its rim covered, its cavity left empty).
"""

from __future__ import annotations

import numpy as np
import trimesh

import phiscene.proxies as proxies
from phiscene.proxies import ProxyParams, decompose_route, fidelity
from phiscene.solid import drawn_in, is_closed_manifold, simplified_closed, solid_surface, wrapped_surface


def sheet(size: float = 0.1, divisions: int = 8) -> trimesh.Trimesh:
    """An open square sheet in the z = 0 plane: no volume, no closed surface, what a flat reconstruction writes."""
    axis = np.linspace(-size / 2, size / 2, divisions + 1)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    n = divisions + 1
    faces = []
    for i in range(divisions):
        for j in range(divisions):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [(a, b, c), (a, c, d)]
    return trimesh.Trimesh(vertices, np.asarray(faces), process=False)


def test_the_wrap_of_an_open_sheet_is_a_closed_slab_of_twice_the_offset():
    mesh = sheet()
    resolution, offset = 20, proxies.WRAP_OFFSET
    cell = 0.1 / resolution
    assert len(solid_surface(mesh, resolution).faces) == 0  # no solid: the sheet is lost at offset 0
    wrap = wrapped_surface(mesh, resolution, offset)
    assert wrap.is_watertight
    lo, hi = wrap.bounds
    # the offset surface of a square: a slab 2 * offset * cell thick, the square grown by offset * cell a side
    # (marching cubes cuts the rounded edges by at most a cell's chord)
    assert np.allclose([lo[2], hi[2]], [-offset * cell, offset * cell], atol=0.05 * cell)
    assert np.allclose(hi[:2], 0.05 + offset * cell, atol=0.25 * cell)
    assert np.allclose(lo[:2], -0.05 - offset * cell, atol=0.25 * cell)
    assert wrap.contains(mesh.vertices * 0.999).all()  # the whole sheet inside


def test_a_wrap_drawn_in_lies_at_the_gap_from_the_mesh():
    """Drawn in, a sphere's wrap lies ``gap`` outside the sphere (its vertices; the oracle is the radius), and an
    open sheet's wrap is a slab of twice ``gap`` (its vertices on the planes z = +-gap, none lost)."""
    ball = trimesh.creation.icosphere(4, 0.05)
    wrap = wrapped_surface(ball, 20, proxies.WRAP_OFFSET)
    gap = 0.0005
    hugged = drawn_in(wrap, ball, gap)
    r = np.linalg.norm(hugged.vertices, axis=1)
    # the vertices' closest points lie on the icosphere's flat faces, at most its sagitta (< 0.2 mm) inside 5 cm
    assert np.all(r <= 0.05 + gap + 1e-9) and np.all(r >= 0.05 - 2e-4 + gap)
    assert np.array_equal(hugged.faces, wrap.faces)
    flat = sheet()
    slab = drawn_in(wrapped_surface(flat, 20, proxies.WRAP_OFFSET), flat, gap)
    assert np.allclose(np.abs(slab.vertices[:, 2])[np.abs(slab.vertices[:, :2]).max(axis=1) < 0.049], gap)


def test_a_closed_surface_simplified_stays_closed_and_within_its_tolerance():
    sphere = trimesh.creation.icosphere(5, 0.1)  # 20,480 faces, every vertex on the sphere
    tolerance = 0.002
    small = simplified_closed(sphere, tolerance)
    assert small.is_watertight and small.is_winding_consistent
    assert len(small.faces) < len(sphere.faces) / 4
    r = np.linalg.norm(small.vertices, axis=1)  # a subset of the vertices: on the sphere
    assert np.allclose(r, 0.1, atol=1e-6)
    pts, _ = trimesh.sample.sample_surface(small, 4000, seed=0)
    assert np.all(np.abs(np.linalg.norm(pts, axis=1) - 0.1) <= tolerance)  # faces within the tolerance
    assert simplified_closed(sheet(), tolerance) is not None  # an open sheet is not a manifold: given back
    open_sheet = sheet()
    assert simplified_closed(open_sheet, tolerance) is open_sheet


def test_two_closed_boxes_touching_along_an_edge_are_not_one_closed_manifold():
    """Each box is closed, and so is their union by vertex index; at the shared edge, two vertices of each box
    lie at the same places, and merged there the edge joins four faces: not what CoACD may take unprocessed."""
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[1, 1, 0], [2, 2, 1]])
    both = trimesh.Trimesh(np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + len(a.vertices)]),
                           process=False)
    assert both.is_watertight  # by index
    assert not is_closed_manifold(both)
    assert is_closed_manifold(a) and is_closed_manifold(trimesh.creation.icosphere(3))
    apart = b.copy()
    apart.apply_translation((0.5, 0.5, 0))
    assert is_closed_manifold(trimesh.util.concatenate([a, apart]))  # two boxes that do not touch


def bowl(radius: float = 0.08, wall: float = 0.003) -> trimesh.Trimesh:
    """An open hemispherical bowl of one sheet (a reconstruction's thin wall), rim at z = 0, cavity above."""
    sphere = trimesh.creation.icosphere(4, radius)
    sphere.update_faces(sphere.triangles_center[:, 2] < -0.002)
    sphere.remove_unreferenced_vertices()
    return sphere


def test_an_open_bowl_is_decomposed_as_its_wrap_without_coacd_preprocessing(monkeypatch):
    import coacd

    mesh = bowl()
    assert not mesh.is_watertight
    modes = []
    real = coacd.run_coacd
    monkeypatch.setattr(coacd, "run_coacd", lambda *a, **kw: modes.append(kw["preprocess_mode"]) or real(*a, **kw))
    params = ProxyParams(convex_tolerance=0.0, max_hulls=8, mcts_iterations=10, mcts_nodes=8, resolution=300)
    hulls, route = decompose_route(mesh, params)
    assert route == "decomposed" and modes == ["off"]
    diag = float(np.linalg.norm(mesh.extents))
    _, outside, _ = fidelity(mesh, hulls)
    assert outside <= 0.01 * diag  # the wall covered
    # the cavity is not filled: the point half way down the bowl's axis lies in no hull
    probe = np.array([[0.0, 0.0, -0.04]])
    inside = [trimesh.convex.convex_hull(h).contains(probe)[0] for h in hulls]
    assert not any(inside)


def test_a_closed_mesh_goes_to_coacd_as_it_is(monkeypatch):
    """A closed mesh (the procedural suites' exact meshes) is not wrapped: CoACD takes it, preprocessing left to
    its own test."""
    seen = []
    monkeypatch.setattr(proxies, "_decompose",
                        lambda m, p, closed=False: seen.append((len(m.faces), closed)) or [m.convex_hull.vertices])
    mesh = trimesh.creation.annulus(0.05, 0.1, 0.04)
    hulls, route = decompose_route(mesh, ProxyParams(convex_tolerance=0.0))
    assert route == "decomposed" and seen == [(len(mesh.faces), False)]


def test_surface_distance_counts_every_face():
    """Distance to a double-walled sphere's surface as it is: a point in the cavity is as far as the inner wall
    (the oracle: radius - wall - |p|), where the solid's distance (outer shell) would give the outer wall."""
    from phiscene.sdf import surface_distance

    outer = trimesh.creation.icosphere(5, 0.1)
    inner = trimesh.creation.icosphere(5, 0.09)
    inner.invert()
    shell = trimesh.util.concatenate([outer, inner])
    points = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.2, 0.0]])
    expected = np.array([0.09, 0.04, 0.1])
    # the icospheres' flat faces lie inside their spheres by at most the sagitta (0.1 mm at 5 subdivisions)
    assert np.allclose(surface_distance(shell, points), expected, atol=2e-4)
