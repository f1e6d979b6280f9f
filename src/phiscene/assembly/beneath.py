"""What lies beneath an object: the vertical gap to its supporters' surfaces and what it rests on.

Rays cast straight down from an object's lowest points onto its supporters' meshes (:func:`gap_under`), read as
the gap that floats or sinks it (:func:`vertical_gap`) and as the objects it rests on (:func:`resting_on`); whether a
supporter lies under an object's centre of mass and around it (:func:`over_support`).
"""

from __future__ import annotations

import numpy as np

from phiscene.assembly.resting import com_world
from phiscene.transforms import transform_points

#: Surface samples of an object's mesh added to its shape's corners when :func:`resting_on` looks for what it rests
#: on (``FaithfulParams.floor_lift``): a box on a round plate overhangs it at every corner, and its hull's corners
#: alone find nothing under them.
RESTING_SAMPLES = 1024


def vertical_gap(points: np.ndarray, supporters: dict, ground_height: float, band: float = 0.3,
                 max_points: int = 256, reach: float = 0.05) -> float | None:
    """Signed vertical gap (m) between points of an object (n, 3), world, and the supporters beneath them.

    ``supporters`` maps a name to its world mesh, or to ``None`` for the ground (height ``ground_height``). Each
    mesh supporter's surface under the object's lowest points (those within ``band`` of its height above the
    lowest, at most ``max_points``) is found by casting rays straight down from ``reach`` above each point (so
    a point sunk in less than that still finds the surface it sank into, and a shelf's upper board is not
    taken for the one under it); the gap is the smallest height of a point above the surface under it, over
    the supporters (negative: it sinks in). ``None`` when no supporter lies under it.
    """
    return gap_under(points, supporters, ground_height, band, max_points, reach)[0]


def gap_under(points: np.ndarray, supporters: dict, ground_height: float, band: float = 0.3, max_points: int = 256,
              reach: float = 0.05, centre: np.ndarray | None = None) -> tuple[float | None, bool]:
    """:func:`vertical_gap`, and whether a supporter's surface lies under ``centre`` (3,) (the ground is under
    everything; ``True`` when no centre is given)."""
    pts = np.asarray(points, dtype=float)
    lo, hi = float(pts[:, 2].min()), float(pts[:, 2].max())
    low = pts[pts[:, 2] <= lo + band * max(hi - lo, 1e-9)]
    if len(low) > max_points:
        low = low[np.linspace(0, len(low) - 1, max_points).astype(int)]
    origins = low + np.array([0.0, 0.0, reach])
    dirs = np.tile([0.0, 0.0, -1.0], (len(low), 1))
    gaps, held = [], centre is None
    for mesh in supporters.values():
        if mesh is None:
            gaps.append(lo - ground_height)
            held = True
            continue
        hits, rays, _ = mesh.ray.intersects_location(origins, dirs, multiple_hits=False)
        if len(hits):
            gaps.append(float(np.min(low[rays, 2] - hits[:, 2])))
        if not held:
            held = bool(mesh.ray.intersects_any(np.asarray(centre, dtype=float)[None], np.array([[0.0, 0.0, -1.0]]))[0])
    return (min(gaps) if gaps else None), held


def resting_on(points: np.ndarray, com: np.ndarray, candidates: dict, ground_height: float, tol: float,
               reach: float = 0.05) -> list[str]:
    """The candidates an object rests on: those whose surface lies at most ``tol`` (m) under its lowest points.

    ``points`` (n, 3) and ``com`` (3,) are the object's (world); ``candidates`` maps an id to its world mesh.
    A candidate counts when :func:`vertical_gap` to it alone is at most ``tol`` (sunk in a little counts); the
    answer is empty unless one of those lies under the centre of mass as well (the object would tip off them).
    """
    found, held = [], False
    for name, mesh in candidates.items():
        gap, under = gap_under(points, {name: mesh}, ground_height, reach=reach, centre=com)
        if gap is not None and gap <= tol:
            found.append(name)
            held = held or under
    return found if held else []


def over_support(pose: np.ndarray, com_local: np.ndarray, points_local: np.ndarray, supporter_mesh,
                 margin: float) -> bool:
    """Whether the supporter's world mesh lies straight under the object's centre of mass and under the points
    ``margin`` (a share of the object's horizontal half-extent) from it along +-x and +-y (world frame).

    Parameters
    ----------
    pose : (4, 4) float
        The object's pose.
    com_local : (3,) float
        Its centre of mass, local frame.
    points_local : (n, 3) float
        Points of its shape, local frame (its horizontal extent).
    supporter_mesh : trimesh.Trimesh
        The supporter at its grounded pose (world).
    margin
        Share of the half-extent (0: the centre of mass alone).
    """
    c = com_world(pose, com_local)
    pts = transform_points(pose, np.asarray(points_local, dtype=float))
    half = 0.5 * (pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0)) * margin
    probes = np.array([c, c + [half[0], 0, 0], c - [half[0], 0, 0], c + [0, half[1], 0], c - [0, half[1], 0]])
    probes[:, 2] = float(np.asarray(supporter_mesh.bounds)[1, 2]) + 1.0  # rays from above the whole supporter
    down = np.tile([0.0, 0.0, -1.0], (len(probes), 1))
    return bool(np.all(supporter_mesh.ray.intersects_any(probes, down)))
