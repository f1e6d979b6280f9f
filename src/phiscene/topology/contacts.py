"""Near-contact queries between objects for the ``geometric`` topology backend.

Objects are represented by seeded uniform surface samples with their face
normals (:class:`Body`); upward-facing and near-vertical samples each get a
:class:`scipy.spatial.cKDTree`. :func:`pair_contacts` finds the samples of
an object A that lie near another object's upward surface (candidate support
from below) or near-vertical surface (candidate leaning contact), with signed
gaps measured along the other object's normal. :func:`hull_offset` measures
how far a centre of mass lies outside the 2D hull of support samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from phiscene.topology.order import box_footprint_area

if TYPE_CHECKING:  # pragma: no cover
    from phiscene.topology.geometric import GeometricParams


@dataclass
class SurfacePart:
    """A subset of an object's samples with its own cKDTree.

    Attributes
    ----------
    index : (m,) int
        Indices into the object's samples.
    tree
        :class:`scipy.spatial.cKDTree` of those samples (``None`` when empty).
    """

    index: np.ndarray
    tree: object

    @classmethod
    def build(cls, points: np.ndarray, mask: np.ndarray) -> "SurfacePart":
        """The samples ``points[mask]`` (points : (n, 3) float, mask : (n,) bool)."""
        from scipy.spatial import cKDTree

        index = np.flatnonzero(mask)
        return cls(index, cKDTree(points[index]) if len(index) else None)


@dataclass
class Body:
    """An object prepared for contact queries (world frame).

    Attributes
    ----------
    id
        Object id.
    points : (n, 3) float
        Surface samples.
    normals : (n, 3) float
        Outward unit normals of the sampled faces.
    spacing
        Typical distance between neighbouring samples (m).
    up, side
        :class:`SurfacePart` of the upward-facing (``n.z >= up_cos``) and of the near-vertical samples.
    bounds : (2, 3) float
        World AABB.
    size
        Longest side of the world OBB (m).
    footprint
        Area of the OBB projected to xy (m^2).
    com : (3,) float
        Centre of mass (uniform density; area-weighted surface centroid for an open mesh).
    local_mesh : trimesh.Trimesh
        The mesh in its local frame (for exact inside tests).
    pose : (4, 4) float
        Local-to-world pose.
    """

    id: str
    points: np.ndarray
    normals: np.ndarray
    spacing: float
    up: SurfacePart
    side: SurfacePart
    bounds: np.ndarray
    size: float
    footprint: float
    com: np.ndarray
    local_mesh: object
    pose: np.ndarray

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether world points (n, 3) are inside the object -> (n,) bool.

        Generalised winding number of the local mesh (:func:`phiscene.sdf.signed_distance_for`,
        cached per mesh), robust to the overlapping shells of scanned or decomposed meshes.
        """
        from phiscene.sdf import signed_distance_for
        from phiscene.transforms import invert, transform_points

        if len(points) == 0:
            return np.zeros(0, bool)
        return signed_distance_for(self.local_mesh).inside(transform_points(invert(self.pose), points))


@dataclass
class Contact:
    """Samples of an object A near one supporter.

    Attributes
    ----------
    index : (k,) int
        Indices into A's samples (unique).
    gap : (k,) float
        Signed gaps along the supporter's normal (m; negative = penetration).
    normal : (k, 3) float
        The supporter's outward normals at the paired samples.
    height : (k,) float
        z of the supporter's paired samples.
    """

    index: np.ndarray
    gap: np.ndarray
    normal: np.ndarray
    height: np.ndarray

    @classmethod
    def empty(cls) -> "Contact":
        return cls(np.zeros(0, int), np.zeros(0), np.zeros((0, 3)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.index)

    def subset(self, mask: np.ndarray) -> "Contact":
        """The entries where ``mask`` (k,) bool is true."""
        return Contact(self.index[mask], self.gap[mask], self.normal[mask], self.height[mask])

    def within(self, max_gap: float) -> "Contact":
        """The entries with gap at most ``max_gap``."""
        return self.subset(self.gap <= max_gap)

    def without(self, index: np.ndarray) -> "Contact":
        """The entries whose sample is not in ``index``."""
        return self.subset(~np.isin(self.index, index))


def prepare_body(object_id: str, local_mesh, pose: np.ndarray, params: "GeometricParams", seed: int) -> Body:
    """Sample an object's world-frame surface and build its query structures.

    The surface is the mesh's outer shell (:func:`phiscene.solid.outer_shell`): a hollow, double-walled
    reconstruction is the solid it stands for, as in the SDF and the proxies. The faces of its sealed cavity are
    no surface another object touches: a book reaching into a hollow box's bottom wall has the cavity's floor
    facing up above it, which read the box on top as containing the book under it.

    About one sample per ``params.sample_spacing`` squared of surface,
    clamped to ``[params.min_samples, params.max_samples]``.

    Parameters
    ----------
    object_id
        The object's id.
    local_mesh : trimesh.Trimesh
        The object's mesh in its local frame (not modified).
    pose : (4, 4) float
        Local-to-world pose.
    params
        Sampling parameters and ``up_cos``.
    seed
        Seed of this object's samples.
    """
    import trimesh

    from phiscene.meshes import oriented_box
    from phiscene.solid import outer_shell

    local_mesh = outer_shell(local_mesh)
    mesh = local_mesh.copy()
    mesh.apply_transform(pose)
    area = float(mesh.area)
    n = int(np.clip(round(area / params.sample_spacing ** 2), params.min_samples, params.max_samples))
    points, faces = trimesh.sample.sample_surface(mesh, n, seed=np.random.default_rng(seed))
    points = np.asarray(points, dtype=float)
    normals = np.asarray(mesh.face_normals, dtype=float)[faces]
    solid = bool(mesh.is_watertight)
    if solid and mesh.volume < 0:  # inside-out winding
        normals = -normals
    com = np.asarray(mesh.center_mass if solid and abs(mesh.volume) > 0 else mesh.centroid, dtype=float)
    obb = oriented_box(mesh)
    return Body(id=object_id, points=points, normals=normals, spacing=math.sqrt(area / n),
                up=SurfacePart.build(points, normals[:, 2] >= params.up_cos),
                side=SurfacePart.build(points, np.abs(normals[:, 2]) < params.up_cos),
                bounds=np.asarray(mesh.bounds, dtype=float), size=float(np.max(obb.primitive.extents)),
                footprint=box_footprint_area(obb.vertices), com=com, local_mesh=local_mesh,
                pose=np.asarray(pose, dtype=float))


def object_seed(seed: int, index: int) -> int:
    """A per-object sampling seed derived deterministically from the backend seed."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


def prepare_bodies(scene, params: "GeometricParams") -> dict[str, Body]:
    """:func:`prepare_body` for every object of ``scene``, seeded by ``(params.seed, index)``."""
    return {o.id: prepare_body(o.id, o.mesh(), o.pose, params, seed=object_seed(params.seed, i))
            for i, o in enumerate(scene.objects)}


def aabbs_near(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    """Whether two AABBs ``(2, 3)`` come within ``margin`` of each other."""
    return bool(np.all(a[0] - margin <= b[1]) and np.all(b[0] - margin <= a[1]))


def ground_contact(a: Body, ground_height: float, max_gap: float, down_cos: float) -> Contact:
    """Samples of ``a`` facing down (``n.z <= -down_cos``) at most ``max_gap`` above the ground (or below it)."""
    gap = a.points[:, 2] - ground_height
    idx = np.flatnonzero((gap <= max_gap) & (-a.normals[:, 2] >= down_cos))
    return Contact(idx, gap[idx], np.tile([0.0, 0.0, 1.0], (len(idx), 1)), np.full(len(idx), ground_height))


def pair_contacts(a: Body, b: Body, max_gap: float, max_depth: float, side_gap: float,
                  params: "GeometricParams") -> tuple[Contact, Contact, np.ndarray]:
    """Samples of ``a`` near upward-facing and near near-vertical surface of ``b``.

    Upward-facing and near-vertical samples of ``b`` are searched separately
    (so the upper face of a thin plate is found even where its lower face is
    nearer). For each sample ``p`` of ``a`` (normal ``n_a``), of the
    ``params.neighbours`` nearest samples ``q`` of ``b`` (normal ``n_b``),
    those qualify whose signed gap ``(p - q) . n_b`` lies in the allowed range
    and that face ``p`` (``n_a . n_b <= -face_cos``); the one with the
    smallest absolute gap is ``p``'s partner. A negative gap (penetration)
    only counts where ``p`` is inside ``b`` (generalised winding number). Support contacts also need
    ``a``'s surface to face down (``n_a.z <= -down_cos``); side contacts need
    ``a``'s centre of mass in front of ``b``'s surface.

    Parameters
    ----------
    a, b
        The supported object and the candidate supporter.
    max_gap
        Largest gap of a support contact (m).
    max_depth
        Deepest penetration of any contact (m, positive).
    side_gap
        Largest gap of a side contact (m).
    params
        ``neighbours``, ``face_cos``, ``down_cos``.

    Returns
    -------
    support
        Samples of ``a`` near upward-facing surface of ``b``.
    side
        Samples of ``a`` near near-vertical surface of ``b`` that are not support samples.
    cover : (m,) int
        Samples of ``a`` that have ``b``'s upward surface within the support range below or
        above them, inside ``b`` or not (``b`` hides what lies under it there).
    """
    reach = max(max_gap, max_depth, side_gap) + b.spacing
    inside = np.all((a.points >= b.bounds[0] - reach) & (a.points <= b.bounds[1] + reach), axis=1)
    cand = np.flatnonzero(inside)
    support, cover = _part_contacts(a, b, b.up, cand, (-max_depth, max_gap), params, front=False)
    rest = np.setdiff1d(cand, support.index, assume_unique=True)
    side, _ = _part_contacts(a, b, b.side, rest, (-max_depth, side_gap), params, front=True)
    return support, side, cover


def _part_contacts(a: Body, b: Body, part: SurfacePart, cand: np.ndarray, gap_range: tuple[float, float],
                   params: "GeometricParams", front: bool) -> tuple[Contact, np.ndarray]:
    """Samples ``cand`` of ``a`` whose gap to the samples ``part`` of ``b`` lies in ``gap_range``.

    Returns the contact (penetrating samples only where inside ``b``) and the
    cover: every candidate with a qualifying partner, inside or not.
    """
    if len(cand) == 0 or part.tree is None:
        return Contact.empty(), np.zeros(0, int)
    reach = max(-gap_range[0], gap_range[1]) + b.spacing
    k = min(params.neighbours, len(part.index))
    dist, j = part.tree.query(a.points[cand], k=k, distance_upper_bound=reach)
    dist, j = dist.reshape(len(cand), k), j.reshape(len(cand), k)
    found = np.isfinite(dist)
    jj = part.index[np.where(found, j, 0)]
    p = a.points[cand][:, None, :]
    q, nb = b.points[jj], b.normals[jj]  # (m, k, 3)
    na = a.normals[cand][:, None, :]
    gap = np.einsum("mkj,mkj->mk", p - q, nb)
    ok = (found & (gap >= gap_range[0]) & (gap <= gap_range[1])
          & (np.einsum("mkj,mkj->mk", na, nb) <= -params.face_cos))
    if front:
        ok &= np.einsum("mkj,mkj->mk", a.com - q, nb) > 0
    else:
        ok &= na[..., 2] <= -params.down_cos
    cover = cand[ok.any(axis=1)]
    ok &= (gap >= 0) | _inside(a.points[cand], b, (ok & (gap < 0)).any(axis=1))[:, None]
    rows = np.flatnonzero(ok.any(axis=1))
    col = np.argmin(np.where(ok[rows], np.abs(gap[rows]), np.inf), axis=1)
    return Contact(cand[rows], gap[rows, col], nb[rows, col], q[rows, col, 2]), cover


def _inside(points: np.ndarray, b: Body, check: np.ndarray) -> np.ndarray:
    """Whether ``points`` (m, 3) lie inside ``b``, evaluated only where ``check`` (m,) bool is set.

    A penetration only counts for points inside ``b``: this keeps a negative
    gap from reaching through a thin plate or past an edge.
    """
    out = np.zeros(len(points), bool)
    rows = np.flatnonzero(check)
    out[rows] = b.contains(points[rows])
    return out


def hull_offset(points: np.ndarray, c: np.ndarray) -> tuple[float, np.ndarray]:
    """How far ``c`` lies outside the 2D convex hull of ``points``, and the direction to it.

    Parameters
    ----------
    points : (n, 2) float
    c : (2,) float

    Returns
    -------
    distance : float
        Distance from ``c`` to the hull when outside; when inside, minus the distance
        to the nearest edge line (<= 0). A degenerate hull (one point, collinear points)
        is treated as a segment; no points at all give ``inf``.
    direction : (2,) float
        Unit vector from the nearest hull point towards ``c`` (zeros when inside).
    """
    from scipy.spatial import ConvexHull, QhullError

    points = np.asarray(points, dtype=float).reshape(-1, 2)
    c = np.asarray(c, dtype=float)
    if len(points) == 0:
        return math.inf, np.zeros(2)
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):  # fewer than 3 points or collinear: the hull is a segment
        centre = points.mean(axis=0)
        rel = points - centre
        u = np.linalg.svd(rel, full_matrices=False)[2][0] if len(points) > 1 else np.zeros(2)
        t = rel @ u
        closest = centre + np.clip((c - centre) @ u, t.min(), t.max()) * u
        return _away(c, closest)
    signed = hull.equations[:, :2] @ c + hull.equations[:, 2]
    if signed.max() <= 0:
        return float(signed.max()), np.zeros(2)
    v = points[hull.vertices]
    edges = np.roll(v, -1, axis=0) - v
    t = np.clip(np.einsum("ij,ij->i", c - v, edges) / np.einsum("ij,ij->i", edges, edges), 0.0, 1.0)
    closest = v + t[:, None] * edges
    return _away(c, closest[int(np.argmin(np.linalg.norm(c - closest, axis=1)))])


def _away(c: np.ndarray, closest: np.ndarray) -> tuple[float, np.ndarray]:
    d = c - closest
    dist = float(np.linalg.norm(d))
    return dist, (d / dist if dist > 0 else np.zeros(2))
