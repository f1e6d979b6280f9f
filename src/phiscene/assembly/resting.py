"""Resting poses of an object's convex hull, and the flush correction of faithful grounding.

The facets an object can rest on (:func:`resting_normals`), the supporters' surface normal under its footprint
(:func:`support_normal`), the resting poses nearest its input orientation (:func:`resting_candidates`), and the
smallest turns that set it flush on what carries it (:func:`flush_pose`) or on the wall or ceiling it is fixed to
(:func:`flush_attached`). Step 1 of :mod:`phiscene.assembly.faithful`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from phiscene.transforms import decompose, make_pose, rotation_angle, transform_points

#: An attached object is moved onto the wall or ceiling it is fixed to when its back is at most this far (m) from
#: it, in front or behind (:func:`flush_attached`); farther, the plane estimate is taken as wrong there.
ATTACH_REACH = 0.1


def support_normal(mesh_world, parents_world: dict[str, object]) -> np.ndarray:
    """Unit surface normal (3,) of the supporters under an object's footprint.

    Parameters
    ----------
    mesh_world
        The object's mesh in world coordinates (trimesh).
    parents_world
        Supporters carrying it from below: ``"ground"`` maps to ``None`` (normal +z), others to their
        world-frame mesh.

    Returns
    -------
    The area-weighted mean of the upward-facing supporter face normals closest to the object's lowest
    points (within 10% of its height of its lowest point; at a supporter's edge or vertex the most upward of the
    faces that meet there, :func:`closest_faces`), or +z when none face up.
    """
    up = np.array([0.0, 0.0, 1.0])
    objects = {k: m for k, m in parents_world.items() if m is not None}
    if not objects:
        return up
    v = np.asarray(mesh_world.convex_hull.vertices)
    zmin, zmax = v[:, 2].min(), v[:, 2].max()
    low = v[v[:, 2] <= zmin + 0.1 * max(zmax - zmin, 1e-6)]
    acc = np.zeros(3)
    if "ground" in parents_world:
        acc += up * len(low)
    for m in objects.values():
        dist, tri = closest_faces(m, low)
        n = m.face_normals[tri]
        near = dist <= max(0.02, 2 * float(np.min(dist)))
        w = (n[:, 2] > 0.5) & near
        acc += (n[w] * m.area_faces[tri][w, None] / max(float(m.area_faces[tri][w].mean()), 1e-12)
                if w.any() else np.zeros((0, 3))).sum(axis=0)
    norm = np.linalg.norm(acc)
    return acc / norm if norm > 1e-9 else up


#: Barycentric coordinate below which a closest point lies on its triangle's edge or vertex (:func:`closest_faces`).
ON_EDGE = 1e-9


def closest_faces(mesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to a mesh and the face nearest each point, the most upward one where several are.

    A point whose closest point on the mesh lies on an edge or a vertex is as near to every face meeting
    there (the top and the side of a table at its rim); of those the face with the largest normal z is taken,
    the surface a body resting there would bear on.

    Parameters
    ----------
    mesh
        Triangle mesh (trimesh) in world coordinates.
    points : (n, 3) float

    Returns
    -------
    distance : (n,) float
    face : (n,) int
    """
    import igl
    import trimesh

    p = np.ascontiguousarray(points, dtype=float)
    d2, face, closest = igl.point_mesh_squared_distance(p, np.ascontiguousarray(mesh.vertices, dtype=float),
                                                        np.ascontiguousarray(mesh.faces, dtype=np.int64))
    face = np.asarray(face, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):  # degenerate faces give NaN: no tie taken
        bary = trimesh.triangles.points_to_barycentric(mesh.triangles[face], closest)
    rim = np.flatnonzero(np.where(np.isfinite(bary), bary, 1.0).min(axis=1) <= ON_EDGE)
    if len(rim):
        normals_z = mesh.face_normals[:, 2]
        faces = np.asarray(mesh.faces, dtype=np.int64)
        order = np.argsort(faces.ravel(), kind="stable")  # the faces around each vertex, by vertex
        first = np.searchsorted(faces.ravel()[order], np.arange(len(mesh.vertices) + 1))
        for i in rim:
            corners = faces[face[i]][bary[i] > ON_EDGE]  # the edge's two vertices, or the one vertex
            if len(corners) == 0:
                continue
            tied = order[first[corners[0]]:first[corners[0] + 1]] // 3
            for c in corners[1:]:
                tied = np.intersect1d(tied, order[first[c]:first[c + 1]] // 3)
            if len(tied):
                face[i] = tied[np.argmax(normals_z[tied])]
    return np.sqrt(np.maximum(np.asarray(d2, dtype=float), 0.0)), face


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit vector ``a`` to unit vector ``b``."""
    from scipy.spatial.transform import Rotation

    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        return Rotation.from_rotvec(perp / np.linalg.norm(perp) * math.pi).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


#: Faces of a hull with less area than this share of its squared diagonal are slivers that no body rests on
#: (:func:`resting_normals`).
RESTING_MIN_AREA = 1e-12


def resting_normals(hull_points: np.ndarray, com: np.ndarray | None = None) -> np.ndarray:
    """Outward normals (k, 3), local frame, of the facets the object's convex hull can rest on.

    Parameters
    ----------
    hull_points : (n, 3) float
        Points whose convex hull is the object's collision shape (local, unscaled).
    com : (3,) float, optional
        Its centre of mass (local, unscaled); default: the hull's as a uniform solid.
    """
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(hull_points, dtype=float))
    centre = hull.center_mass if com is None else np.asarray(com, dtype=float)
    # A hull rests on a face exactly when the centre of mass projects into it (the sinks of the toppling graph of
    # trimesh.poses.compute_stable_poses, which is what it returns with threshold 0). Found directly: that function
    # walks a networkx graph over every face (43 s for a 12,000-face hull of a reconstructed bowl), and a
    # degenerate face (a sliver of a clipped or decimated hull) gets a NaN landing probability that, toppled into
    # a resting face, drops that face from its answer (the bowl's base).
    n = np.asarray(hull.face_normals, dtype=float)
    tri = np.asarray(hull.triangles, dtype=float)
    proj = centre - np.einsum("ij,ij->i", n, centre - tri[:, 0])[:, None] * n
    with np.errstate(divide="ignore", invalid="ignore"):
        bary = trimesh.triangles.points_to_barycentric(tri, proj)
    diag = float(np.linalg.norm(hull.extents))
    ok = (np.asarray(hull.area_faces) > RESTING_MIN_AREA * diag**2) & np.all(np.isfinite(bary), axis=1)
    rests = np.flatnonzero(ok & np.all(bary >= 0.0, axis=1))
    # one normal per resting facet (coplanar faces the centre projects onto, at a shared edge: the same to 1e-3,
    # as trimesh merges them)
    facets: dict[tuple, np.ndarray] = {}
    for f in rests:
        facets.setdefault(tuple(np.around(n[f], 3)), n[f])
    return np.array(list(facets.values()), dtype=float).reshape(-1, 3)


def resting_candidates(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, up: np.ndarray,
                       max_angle_deg: float) -> list[tuple[np.ndarray, float]]:
    """The pose rotated onto each resting facet within ``max_angle_deg`` of facing ``-up``, nearest first.

    Each candidate is the smallest rotation, about the centre of mass, that makes one resting facet face
    exactly ``-up``.

    Parameters
    ----------
    pose : (4, 4) float
        Input pose (uniform scale allowed).
    normals_local : (k, 3) float
        Resting facet normals (:func:`resting_normals`).
    com_local : (3,) float
        Centre of mass, local frame (the rotation's fixed point).
    up : (3,) float
        Unit supporter normal.
    max_angle_deg
        Facets farther than this from ``-up`` are left out.

    Returns
    -------
    list of (pose (4, 4), angle in deg), sorted by angle; a facet already flush (angle < 1e-9) gives ``pose``
    itself with angle 0.
    """
    if len(normals_local) == 0:
        return []
    R, t, s = decompose(pose)
    world = normals_local @ R.T
    world = world / np.linalg.norm(world, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(world @ -up, -1.0, 1.0)))
    c = com_world(pose, com_local)
    out = []
    for k in np.argsort(angles, kind="stable"):
        angle = float(angles[k])
        if angle > max_angle_deg:
            break
        if angle < 1e-9:
            out.append((pose, 0.0))
            continue
        Q = rotation_between(world[k], -up)
        out.append((make_pose(Q @ R, c - Q @ (c - t), s), angle))
    return out


def flush_pose(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, up: np.ndarray,
               max_angle_deg: float) -> tuple[np.ndarray, float]:
    """The pose rotated so its nearest resting facet faces ``-up``, about its centre of mass.

    Parameters are those of :func:`resting_candidates`.

    Returns
    -------
    pose : (4, 4) float
        The flushed pose (``pose`` itself when no facet is within ``max_angle_deg``).
    angle
        The rotation applied (deg; 0 when none).
    """
    candidates = resting_candidates(pose, normals_local, com_local, up, max_angle_deg)
    return candidates[0] if candidates else (pose, 0.0)


def flush_attached(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, hull_local: np.ndarray,
                   normal: np.ndarray, offset: float, wall: bool, max_angle_deg: float,
                   reach: float = ATTACH_REACH) -> tuple[np.ndarray, float, float]:
    """An object fixed to a wall or the ceiling made flush with it, upright, and touching it.

    A poster, a shelf or a clock is fixed with one face against its plane; a rotation error of the input tilts
    that face (and a shelf's top with it, so that nothing can stand on it) and a depth error pushes it into the
    plane or off it. Three steps, each about the centre of mass and each only when small:

    1. the resting facet of its hull nearest to facing the plane is made to face it exactly (smallest
       rotation; skipped beyond ``max_angle_deg``);
    2. on a wall only: a rotation about the wall normal makes the facet nearest to facing down, among those
       roughly perpendicular to the wall, face straight down within the wall's plane (upright; skipped beyond
       ``max_angle_deg``); a ceiling leaves the turn about the vertical free;
    3. a translation along the normal puts its hull's farthest point behind or nearest point in front exactly on
       the plane: always from behind it (nothing fixed to a wall is inside it: a depth error put a wall shelf
       21 cm into its wall, and what stood on it fell to the floor), from in front when at most ``reach`` away.

    Parameters
    ----------
    pose : (4, 4) float
        Input pose (uniform scale allowed).
    normals_local : (k, 3) float
        Resting facet normals of the hull (:func:`resting_normals`), local frame.
    com_local : (3,) float
        Centre of mass, local frame.
    hull_local : (n, 3) float
        Points of the collision shape, local frame.
    normal : (3,) float
        The plane's unit normal, pointing into the room.
    offset
        The plane's offset (points ``p`` on it: ``normal . p + offset = 0``).
    wall
        The plane is a wall (step 2 applies).
    max_angle_deg
        Largest rotation of steps 1 and 2 (deg).
    reach
        Largest translation of step 3 from in front of the plane (m).

    Returns
    -------
    pose : (4, 4) float
        The corrected pose.
    angle
        Rotation applied, steps 1 and 2 together (deg).
    shift
        Signed translation along ``normal`` (m; positive: away from the plane).
    """
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    out = np.array(pose, dtype=float, copy=True)
    candidates = resting_candidates(out, normals_local, com_local, n, max_angle_deg)
    if candidates:
        out = candidates[0][0]
    R, t, s = decompose(out)
    if wall and len(normals_local):
        down = np.array([0.0, 0.0, -1.0]) - (np.array([0.0, 0.0, -1.0]) @ n) * n
        world = normals_local @ R.T
        world = world / np.linalg.norm(world, axis=1, keepdims=True)
        side = world[np.abs(world @ n) < 0.5]
        if np.linalg.norm(down) > 1e-9 and len(side):
            down = down / np.linalg.norm(down)
            proj = side - np.outer(side @ n, n)
            proj = proj / np.maximum(np.linalg.norm(proj, axis=1, keepdims=True), 1e-12)
            k = int(np.argmax(proj @ down))
            angle = math.atan2(float(np.cross(proj[k], down) @ n), float(np.clip(proj[k] @ down, -1.0, 1.0)))
            if abs(math.degrees(angle)) <= max_angle_deg:
                from scipy.spatial.transform import Rotation

                Q = Rotation.from_rotvec(n * angle).as_matrix()
                c = com_world(out, com_local)
                out = make_pose(Q @ R, c - Q @ (c - t), s)
    turned = math.degrees(rotation_angle(decompose(pose)[0], decompose(out)[0]))
    gap = float((transform_points(out, np.asarray(hull_local, dtype=float)) @ n + offset).min())
    shift = -gap if gap < 0.0 or gap <= reach else 0.0
    out[:3, 3] += shift * n
    return out, turned, shift


def com_world(pose: np.ndarray, com_local: np.ndarray) -> np.ndarray:
    """World position (3,) of a local point (the centre of mass) under ``pose``."""
    return transform_points(pose, np.asarray(com_local, dtype=float)[None])[0]


#: Part of the key of the cached resting normals: changed when :func:`resting_normals`
#: answers differently for the same hull.
RESTING_VERSION = b"v2"


def cached_resting_normals(hull_points: np.ndarray, cache_dir: Path, com: np.ndarray | None = None) -> np.ndarray:
    """:func:`resting_normals` of a hull (k, 3) with centre of mass ``com`` (3,)
    (default the uniform solid's), cached in ``cache_dir/resting`` by the hull's vertices, ``com`` and
    :data:`RESTING_VERSION`."""
    import hashlib

    from phiscene.atomic import atomic_path

    points = np.ascontiguousarray(hull_points, dtype=float)
    extra = (b"" if com is None else b"com" + np.ascontiguousarray(com, dtype=float).tobytes()) + RESTING_VERSION
    key = hashlib.sha256(points.tobytes() + str(points.shape).encode() + extra).hexdigest()[:20]
    path = Path(cache_dir) / "resting" / f"{key}.npy"
    if path.exists():
        try:
            cached = np.load(path)
            if cached.ndim == 2 and cached.shape[1] == 3:
                return cached
        except (OSError, ValueError):
            pass  # unreadable: recompute and rewrite
    normals = resting_normals(points, com)
    with atomic_path(path) as tmp:
        np.save(tmp, normals)
    return normals
