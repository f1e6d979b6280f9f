"""Making a mesh usable as a rigid-body asset: one clean closed surface, light, centred.

"Clean" means what CoACD can decompose without its own voxel remeshing (which is
slow, loses millimetres, and can abort on degenerate input): a single closed,
consistently wound surface without fold-overs or self-intersections. Multi-shell
and open models (``pybullet_data``'s random blobs and VHACD teddy, the mug) are
joined by an exact boolean union or, when that is not clean, rebuilt as the
zero level set of the shells' joint signed distance; heavy meshes are simplified
to a face budget.
"""

from __future__ import annotations

import numpy as np
import trimesh

from phiscene.errors import InputError
from phiscene.meshes import check_mesh, repair
from phiscene.tolerances import TOL

#: Face budget of one asset mesh; heavier meshes are simplified (keeps CoACD fast).
MAX_FACES = 2000


def self_intersections(mesh: trimesh.Trimesh) -> int:
    """Number of intersecting triangle pairs that share no vertex (open3d's exact test)."""
    from phiscene.o3d import open3d
    o3d = open3d()

    om = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(mesh.vertices, dtype=float)),
                                   o3d.utility.Vector3iVector(np.asarray(mesh.faces, dtype=np.int32)))
    return len(np.asarray(om.get_self_intersecting_triangles()))


#: Largest accepted bend (deg) between adjacent faces of an asset mesh; more is a fold-over.
MAX_FOLD_DEG = 170.0


def is_clean(mesh: trimesh.Trimesh) -> bool:
    """A single closed surface CoACD can decompose as it is.

    Closed, consistently wound, positive volume, one piece, no fold-overs
    (:data:`MAX_FOLD_DEG`) and no self-intersections. CoACD voxel-remeshes anything it finds non-manifold or
    self-intersecting first (slow, loses millimetres), and degenerate input can abort it.
    """
    if not (mesh.is_volume and mesh.body_count == 1 and mesh.volume > TOL.min_volume):
        return False
    if len(mesh.face_adjacency_angles) and np.degrees(mesh.face_adjacency_angles.max()) > MAX_FOLD_DEG:
        return False
    return self_intersections(mesh) == 0


def closed_shells(mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    """The mesh's connected pieces as closed shells: watertight pieces as they are, open ones as convex hulls."""
    shells = []
    for body in mesh.split(only_watertight=False):
        if body.is_volume and body.volume > TOL.min_volume:
            shells.append(body)
        elif len(body.faces) >= 4:
            try:
                hull = body.convex_hull
            except Exception:  # qhull refuses flat pieces
                continue
            if hull.volume > TOL.min_volume:
                shells.append(hull)
    return shells


def remesh_union(shells: list[trimesh.Trimesh], pitch: float) -> trimesh.Trimesh:
    """One clean surface around the union of closed shells: zero level set of their joint signed distance.

    The signed distance (open3d ray casting, min over shells) is sampled on a grid of
    spacing ``pitch`` and its zero set extracted by manifold3d's marching tetrahedra,
    which yields a closed 2-manifold with edges of about ``pitch``.

    Parameters
    ----------
    shells
        Closed meshes (may overlap or touch).
    pitch
        Grid spacing and target edge length (m).
    """
    import manifold3d

    from phiscene.o3d import open3d
    o3d = open3d()

    lo = np.min([s.bounds[0] for s in shells], axis=0) - 2 * pitch
    hi = np.max([s.bounds[1] for s in shells], axis=0) + 2 * pitch
    shape = np.ceil((hi - lo) / pitch).astype(int) + 1
    axes = [lo[k] + pitch * np.arange(shape[k]) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    inside = np.full(len(pts), -np.inf)
    for shell in shells:
        if shell.is_convex:  # exact in float64: distance inside = min over face planes
            normals = np.asarray(shell.face_normals)
            offsets = np.einsum("ij,ij->i", normals, shell.triangles[:, 0])
            depth = np.full(len(pts), np.inf)
            for chunk in np.array_split(np.arange(len(normals)), max(1, len(normals) // 64)):
                depth = np.minimum(depth, (offsets[chunk][None, :] - pts @ normals[chunk].T).min(axis=1))
        else:
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(o3d.core.Tensor(np.asarray(shell.vertices, dtype=np.float32)),
                                o3d.core.Tensor(np.asarray(shell.faces, dtype=np.uint32)))
            depth = -scene.compute_signed_distance(o3d.core.Tensor(pts.astype(np.float32))).numpy()
        inside = np.maximum(inside, depth)
    flat = inside.tolist()
    nx, ny, nz = (int(v) for v in shape)
    lx, ly, lz = (float(v) for v in lo)
    inv = 1.0 / pitch

    def sdf(x: float, y: float, z: float) -> float:  # trilinear interpolation, positive inside
        fx, fy, fz = (x - lx) * inv, (y - ly) * inv, (z - lz) * inv
        i, j, k = min(max(int(fx), 0), nx - 2), min(max(int(fy), 0), ny - 2), min(max(int(fz), 0), nz - 2)
        tx, ty, tz = fx - i, fy - j, fz - k
        a = (i * ny + j) * nz + k
        b = a + ny * nz
        c00 = flat[a] + (flat[a + 1] - flat[a]) * tz
        c01 = flat[a + nz] + (flat[a + nz + 1] - flat[a + nz]) * tz
        c10 = flat[b] + (flat[b + 1] - flat[b]) * tz
        c11 = flat[b + nz] + (flat[b + nz + 1] - flat[b + nz]) * tz
        c0 = c00 + (c01 - c00) * ty
        c1 = c10 + (c11 - c10) * ty
        return c0 + (c1 - c0) * tx

    out = manifold3d.Manifold.level_set(sdf, [*(lo + pitch), *(hi - pitch)], pitch).to_mesh64()
    return trimesh.Trimesh(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts), process=True)


def _manifold(mesh: trimesh.Trimesh):
    import manifold3d

    return manifold3d.Manifold(manifold3d.Mesh64(np.asarray(mesh.vertices, dtype=np.float64),
                                                 np.asarray(mesh.faces, dtype=np.uint32)))


def _trimesh(manifold) -> trimesh.Trimesh:
    out = manifold.to_mesh64()
    return trimesh.Trimesh(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts), process=False)


def _finish(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Recentred on the bounding-box centre, vertices rounded to float32 (what a .glb stores)."""
    v = np.asarray(mesh.vertices, dtype=float)
    v = v - (v.min(axis=0) + v.max(axis=0)) / 2
    return trimesh.Trimesh(v.astype(np.float32).astype(float), np.asarray(mesh.faces), process=False)


def _simplifications(mesh: trimesh.Trimesh, max_faces: int, steps: int):
    """Candidate reductions of ``mesh`` to at most ``max_faces`` faces, best-shaped first.

    Quadric decimation (fast_simplification) at a few budgets, then manifold3d's edge
    collapse (which keeps the surface a closed 2-manifold) at growing tolerances.
    """
    for fraction in (1.0, 0.85, 0.7):
        yield repair(mesh.simplify_quadric_decimation(face_count=int(fraction * max_faces)))
    man = _manifold(mesh)
    if man.status().name != "NoError":
        return
    tol = 1e-3 * float(np.max(mesh.extents))
    for _ in range(steps):
        light = _trimesh(man.simplify(tol))
        tol *= 1.25
        if len(light.faces) < 4:  # collapsed (a thin shape at a coarse tolerance): coarser ones only lose more
            return
        if len(light.faces) <= max_faces:
            yield light


def simplify_clean(mesh: trimesh.Trimesh, max_faces: int, steps: int = 20) -> trimesh.Trimesh | None:
    """``mesh`` finished (:func:`_finish`) with at most ``max_faces`` faces and clean (:func:`is_clean`), or ``None``.

    The first candidate of :func:`_simplifications` that is clean after rounding and keeps
    the volume within 5 % is returned; an empty or degenerate mesh (fewer than 4 faces) gives ``None``.
    """
    if len(mesh.faces) < 4:  # nothing left (remeshed at cells coarser than the shape is thin)
        return None
    if len(mesh.faces) <= max_faces:
        out = _finish(mesh)
        return out if is_clean(out) else None
    for light in _simplifications(mesh, max_faces, steps):
        out = _finish(light)
        if len(out.faces) <= max_faces and is_clean(out) and abs(out.volume / mesh.volume - 1.0) < 0.05:
            return out
    return None


def canonical(mesh: trimesh.Trimesh, max_faces: int = MAX_FACES, name: str = "asset",
              remesh_resolution: int = 48) -> trimesh.Trimesh:
    """Make a mesh usable as a rigid body: one clean closed surface, light, centred on its bounding box.

    Steps: drop visuals and merge vertices, :func:`phiscene.meshes.repair`. A clean
    single shell is only simplified to ``max_faces``. Otherwise its closed shells
    (open pieces replaced by their convex hulls) are joined by an exact boolean
    union, or, when that is not clean (touching shells, slivers), rebuilt by
    :func:`remesh_union` at ``remesh_resolution`` cells along the longest side, then
    simplified. The result is recentred and rounded to float32 (:func:`_finish`).

    Raises
    ------
    InputError
        When no clean mesh results.
    """
    m = repair(trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), process=True))
    out = simplify_clean(m, max_faces) if m.body_count == 1 and m.is_volume else None
    shells = closed_shells(m) if out is None else []
    if out is None and len(shells) > 1:
        union = trimesh.boolean.union(shells, engine="manifold")
        out = simplify_clean(union, max_faces) if union.body_count == 1 else None
    if out is None and not shells:
        raise InputError(name, None, "no closed shell with volume")
    size = float(np.max(np.ptp(np.vstack([s.bounds for s in shells]), axis=0))) if shells else 0.0
    for cells in (remesh_resolution, remesh_resolution * 5 // 6, remesh_resolution * 2 // 3):
        if out is not None:
            break
        out = simplify_clean(remesh_union(shells, size / cells), max_faces)
    if out is None:
        raise InputError(name, None, "could not make a clean closed mesh (union, remeshing and simplification)")
    check_mesh(out, name)
    return out


#: Stable poses less likely than this (trimesh's basin estimate) are not chosen as resting poses.
MIN_POSE_PROBABILITY = 0.02


def resting_transform(mesh: trimesh.Trimesh, nearest: bool = False) -> np.ndarray:
    """(4, 4) rotation putting a closed mesh on a statically stable face (trimesh stable poses, no noise).

    Parameters
    ----------
    mesh
        Closed mesh (its centre of mass decides stability).
    nearest
        Choose the stable pose with the smallest rotation from the current orientation
        (among those with probability >= :data:`MIN_POSE_PROBABILITY`) instead of the most probable one.
    """
    from phiscene.transforms import rotation_angle

    transforms, probs = trimesh.poses.compute_stable_poses(mesh, sigma=0.0, n_samples=1)
    transforms, probs = np.asarray(transforms, dtype=float), np.asarray(probs, dtype=float)
    if nearest:
        ok = np.flatnonzero(probs >= MIN_POSE_PROBABILITY)
        ok = ok if len(ok) else np.arange(len(probs))  # round objects: many poses, each unlikely
        best = ok[int(np.argmin([rotation_angle(np.eye(3), transforms[k][:3, :3]) for k in ok]))]
    else:
        best = int(np.argmax(probs))
    T = transforms[best].copy()
    T[:3, 3] = 0.0
    return T
