"""Starts of faithful grounding's guarded settling, besides the corrected input pose.

Carried with its supporter (:func:`carried`), moved along the camera ray (:func:`ray_corrected`), shifted
horizontally (:func:`shifted_starts`) and moved onto the nearest upward-facing surface it fits on
(:func:`onto_start`). See :mod:`phiscene.assembly.faithful` for their order.
"""

from __future__ import annotations

import math

import numpy as np

from phiscene.assembly.beneath import gap_under
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.resting import com_world
from phiscene.transforms import transform_points

#: Remedy ``ray`` (:func:`ray_corrected`): after the shift the surface under the object must be where it was,
#: within this (m): a shift that takes it off its supporter's edge or onto another object is not made.
RAY_SURFACE_TOL = 0.01


#: Upward surface samples per placed object for the remedy ``onto`` (:func:`upward_samples`).
ONTO_SAMPLES = 3000


#: Remedy ``onto``: the footprint is rasterised with at most this many cells across (:func:`fitting_point`).
FIT_CELLS = 48


def shifted_starts(pose: np.ndarray, step: float, max_shift: float,
                   directions: int) -> list[tuple[float, list[np.ndarray]]]:
    """``pose`` translated horizontally by ``step``, ``2 step``, ... up to ``max_shift`` in ``directions`` directions.

    Parameters
    ----------
    pose : (4, 4) float
        The corrected pose.
    step
        Distance between rings (m; the slide bound, so that neighbouring starts cover the plane).
    max_shift
        Largest shift (m).
    directions
        Evenly spaced directions per ring, the first along +x.

    Returns
    -------
    list of (shift in m, its ``directions`` poses (4, 4)), nearest ring first; empty when ``step``,
    ``max_shift`` or ``directions`` is 0.
    """
    if step <= 0 or max_shift <= 0 or directions <= 0:
        return []
    angles = 2 * math.pi * np.arange(directions) / directions
    out = []
    for ring in range(1, int(math.floor(max_shift / step + 1e-9)) + 1):
        r = ring * step
        starts = []
        for a in angles:
            start = np.array(pose, dtype=float, copy=True)
            start[:2, 3] += r * np.array([math.cos(a), math.sin(a)])
            starts.append(start)
        out.append((r, starts))
    return out


def carried(pose: np.ndarray, com_local: np.ndarray, supporter_before: np.ndarray,
            supporter_after: np.ndarray) -> np.ndarray:
    """``pose`` (4, 4) translated as its supporter's point at the object's centre of mass moved.

    Parameters
    ----------
    pose : (4, 4) float
        The object's input pose.
    com_local : (3,) float
        Its centre of mass, local frame.
    supporter_before, supporter_after : (4, 4) float
        The supporter's input and grounded poses.
    """
    c = com_world(pose, com_local)
    moved = transform_points(supporter_after @ np.linalg.inv(supporter_before), c[None])[0]
    out = np.array(pose, dtype=float, copy=True)
    out[:3, 3] += moved - c
    return out


def carried_vertically(pose: np.ndarray, com_local: np.ndarray, supporter_before: np.ndarray,
                       supporter_after: np.ndarray) -> np.ndarray:
    """:func:`carried` without its horizontal part: ``pose`` (4, 4) raised or lowered as its supporter's point at
    the object's centre of mass moved, kept where it was horizontally."""
    full = carried(pose, com_local, supporter_before, supporter_after)
    out = np.array(pose, dtype=float, copy=True)
    out[2, 3] = full[2, 3]
    return out


def along_ray(pose: np.ndarray, com_local: np.ndarray, eye: np.ndarray, gap: float, share: float,
              min_pitch_deg: float, max_shift: float) -> tuple[np.ndarray, float]:
    """``pose`` moved along the camera ray through its centre of mass so that it drops by ``share * gap`` (m).

    Parameters
    ----------
    pose : (4, 4) float
    com_local : (3,) float
        Centre of mass, local frame (unscaled).
    eye : (3,) float
        The camera's centre, world frame.
    gap
        Its vertical gap to what holds it (m; negative: sunk in).
    share
        Share of the gap closed.
    min_pitch_deg
        Rays flatter than this (deg below the horizon) leave it unchanged.
    max_shift
        Nor is it moved when closing the whole gap would take a shift longer than this (m).

    Returns
    -------
    pose : (4, 4) float
        The moved pose (``pose`` itself when unchanged).
    shift : float
        Signed distance moved along the ray (m, > 0: away from the camera; 0 when unchanged).
    """
    d = com_world(pose, com_local) - np.asarray(eye, dtype=float)
    d = d / np.linalg.norm(d)
    if -d[2] < math.sin(math.radians(min_pitch_deg)):
        return pose, 0.0
    t = float(gap / -d[2])
    if abs(t) > max_shift:
        return pose, 0.0
    t *= share
    out = np.asarray(pose, dtype=float).copy()
    out[:3, 3] += t * d
    return out, t


def ray_corrected(pose: np.ndarray, points_local: np.ndarray, com_local: np.ndarray, supporters: dict,
                  ground_height: float, eye: np.ndarray, fp: FaithfulParams,
                  surface_tol: float = RAY_SURFACE_TOL) -> tuple[np.ndarray, float]:
    """Remedy ``ray``: ``ray_share`` of the object's vertical gap to its supporters closed along the camera ray.

    The gap (:func:`beneath.vertical_gap`) is measured again where the shift takes the object: unless the surface under
    it goes on there within ``surface_tol`` (m) of where it was, and still under its centre of mass if it was
    (not over its supporter's edge, not onto another object), the shift is not made.

    Parameters
    ----------
    pose : (4, 4) float
    points_local : (n, 3) float
        Points of its collision shape, local frame (unscaled).
    com_local : (3,) float
    supporters
        Name -> world mesh, or ``None`` for the ground, of what holds it from below.
    ground_height
        Height of the ground (m).
    eye : (3,) float
        The camera's centre, world frame.

    Returns
    -------
    pose : (4, 4) float
    shift : float
        Signed distance moved along the ray (m, > 0: away from the camera; 0 when not moved).
    """
    gap, held = gap_under(transform_points(pose, points_local), supporters, ground_height,
                          centre=com_world(pose, com_local))
    if gap is None:
        return pose, 0.0
    moved, t = along_ray(pose, com_local, eye, gap, fp.ray_share, fp.ray_min_pitch, fp.ray_max_shift)
    if t == 0.0:
        return pose, 0.0
    after, held_after = gap_under(transform_points(moved, points_local), supporters, ground_height,
                                  centre=com_world(moved, com_local))
    if after is None or abs(after - (gap + moved[2, 3] - pose[2, 3])) > surface_tol or (held and not held_after):
        return pose, 0.0
    return moved, t


def upward_samples(mesh_world, n: int, seed: int, min_normal_z: float = 0.8) -> np.ndarray:
    """Points (k, 3) sampled (area-weighted, seeded) on the upward-facing faces of a world-frame mesh.

    Faces whose unit normal has a z component below ``min_normal_z`` (walls, undersides, steep slopes) are
    left out; ``k`` is 0 when none faces up.
    """
    import trimesh

    faces = np.flatnonzero(np.asarray(mesh_world.face_normals)[:, 2] >= min_normal_z)
    if len(faces) == 0 or n <= 0:
        return np.zeros((0, 3))
    sub = mesh_world.submesh([faces], append=True)
    pts, _ = trimesh.sample.sample_surface(sub, n, seed=seed)
    return np.asarray(pts, dtype=float)


def fitting_point(level_xy: np.ndarray, footprint_xy: np.ndarray, start_xy: np.ndarray) -> np.ndarray | None:
    """The point nearest to ``start_xy`` at which an object's footprint lies wholly over a sampled surface.

    The surface (its samples of one level) is rasterised at its sampling spacing (holes between samples closed,
    then one cell taken off its rim: a cell holding an edge sample reaches past the edge), eroded by the
    footprint (:func:`scipy.ndimage.binary_erosion`: the Minkowski difference, so an elongated object fits along
    a narrow shelf, not across it), and the nearest cell centre that remains is returned: the smallest
    horizontal motion that puts the object wholly over the surface.

    Parameters
    ----------
    level_xy : (k, 2) float
        Surface samples (xy) of one level.
    footprint_xy : (m, 2) float
        The object's collision-shape points (xy) relative to the point being placed (its centre of mass).
    start_xy : (2,) float
        Where that point is now.

    Returns
    -------
    (2,) float, or ``None`` when the footprint fits nowhere (a surface smaller than the object) or the surface
    has fewer than 4 samples.
    """
    from scipy import ndimage
    from scipy.spatial import Delaunay, QhullError, cKDTree

    level_xy = np.asarray(level_xy, dtype=float).reshape(-1, 2)
    rel = np.asarray(footprint_xy, dtype=float).reshape(-1, 2)
    if len(level_xy) < 4 or len(rel) < 3:
        return None
    spacing = float(np.median(cKDTree(level_xy).query(level_xy, k=2)[0][:, 1]))
    # the sampling spacing, but at most FIT_CELLS cells across the footprint and 8 FIT_CELLS across the surface:
    # the erosion costs (surface cells) x (footprint cells)
    reach_xy = float(np.max(np.ptp(level_xy, axis=0)))
    size = float(np.max(np.ptp(rel, axis=0)))
    cell = max(spacing, 1e-3, size / FIT_CELLS, reach_xy / (8 * FIT_CELLS))
    start = np.asarray(start_xy, dtype=float)
    # the grid is anchored so that ``start_xy`` is a cell centre: a straight move along an axis stays on its line
    lo = start - cell * (0.5 + np.ceil((start - level_xy.min(axis=0) + 2 * cell) / cell))
    shape = np.ceil((np.maximum(level_xy.max(axis=0), start) + 2 * cell - lo) / cell).astype(int) + 1
    idx = np.floor((level_xy - lo) / cell).astype(int)
    surface = np.zeros(shape, dtype=bool)
    surface[idx[:, 0], idx[:, 1]] = True
    surface = ndimage.binary_closing(surface, structure=np.ones((3, 3), dtype=bool))
    # a cell holding a sample may reach a cell's width past the surface's edge: one cell in from the edge
    surface = ndimage.binary_erosion(surface, structure=ndimage.generate_binary_structure(2, 1))
    # the footprint as cell offsets: every cell with its centre or a corner inside the footprint's convex hull
    half = int(np.ceil(np.abs(rel).max() / cell)) + 1
    grid = np.arange(-half, half + 1)
    oi, oj = np.meshgrid(grid, grid, indexing="ij")
    inside = np.zeros(oi.shape, dtype=bool)
    try:
        hull = Delaunay(rel)
    except QhullError:  # degenerate footprint (all points on a line): its bounding box
        hull = None
    for di, dj in ((0.0, 0.0), (-0.5, -0.5), (-0.5, 0.5), (0.5, -0.5), (0.5, 0.5)):
        pts = np.column_stack([(oi.ravel() + di) * cell, (oj.ravel() + dj) * cell])
        if hull is not None:
            hit = hull.find_simplex(pts) >= 0
        else:
            hit = np.all((pts >= rel.min(axis=0)) & (pts <= rel.max(axis=0)), axis=1)
        inside |= hit.reshape(oi.shape)
    fits = ndimage.binary_erosion(surface, structure=inside, border_value=0)
    cells = np.argwhere(fits)
    if len(cells) == 0:
        return None
    centres = lo + (cells + 0.5) * cell
    return centres[int(np.argmin(np.linalg.norm(centres - start, axis=1)))]


def onto_start(pose: np.ndarray, com_local: np.ndarray, points_world: np.ndarray, surfaces: np.ndarray,
               reach: float, clearance: float, planes=()) -> tuple[np.ndarray, float] | None:
    """``pose`` moved onto the nearest supporting surface: wholly over it by the smallest motion, just above it.

    An object carried from below whose input is off its supporter (a vase beside the wall shelf it stands on,
    a can hanging over the board's edge: the depth error of a single image) falls when released. Its
    supporter's top is found as the upward-facing surface point nearest to the bottom of the object (within
    ``reach`` m); the object is moved horizontally by the smallest motion that puts its whole footprint over the
    samples of that level (:func:`fitting_point`), or, when it fits nowhere there (a surface narrower than the
    object), over that point pulled inward from the edge by mean-shift steps; and vertically so that its lowest
    point is ``clearance`` m above the surface.

    Parameters
    ----------
    pose : (4, 4) float
        The corrected pose.
    com_local : (3,) float
        Centre of mass, local frame.
    points_world : (n, 3) float
        The object's collision-shape points under ``pose``.
    surfaces : (k, 3) float
        Upward surface samples of the candidate supporters (:func:`upward_samples`).
    reach
        Largest distance (m) between the object's bottom and the surface.
    clearance
        Gap left under the object (m).
    planes
        Walls (:class:`~phiscene.scene.Plane`): surface points behind one are left out (an estimated wall may cut
        through the shelf fixed to it), and in the fallback those closer to one than the object's footprint
        radius.

    Returns
    -------
    (pose (4, 4), horizontal shift in m), or ``None`` when no surface is within reach.
    """
    pts = np.asarray(points_world, dtype=float)
    footprint = max(0.5 * float(np.max(np.ptp(pts[:, :2], axis=0))), 1e-3 / 1.5)  # footprint radius
    surfaces = np.asarray(surfaces, dtype=float).reshape(-1, 3)
    for plane in planes:
        surfaces = surfaces[plane.signed_distance(surfaces) >= 0.0]
    if len(surfaces) == 0:
        return None
    c = com_world(pose, com_local)
    low = float(pts[:, 2].min())
    bottom = np.array([c[0], c[1], low])
    d = np.linalg.norm(surfaces - bottom, axis=1)
    k = int(np.argmin(d))
    if d[k] > reach:
        return None
    level = surfaces[np.abs(surfaces[:, 2] - surfaces[k, 2]) <= 0.01]
    target = fitting_point(level[:, :2], pts[:, :2] - c[:2], c[:2])
    if target is None or np.linalg.norm(target - c[:2]) > reach:
        # fits nowhere within reach: the nearest point pulled inward, mean-shift steps with a kernel of 1.5
        # footprint radii (the shift converges slowly near the kernel radius), clear of the walls
        for plane in planes:
            level = level[plane.signed_distance(level) >= footprint]
        if len(level) == 0:
            return None
        target = level[int(np.argmin(np.linalg.norm(level - bottom, axis=1))), :2].copy()
        for _ in range(10):  # mean shift: away from the edge, towards where the surface lies around the point
            near = level[np.linalg.norm(level[:, :2] - target, axis=1) <= 1.5 * footprint]
            if len(near) == 0:
                break
            target = near[:, :2].mean(axis=0)
    out = np.array(pose, dtype=float, copy=True)
    out[:2, 3] += target - c[:2]
    out[2, 3] += surfaces[k, 2] + clearance - low
    return out, float(np.linalg.norm(target - c[:2]))
