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

Objects with no flat face and no upright frame (toys, fruit, plants, bags on a floor) cast box votes whose axes
are arbitrary, and no two of them may agree. What such a scene still shows is its floor: the objects standing on
it touch it at their lowest points, which lie on one plane normal to up. When the votes stay that weak,
:func:`floor_up` fits that plane (the objects with nothing beneath them whose bottoms lie within ``floor_band`` of
the lowest, each one witness; at least :data:`FLOOR_MIN_OBJECTS` of them, spread over the floor, and more than the
votes that agree) and its normal is the estimate (:attr:`UpEstimate.floor` records it).

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

#: Objects standing on the floor that :func:`estimate_up` needs to take its plane (:func:`floor_up`): three points
#: always lie on a plane, a fourth tests it (a Gen3DSR room's desk and two chairs, placed decimetres off, gave a
#: plane 35 degrees from its votes with no residual at all).
FLOOR_MIN_OBJECTS = 4

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
    floor_plane_rms
        :func:`floor_up`'s plane is taken only when the objects' lowest points lie within this RMS distance (m) of
        it (depth errors of real reconstructions put them 1-3 cm off; more is not one floor).
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
    floor_plane_rms: float = 0.03

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
        if self.floor_plane_rms < 0:
            raise ValueError(f"levelling parameter 'floor_plane_rms' must be >= 0, got {self.floor_plane_rms}")
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
    floor : FloorPlane or None
        The floor plane the estimate was taken from, when the votes were too weak (:func:`estimate_up`); ``None``:
        the votes.
    """

    up: np.ndarray
    tilt_deg: float
    spread_deg: float
    votes: dict
    steep_prior: np.ndarray | None = None
    floor: "FloorPlane | None" = None

    def to_dict(self) -> dict:
        """JSON form (``import.json``)."""
        out = {"up": [float(v) for v in self.up], "tilt_deg": float(self.tilt_deg),
               "spread_deg": float(self.spread_deg), "votes": self.votes}
        if self.steep_prior is not None:
            out["steep_prior"] = [float(v) for v in self.steep_prior]
        if self.floor is not None:
            out["floor"] = self.floor.to_dict()
        return out


@dataclass(frozen=True)
class FloorPlane:
    """The floor through the lowest points of the objects standing on it (:func:`floor_up`).

    Attributes
    ----------
    up : (3,) float
        Unit normal of the plane (pointing along the start direction), source frame.
    objects
        Ids of the objects standing on it, one witness each.
    rms
        RMS distance (m) of their lowest points from the plane.
    """

    up: np.ndarray
    objects: tuple[str, ...]
    rms: float

    def to_dict(self) -> dict:
        """JSON form."""
        return {"up": [round(float(v), 6) for v in self.up], "objects": list(self.objects),
                "rms": round(float(self.rms), 6)}


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

    When still fewer than :data:`MIN_AGREEMENT` votes agree, the floor is fitted (:func:`floor_up`, started from
    that estimate, the camera's up and the steeper priors): a plane within ``floor_plane_rms`` of the lowest points
    of at least :data:`FLOOR_MIN_OBJECTS` standing objects, more than the votes that agree, within ``max_tilt_deg`` of
    the camera's up, is the estimate (the one with the most objects, then the least RMS;
    :attr:`UpEstimate.floor`).

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
    steeper = [_unit(c * prior + s * side) for side in (a, -a, b, -b)]
    for steep in steeper:
        estimate = _estimate(meshes, steep, params)
        agree = _agreement(estimate)
        if agree[0] >= MIN_AGREEMENT and agree > score:
            best, score = UpEstimate(estimate.up, angle_deg(estimate.up, prior), estimate.spread_deg,
                                     estimate.votes, steep), agree
    if best.steep_prior is not None:
        log.info("up: %d votes agree within %g deg of the camera's up, %d of a prior %g deg steeper: levelled by "
                 "%.1f deg", first, params.max_tilt_deg, score[0], STEEP_PRIOR_DEG, best.tilt_deg)
    if score[0] < MIN_AGREEMENT:
        parts = {i: np.asarray(m.vertices, dtype=float) for i, m in meshes.items()}
        # from the estimate, the camera's up and the steeper priors: a start far off the floor's normal sees its
        # far side higher than the band, and too few objects on it
        planes = [f for f in (floor_up(parts, start, params.floor_band) for start in [best.up, prior, *steeper])
                  if f is not None and f.rms <= params.floor_plane_rms
                  and angle_deg(f.up, prior) <= params.max_tilt_deg]
        floor = min(planes, key=lambda f: (-len(f.objects), f.rms), default=None)
        if floor is not None and len(floor.objects) >= FLOOR_MIN_OBJECTS and len(floor.objects) > score[0]:
            log.info("up: %d votes agree; the floor under %d standing objects (RMS %.3f m) levels by %.1f deg",
                     score[0], len(floor.objects), floor.rms, angle_deg(floor.up, prior))
            return _recount(best.votes, floor.up, prior, params, floor)
    return best


def _recount(votes: dict, up: np.ndarray, prior: np.ndarray, params: LevelParams,
             floor: "FloorPlane") -> UpEstimate:
    """The estimate ``up`` (taken from ``floor``), with each vote's ``inlier`` flag and the spread recounted
    about it."""
    cos_in = np.cos(np.radians(params.inlier_deg))
    record, ang, weight = {}, [], []
    for i, v in votes.items():
        inlier = bool(np.asarray(v["up"], dtype=float) @ up >= cos_in * np.linalg.norm(v["up"]))
        record[i] = {**v, "inlier": inlier}
        if inlier:
            ang.append(np.radians(angle_deg(v["up"], up)))
            weight.append(v["weight"])
    spread = float(np.degrees(np.sqrt(np.average(np.square(ang), weights=weight)))) if ang else 0.0
    return UpEstimate(up, angle_deg(up, prior), spread, record, None, floor)


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
    if band <= 0:
        return float(lo[:, 2].min())
    if len(parts) < 2:
        return resting_bottom(parts[0], rest_deg)
    standing = standing_objects(parts)
    bottoms = np.array([resting_bottom(parts[i], rest_deg) for i in range(len(parts)) if standing[i]])
    return float(np.median(bottoms[bottoms <= bottoms.min() + band]))


def standing_objects(parts: list[np.ndarray]) -> np.ndarray:
    """Which objects of a levelled scene (z up) have nothing beneath them: no other object covers at least
    :data:`BENEATH_SHARE` of their bounding-box footprint with a top below their mid-height.

    Parameters
    ----------
    parts : list of (n_i, 3) float
        Each object's vertices.

    Returns
    -------
    (len(parts),) bool
    """
    lo = np.array([p.min(axis=0) for p in parts])
    hi = np.array([p.max(axis=0) for p in parts])
    mid = 0.5 * (lo[:, 2] + hi[:, 2])
    area = np.maximum(np.prod(hi[:, :2] - lo[:, :2], axis=1), 1e-12)
    standing = np.ones(len(parts), dtype=bool)
    for i in range(len(parts)):
        overlap = np.prod(np.clip(np.minimum(hi[:, :2], hi[i, :2]) - np.maximum(lo[:, :2], lo[i, :2]), 0, None),
                          axis=1)
        beneath = (overlap >= BENEATH_SHARE * area[i]) & (hi[:, 2] < mid[i])
        beneath[i] = False
        standing[i] = not beneath.any()
    return standing


#: The lowest points :func:`floor_up` fits must spread at least this far (m, RMS about their centre) across the
#: floor in its narrowest direction: a row of objects along one line leaves the plane free to turn about it.
FLOOR_MIN_SPREAD = 0.1
#: Refits of :func:`floor_up` at most (each with the objects' lowest points along the last normal).
FLOOR_ITERATIONS = 8


def floor_up(parts: dict[str, np.ndarray], start, band: float) -> FloorPlane | None:
    """The plane through the lowest points of the objects standing on the floor, and its normal.

    Levelled along the current up direction (``start`` first), the objects with nothing beneath them
    (:func:`standing_objects`) whose lowest points lie within ``band`` of the lowest such point stand on the floor;
    a least-squares plane through those points gives the next up direction, and the objects' lowest points are
    taken again along it, until it stops turning (at most :data:`FLOOR_ITERATIONS` fits). On a level floor every
    object touches it at its lowest point whatever its shape or turn (a ball's lowest point lies under its centre),
    so with no error the plane is the floor exactly.

    Parameters
    ----------
    parts
        Object id -> its vertices (n_i, 3), source frame.
    start : (3,) float
        Up direction to start from (source frame).
    band
        Height (m) above the lowest standing object within which an object stands on the floor
        (:attr:`LevelParams.floor_band`).

    Returns
    -------
    The plane; ``None`` when fewer than 3 objects stand on it or their lowest points do not spread over it
    (:data:`FLOOR_MIN_SPREAD`).
    """
    ids = list(parts)
    if len(ids) < 3:
        return None
    up = _unit(start)
    z = np.array([0.0, 0.0, 1.0])
    for _ in range(FLOOR_ITERATIONS):
        R = rotation_between(up, z)
        turned = [np.asarray(parts[i], dtype=float) @ R.T for i in ids]
        bottoms = np.array([t[:, 2].min() for t in turned])
        standing = standing_objects(turned)
        on_floor = standing & (bottoms <= bottoms[standing].min() + band)
        if on_floor.sum() < 3:
            return None
        points = np.array([turned[k][np.argmin(turned[k][:, 2])] for k in np.flatnonzero(on_floor)])
        centred = points - points.mean(axis=0)
        if np.linalg.svd(centred[:, :2], compute_uv=False)[1] / np.sqrt(len(points)) < FLOOR_MIN_SPREAD:
            return None
        design = np.c_[centred[:, :2], np.ones(len(points))]
        slope, *_ = np.linalg.lstsq(design, centred[:, 2], rcond=None)
        normal = R.T @ _unit(np.array([-slope[0], -slope[1], 1.0]))
        turn = angle_deg(normal, up)
        up = normal
        if turn < 1e-4:
            break
    rms = float(np.sqrt(np.mean((centred[:, 2] - design @ slope) ** 2)))
    return FloorPlane(up, tuple(ids[k] for k in np.flatnonzero(on_floor)), rms)


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
