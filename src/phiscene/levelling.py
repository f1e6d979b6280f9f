"""Gravity from geometry: the up direction of a camera-frame scene, and the rigid transform that levels it.

A 3D foundation model places objects in a frame that follows the camera, so gravity is off by the camera's
pitch and roll (2.5 to 22 degrees on real SAM 3D Objects scenes). Nothing in such a scene is labelled "floor",
and a table-top photo has no floor at all. What real scenes do offer:

* large upward-facing planar regions: table tops, seats, plates, shelves, the tops of cabinets and dressers.
  On one object they are a sharp peak in the distribution of area-weighted face normals;
* the canonical frame of box-like furniture: a 3D generator builds objects upright, so one axis of an object's
  minimum-volume oriented bounding box is its up axis.

Each object casts one *vote* for the up direction (:func:`object_votes`): the normal of its dominant upward planar
region when it has one covering at least ``plane_share`` of its area, otherwise its oriented bounding box axis
nearest the prior, with a smaller weight. A plane vote weighs its region's area, a box vote ``box_weight`` times the
box's area scale, each raised to ``weight_power`` (0.5: a large object counts more, but its own rotation error
does not become the scene's; see :class:`LevelParams`). Votes are restricted to a
cone of ``max_tilt_deg`` around the camera's rough up direction (the prior). The estimate
(:func:`estimate_up`) is a mode of the votes: a weighted mean re-estimated from the votes within ``inlier_deg`` of
the current estimate until it stops changing (mean shift), started from the mean of all votes and from every vote;
the mode whose cone holds the most votes wins (then the most weight). A fruit, a tilted book or a mis-rotated object
is outvoted by the table top and the furniture, and one large leaning board does not outweigh the objects that
agree with each other. Its spread (weighted RMS angle of the inliers) is reported as a confidence measure.
A camera looking steeply down (more than about 40 degrees) puts the scene's up outside the prior's cone; when fewer
than :data:`MIN_AGREEMENT` votes agree, the estimate is made again from priors :data:`STEEP_PRIOR_DEG` steeper.

:func:`levelling_transform` turns the estimate into a rigid transform: the minimal rotation taking up to +z,
preceded by the up-axis convention of the source (y-up files become z-up), a rotation about z that makes the
camera's viewing direction +y (x is the camera's right), and a translation that puts the ground plane at
``z = 0``. The ground (:func:`floor_height`) is where the objects standing on it stand: the median of the bottoms
of the objects with nothing beneath them, within ``floor_band`` of the lowest (the feet of the furniture, or the
table in a table-top photo), each bottom taken where the object would rest on its nearest resting facet
(``floor_rest_deg``), not at the corner a rotation error tilts down. Depth errors move objects along the camera's
ray, which looks down: the lowest point of the scene belongs to the object sunk deepest, and putting it on the
ground would lift everything else (by 4 to 16 cm on the ``clutter`` suite's initial scenes). The median moves the
floor-standing objects least in total.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh

from phiscene.params import Params
from phiscene.tolerances import TOL

log = logging.getLogger(__name__)

#: Fewer votes than this agreeing on the up estimate in the camera's cone: steeper priors are tried
#: (:func:`estimate_up`).
MIN_AGREEMENT = 3

#: How far (deg) those steeper priors are turned from the camera's up. With the cone's ``max_tilt_deg`` (40),
#: scenes tilted up to about 70 degrees are in reach, while a wall's normal, 90 degrees from up, stays 20 degrees
#: outside the cone of a prior turned towards it from a level camera.
STEEP_PRIOR_DEG = 30.0

#: Up axis conventions of source files -> the rotation that makes them z-up.
UP_AXES = ("y", "z")


@dataclass(frozen=True)
class LevelParams(Params):
    """Settings of the up-direction estimate (:func:`estimate_up`).

    Attributes
    ----------
    max_tilt_deg
        Votes farther than this from the prior are ignored (the camera's largest plausible pitch/roll).
    plane_bandwidth_deg
        Faces within this angle of a candidate normal count towards its planar region.
    plane_share
        An object votes with its dominant plane when the plane covers at least this share of its surface area.
    box_weight
        Weight of an oriented-bounding-box vote relative to a plane vote of the same area scale.
    weight_power
        A vote weighs its area (the planar region's, or the box's area scale) raised to this power: 1 = the
        largest object decides, 0 = one object, one vote. A 3D foundation model errs in each object's rotation
        whatever its size (median 3.6 degrees, 90th percentile 11), so under area weights the largest object's
        own rotation error becomes the scene's tilt; equal weights let a few small objects that are not level
        (a leaning plank, a tilted book) outvote the furniture. Measured against the exact tilt of the
        ``clutter`` suite's 20 camera-frame scenes (``benchmarks/levelling_clutter.py``), with the mean shift
        from the mean of all votes only: 1 leaves a mean error of 3.05 degrees (90th percentile 7.07), 0.5 (the
        default) 2.59 (6.06); on 19 scenes of another seed 1.88 (4.79) and 1.18 (2.10). With the mode that
        holds the most votes (:func:`estimate_up`) and 0.5: 2.07 (4.38) and 1.16 (2.10).
    inlier_deg
        Votes within this angle of the current estimate are kept when it is re-estimated.
    candidates
        Faces sampled (by area) per object as candidate plane normals.
    seed
        Seed of that sampling.
    floor_band
        Ground height (:func:`floor_height`): objects with nothing beneath them whose bottoms lie within this
        height (m) of the lowest one stand on the ground; 0 = the lowest point of the scene.
    floor_rest_deg
        Each standing object's bottom is taken where it would rest (:func:`resting_bottom`): turned, about its
        centre of mass, onto the resting facet of its convex hull nearest to facing down, when that facet is
        within this angle (the turn grounding's flush makes, ``assembly.faithful.max_flush_angle``); 0 = its
        lowest point as it came. A rotation error tilts an object about its centre, so its lowest corner sinks
        below its base by about half its width times the tilt: a table-top slab 2.5 m wide tilted 2.6 degrees
        has its corner 4 cm below its base; with that corner as the ground, flushing the slab lowered it and
        everything on it by 4 cm (``custom_viga``).
    """

    _label = "levelling parameters"

    max_tilt_deg: float = 40.0
    plane_bandwidth_deg: float = 4.0
    plane_share: float = 0.08
    box_weight: float = 0.25
    weight_power: float = 0.5
    inlier_deg: float = 10.0
    candidates: int = 1500
    seed: int = 0
    floor_band: float = 0.25
    floor_rest_deg: float = 20.0

    def check(self) -> None:
        """Angles in (0, 90) degrees, shares in (0, 1], positive counts (``ValueError``)."""
        for key in ("max_tilt_deg", "plane_bandwidth_deg", "inlier_deg"):
            if not 0.0 < getattr(self, key) < 90.0:
                raise ValueError(f"levelling parameter {key!r} must be in (0, 90) degrees, got {getattr(self, key)}")
        if not 0.0 < self.plane_share <= 1.0:
            raise ValueError(f"levelling parameter 'plane_share' must be in (0, 1], got {self.plane_share}")
        if not 0.0 <= self.floor_rest_deg < 90.0:
            raise ValueError(f"levelling parameter 'floor_rest_deg' must be in [0, 90) degrees, got "
                             f"{self.floor_rest_deg}")
        if self.box_weight < 0 or self.candidates < 1 or self.floor_band < 0 or self.weight_power < 0:
            raise ValueError("levelling parameters 'box_weight', 'weight_power' and 'floor_band' must be >= 0 and "
                             "'candidates' >= 1")


@dataclass(frozen=True)
class UpEstimate:
    """The estimated up direction of a scene.

    Attributes
    ----------
    up : (3,) float
        Unit up vector in the source frame.
    tilt_deg
        Angle between ``up`` and the prior.
    spread_deg
        Weighted RMS angle of the inlier votes from ``up``.
    votes
        Per object id: ``{"kind": "plane" | "box", "up": [3], "area": a, "weight": w, "inlier": bool}`` (``area``:
        the planar region's area, or the box's area scale, m^2).
    steep_prior : (3,) float or None
        The steeper prior the votes were cast in, when the camera's up gave too few agreeing votes
        (:func:`estimate_up`); ``None``: the camera's up.
    """

    up: np.ndarray
    tilt_deg: float
    spread_deg: float
    votes: dict
    steep_prior: np.ndarray | None = None

    def to_dict(self) -> dict:
        """JSON form (``import.json``)."""
        out = {"up": [float(v) for v in self.up], "tilt_deg": float(self.tilt_deg),
               "spread_deg": float(self.spread_deg), "votes": self.votes}
        if self.steep_prior is not None:
            out["steep_prior"] = [float(v) for v in self.steep_prior]
        return out


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (degrees) between two vectors (3,)."""
    return float(np.degrees(np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))))


def plane_vote(mesh: trimesh.Trimesh, prior: np.ndarray, params: LevelParams) -> tuple[np.ndarray, float] | None:
    """The normal of the dominant upward planar region of a mesh and the region's area, if it is one.

    Parameters
    ----------
    mesh
        The object in the source frame.
    prior : (3,) float
        Unit prior up direction.

    Returns
    -------
    ``(normal (3,), area)``, or ``None`` when no region within ``max_tilt_deg`` of the prior covers
    ``plane_share`` of the mesh's area.
    """
    normals, areas = mesh.face_normals, mesh.area_faces
    near = normals @ prior > np.cos(np.radians(params.max_tilt_deg))
    if near.sum() < 3 or areas.sum() <= 0:
        return None
    n, a = normals[near], areas[near]
    rng = np.random.default_rng(params.seed)
    pick = rng.choice(len(n), size=min(params.candidates, len(n)), replace=False, p=a / a.sum())
    cos_bw = np.cos(np.radians(params.plane_bandwidth_deg))
    score = ((n[pick] @ n.T) > cos_bw).astype(float) @ a
    best = n[pick[int(np.argmax(score))]]
    for _ in range(5):  # mean shift on the sphere: the mean normal of the faces within the bandwidth
        w = a * ((n @ best) > cos_bw)
        best = _unit((n * w[:, None]).sum(axis=0))
    share = float(a[(n @ best) > cos_bw].sum())
    if share < params.plane_share * float(areas.sum()):
        return None
    return best, share


def box_vote(mesh: trimesh.Trimesh, prior: np.ndarray) -> tuple[np.ndarray, float]:
    """The axis of the minimum-volume oriented bounding box nearest the prior, and the box's area scale.

    Returns
    -------
    ``(axis (3,) pointing along the prior, volume ** (2/3))``
    """
    box = mesh.bounding_box_oriented.primitive
    axes = np.asarray(box.transform, dtype=float)[:3, :3]
    i = int(np.argmax(np.abs(axes.T @ prior)))
    axis = axes[:, i] * np.sign(axes[:, i] @ prior)
    return _unit(axis), float(np.prod(box.extents)) ** (2.0 / 3.0)


def object_votes(meshes: dict[str, trimesh.Trimesh], prior: np.ndarray, params: LevelParams) -> dict:
    """One up vote per object (module docstring); objects whose vote is outside the prior's cone cast none."""
    prior = _unit(prior)
    votes = {}
    for oid, mesh in meshes.items():
        plane = plane_vote(mesh, prior, params)
        if plane is not None:
            votes[oid] = {"kind": "plane", "up": plane[0], "area": plane[1], "weight": plane[1] ** params.weight_power}
            continue
        axis, scale = box_vote(mesh, prior)
        if angle_deg(axis, prior) <= params.max_tilt_deg and params.box_weight > 0:
            votes[oid] = {"kind": "box", "up": axis, "area": scale,
                          "weight": params.box_weight * scale ** params.weight_power}
    return votes


def estimate_up(meshes: dict[str, trimesh.Trimesh], prior, params: LevelParams = LevelParams()) -> UpEstimate:
    """Up direction of a scene from its objects' votes (module docstring).

    When fewer than :data:`MIN_AGREEMENT` votes agree on the estimate (the scene's up may lie outside the prior's
    cone: a camera looking steeply down), the estimate is made again with the prior turned by
    :data:`STEEP_PRIOR_DEG` towards each of four directions at right angles, and the one on which the most votes
    agree (then the most weight), at least :data:`MIN_AGREEMENT` and more than the first, is taken
    (:attr:`UpEstimate.steep_prior` records its prior).

    Parameters
    ----------
    meshes
        Object id -> mesh in the source frame.
    prior : (3,) float
        The camera's rough up direction in the source frame.

    Returns
    -------
    The estimate; the prior itself (spread 0) when no object votes.
    """
    prior = _unit(prior)
    best = _estimate(meshes, prior, params)
    score = _agreement(best)
    if score[0] >= MIN_AGREEMENT:
        return best
    first = score[0]
    a = _unit(np.cross(prior, [1.0, 0.0, 0.0] if abs(prior[0]) < 0.9 else [0.0, 1.0, 0.0]))
    b = np.cross(prior, a)
    c, s = np.cos(np.radians(STEEP_PRIOR_DEG)), np.sin(np.radians(STEEP_PRIOR_DEG))
    for side in (a, -a, b, -b):
        steep = _unit(c * prior + s * side)
        estimate = _estimate(meshes, steep, params)
        agree = _agreement(estimate)
        if agree[0] >= MIN_AGREEMENT and agree > score:
            best, score = UpEstimate(estimate.up, angle_deg(estimate.up, prior), estimate.spread_deg,
                                     estimate.votes, steep), agree
    if best.steep_prior is not None:
        log.info("up: %d votes agree within %g deg of the camera's up, %d of a prior %g deg steeper: levelled by "
                 "%.1f deg", first, params.max_tilt_deg, score[0], STEEP_PRIOR_DEG, best.tilt_deg)
    return best


def _agreement(estimate: UpEstimate) -> tuple[int, float]:
    """How many votes agree on an estimate (its inliers), and their weight."""
    inliers = [v for v in estimate.votes.values() if v["inlier"]]
    return len(inliers), float(sum(v["weight"] for v in inliers))


def _estimate(meshes: dict[str, trimesh.Trimesh], prior: np.ndarray, params: LevelParams) -> UpEstimate:
    """:func:`estimate_up` with one prior (unit (3,)): the densest mode of the votes in its cone."""
    votes = object_votes(meshes, prior, params)
    if not votes:
        return UpEstimate(prior, 0.0, 0.0, {})
    ids = list(votes)
    V = np.array([votes[i]["up"] for i in ids])
    W = np.array([votes[i]["weight"] for i in ids])
    cos_in = np.cos(np.radians(params.inlier_deg))
    up = _densest_mode(V, W, cos_in)
    keep = V @ up >= cos_in
    ang = np.radians([angle_deg(v, up) for v in V])
    spread = float(np.degrees(np.sqrt((W[keep] * ang[keep] ** 2).sum() / W[keep].sum()))) if keep.any() else 0.0
    record = {i: {"kind": votes[i]["kind"], "up": [round(float(x), 6) for x in votes[i]["up"]],
                  "area": round(float(votes[i]["area"]), 6), "weight": round(float(votes[i]["weight"]), 6),
                  "inlier": bool(k)} for i, k in zip(ids, keep)}
    return UpEstimate(up, angle_deg(up, prior), spread, record)


def _mean_shift(V: np.ndarray, W: np.ndarray, start: np.ndarray, cos_in: float) -> np.ndarray:
    """Weighted mean shift on the sphere from ``start``: the mean of the votes within the window, to convergence."""
    up = start
    for _ in range(20):
        keep = V @ up >= cos_in
        if not keep.any():
            break
        new = _unit((V[keep] * W[keep, None]).sum(axis=0))
        if angle_deg(new, up) < 1e-6:
            break
        up = new
    return up


def _densest_mode(V: np.ndarray, W: np.ndarray, cos_in: float) -> np.ndarray:
    """The mode of the votes whose window holds the most votes (then the most weight).

    The mean shift (:func:`_mean_shift`) is started from the weighted mean of all votes and from every vote; the
    mode whose window holds the most votes wins, then the one holding the most weight, then the first start (the
    overall mean). Started from the overall mean alone, a scene whose votes split into groups farther apart than
    the window follows the heaviest group, or ends between the groups with no vote in its window: the exact
    tilt's error on ``clutter/scene_001`` (one object's plane 35 degrees off, the heaviest vote, against two others)
    was 14.3 degrees, 3.4 now. Counting votes is the consensus of a robust estimator (each object one witness of
    gravity); the weights refine the estimate within the winning window.

    Parameters
    ----------
    V : (n, 3) float
        Unit votes.
    W : (n,) float
        Their weights.
    cos_in
        Cosine of the window's half angle.

    Returns
    -------
    (3,) float
        Unit up direction.
    """
    best, best_weight = None, (0, 0.0)
    for start in [_unit((V * W[:, None]).sum(axis=0)), *V]:
        up = _mean_shift(V, W, start, cos_in)
        inliers = V @ up >= cos_in
        weight = (int(inliers.sum()), float(W[inliers].sum()))
        if best is None or weight[0] > best_weight[0] or (
                weight[0] == best_weight[0] and weight[1] > best_weight[1] + 1e-12):
            best, best_weight = up, weight
    return best


def rotation_between(a, b) -> np.ndarray:
    """The minimal rotation (3, 3) taking unit vector ``a`` to unit vector ``b``."""
    from scipy.spatial.transform import Rotation

    a, b = _unit(a), _unit(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * _unit(perp)).as_matrix()
    return Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_matrix()


#: Share of an object's footprint another object must cover to count as beneath it (:func:`floor_height`).
BENEATH_SHARE = 0.25
#: Vertex cap of the hull whose resting facets place a standing object's bottom (:func:`resting_bottom`; the
#: hull of a 30k-face reconstruction has thousands of vertices, and enumerating resting poses scales with them).
RESTING_HULL_VERTICES = 256


def resting_bottom(points: np.ndarray, max_angle_deg: float) -> float:
    """Height of an object's lowest point once it rests on its nearest resting facet (z up).

    The object (the convex hull of ``points``, a uniform solid) is turned about its centre of mass by the smallest
    rotation that makes its resting facet nearest to facing down face straight down
    (:func:`phiscene.assembly.resting.resting_candidates`), when that facet is within ``max_angle_deg``; else,
    or when ``max_angle_deg`` is 0, it stays as it is.

    Parameters
    ----------
    points : (n, 3) float
        The object's vertices, levelled (z up).
    max_angle_deg
        Largest turn (deg).

    Returns
    -------
    The lowest z of the turned hull (m).
    """
    from scipy.spatial import QhullError

    from phiscene.assembly.resting import resting_candidates, resting_normals
    from phiscene.proxies import capped_hull

    points = np.asarray(points, dtype=float)
    low = float(points[:, 2].min())
    if max_angle_deg <= 0:
        return low
    try:
        with np.errstate(invalid="ignore", divide="ignore"):  # a flat hull's centre of mass divides by 0
            hull = trimesh.convex.convex_hull(capped_hull(trimesh.Trimesh(vertices=points, process=False),
                                                          RESTING_HULL_VERTICES))
            flat = not hull.is_volume  # a poster's quad: it rests as it is
    except (QhullError, ValueError):  # collinear points: nothing to rest on
        return low
    if flat:
        return low
    found = resting_candidates(np.eye(4), resting_normals(hull.vertices), np.asarray(hull.center_mass),
                               np.array([0.0, 0.0, 1.0]), max_angle_deg)
    if not found:
        return low
    turned = found[0][0]
    return float((np.asarray(hull.vertices) @ turned[:3, :3].T + turned[:3, 3])[:, 2].min())


def floor_height(parts: list[np.ndarray], band: float, rest_deg: float = 0.0) -> float:
    """Height of the ground under a levelled scene (z up): where the objects standing on it stand.

    An object stands on the ground unless another one is beneath it: covering at least ``BENEATH_SHARE`` of its
    bounding-box footprint with a top below its mid-height (a book on a table; a chair tucked under a table
    is not on it). Its bottom is where it would rest (:func:`resting_bottom`, within ``rest_deg``; 0 = its lowest
    point). Of those, the ones whose bottoms lie within ``band`` of the lowest bottom are taken (a poster
    on a wall has nothing beneath it either), and the ground is the median of their bottoms.

    Parameters
    ----------
    parts : list of (n_i, 3) float
        Each object's vertices, levelled (z up).
    band
        Height band above the lowest standing object (m); 0 = the lowest point of the scene.
    rest_deg
        Largest turn onto a resting facet (deg; :attr:`LevelParams.floor_rest_deg`).

    Returns
    -------
    The ground height (m).
    """
    lo = np.array([p.min(axis=0) for p in parts])
    hi = np.array([p.max(axis=0) for p in parts])
    if band <= 0:
        return float(lo[:, 2].min())
    if len(parts) < 2:
        return resting_bottom(parts[0], rest_deg)
    mid = 0.5 * (lo[:, 2] + hi[:, 2])
    area = np.maximum(np.prod(hi[:, :2] - lo[:, :2], axis=1), 1e-12)
    standing = []
    for i in range(len(parts)):
        overlap = np.prod(np.clip(np.minimum(hi[:, :2], hi[i, :2]) - np.maximum(lo[:, :2], lo[i, :2]), 0, None),
                          axis=1)
        beneath = (overlap >= BENEATH_SHARE * area[i]) & (hi[:, 2] < mid[i])
        beneath[i] = False
        standing.append(not beneath.any())
    bottoms = np.array([resting_bottom(parts[i], rest_deg) for i in range(len(parts)) if standing[i]])
    return float(np.median(bottoms[bottoms <= bottoms.min() + band]))


def levelling_transform(parts: list[np.ndarray], up, forward=None, floor_band: float = 0.0,
                        floor_rest_deg: float = 0.0) -> np.ndarray:
    """The rigid transform (4, 4) that levels a scene: ``up`` -> +z, ``forward`` -> +y, the ground at z = 0.

    A scene that would then reach farther than ``TOL.max_coordinate`` from the origin horizontally (its frame is a
    building's or a map's, not a camera's) is also moved horizontally so that the centre of its bounding box is
    at the origin; any other keeps its horizontal position (a camera-frame scene: the camera above the origin).

    Parameters
    ----------
    parts : list of (n_i, 3) float
        Each object's vertices, source frame (for the ground height).
    up : (3,) float
        Unit up direction in the source frame.
    forward : (3,) float, optional
        The camera's viewing direction in the source frame; its horizontal part becomes +y (default: keep the
        minimal rotation's heading).
    floor_band
        :func:`floor_height`'s band (m); 0 = the lowest point on the ground.
    floor_rest_deg
        :func:`floor_height`'s largest turn onto a resting facet (deg; 0 = the objects as they came).
    """
    R = rotation_between(up, [0.0, 0.0, 1.0])
    if forward is not None:
        f = R @ np.asarray(forward, dtype=float)
        if np.hypot(f[0], f[1]) > 1e-9:
            heading = np.arctan2(f[0], f[1])  # rotate about z so that f's horizontal part points along +y
            c, s = np.cos(heading), np.sin(heading)
            R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R
    turned = [np.asarray(p, dtype=float) @ R.T for p in parts]
    T = np.eye(4)
    T[:3, :3] = R
    T[2, 3] = -floor_height(turned, floor_band, floor_rest_deg)
    lo = np.min([p.min(axis=0) for p in turned], axis=0)
    hi = np.max([p.max(axis=0) for p in turned], axis=0)
    if np.abs(np.concatenate([lo[:2], hi[:2]])).max() > TOL.max_coordinate:
        # a frame far from the scene (a scan in a building's or a map's coordinates): its horizontal centre to the
        # origin, instead of a refusal as not in metres (no camera-frame scene lies that far from its camera)
        T[:2, 3] = -0.5 * (lo[:2] + hi[:2])
        log.info("the scene lies %.1f m from the origin of its frame: moved by (%.3f, %.3f) m to centre it",
                 float(np.linalg.norm(T[:2, 3])), *T[:2, 3])
    return T
