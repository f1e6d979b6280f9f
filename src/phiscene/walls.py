"""Walls estimated from what hangs on them: the planes a real scene's wall objects stand for.

A scene imported from a 3D foundation model (:mod:`phiscene.io.placed`) has objects and a levelled ground, but
no walls: nothing in the photo is reconstructed as a wall. What it does hold is what hangs on them: posters,
paintings, whiteboards, windows, clocks. Each such object (decided attached by
:func:`phiscene.topology.attached.attached_objects`, for any reason but ``partial`` or ``ceiling``) that is a thin
vertical panel (:func:`phiscene.topology.attached.panel_normal`) is one piece of evidence: its thin axis, made
horizontal and turned towards the room (the camera's eye when known, else the centre of the free objects), is a
wall's normal, and its back face lies on that wall. So is a free object whose description says it stands or leans
against a wall (:func:`phiscene.topology.words.says_against_wall`: "mattress leaning against wall"): the wall
faces away from the way its top leans over its bottom (:func:`_lean_normal`, when it leans at least
:data:`MIN_LEAN_DEG`; else its thin axis if it is a panel, turned towards the room) and touches its rearmost point.
Nothing in the scene shows a wall that nothing hangs on or leans on, so such walls stay unknown.

:func:`estimate_walls` groups the evidence: panels whose normals agree within ``merge_deg`` and whose backs lie
within ``merge_gap`` of each other along that normal are one wall (largest panel first; the normal is the
area-weighted mean of the group's). The wall plane is put at the group's rearmost back, then moved back behind
every free object (nothing free may start inside a wall: the simulator would throw it out). Depth errors leave
furniture a few centimetres behind the paintings above it (7 to 18 cm on the REST3D scenes); an object farther
than ``max_behind`` behind the evidence means the evidence is not a wall the scene stands against (a curtain's
folds give a wrong normal, a panel that is not on a wall), and that group gives no wall.

The planes become the scene's :attr:`~phiscene.scene.Scene.structure` (marked
:attr:`~phiscene.scene.Plane.estimated`): static colliders in every simulator, and supporters an object leans on
(:mod:`phiscene.topology.leaning`). The objects they come from are fixed to them and stay exactly where the input
has them: unlike on a given wall, they are not made flush with it (the plane is their own average). Walls a scene
gives are never replaced.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from phiscene.params import Params
from phiscene.scene import Plane, Scene
from phiscene.topology.attached import PARTIAL, AttachedParams, attached_objects, object_text, panel_normal
from phiscene.topology.words import says_against_wall

#: Attachment reasons that are not evidence of a wall (a furniture fragment; a ceiling fixture).
NOT_WALL_EVIDENCE = (PARTIAL, "ceiling")
#: A free object against a wall leans on it when its top is at least this far (deg) off vertical over its bottom.
MIN_LEAN_DEG = 5.0
#: Share of an object's height whose vertices make its top and its bottom (:func:`_lean_normal`).
LEAN_BAND = 0.1


@dataclass(frozen=True)
class WallParams(Params):
    """Settings of the wall estimate (``config.yaml`` ``suites.<suite>.source.placed.walls``).

    Attributes
    ----------
    enabled
        Estimate walls when the scene gives none (false: a gravity-only scene, as before).
    merge_deg
        Panels whose normals agree within this angle (deg) may be on one wall.
    merge_gap
        ... when their backs also lie within this distance (m) of each other along the normal.
    max_behind
        A free object farther than this (m) behind a group's rearmost back rejects the group.
    """

    _label = "wall parameters"

    enabled: bool = True
    merge_deg: float = 15.0
    merge_gap: float = 0.3
    max_behind: float = 0.25

    def check(self) -> None:
        """An angle in (0, 90), non-negative distances (``ValueError``)."""
        if not 0.0 < self.merge_deg < 90.0:
            raise ValueError(f"wall 'merge_deg' must be in (0, 90), got {self.merge_deg}")
        if min(self.merge_gap, self.max_behind) < 0.0:
            raise ValueError("wall 'merge_gap' and 'max_behind' must be >= 0")


@dataclass
class WallEstimate:
    """Walls of a scene and how they were found.

    Attributes
    ----------
    planes
        The walls (``kind == "wall"``), largest evidence first.
    record
        JSON-ready account: per wall its evidence, normal, offset and how far free objects pushed it back
        (``walls``); groups given up and why (``rejected``).
    """

    planes: list[Plane]
    record: dict = field(default_factory=dict)


@dataclass
class _Group:
    """Panels on one wall: their ids, horizontal normals (3,), weights (area, m^2) and world vertices (n, 3)."""

    ids: list[str]
    normals: list[np.ndarray]
    weights: list[float]
    points: list[np.ndarray]

    @property
    def normal(self) -> np.ndarray:
        n = np.sum([w * v for w, v in zip(self.weights, self.normals)], axis=0)
        return n / np.linalg.norm(n)

    def add(self, oid: str, normal: np.ndarray, weight: float, points: np.ndarray) -> None:
        """One more panel of this wall."""
        self.ids.append(oid)
        self.normals.append(normal)
        self.weights.append(weight)
        self.points.append(points)

    def back(self, n: np.ndarray) -> float:
        """The rearmost point of the group along ``n``: min over its vertices of ``n . p``."""
        return float(min((p @ n).min() for p in self.points))


def _horizontal(v: np.ndarray) -> np.ndarray | None:
    h = np.array([v[0], v[1], 0.0])
    norm = np.linalg.norm(h)
    return h / norm if norm > 1e-9 else None


def _lean_normal(points: np.ndarray) -> np.ndarray | None:
    """The normal (3,) of the wall an object leans on: horizontal, opposite to the way its top leans over its bottom
    (the mean of its vertices in the top and the bottom :data:`LEAN_BAND` of its height), or ``None`` when it leans
    less than :data:`MIN_LEAN_DEG`. ``points`` (n, 3): its vertices in the world frame."""
    z = points[:, 2]
    lo, hi = float(z.min()), float(z.max())
    if hi - lo <= 0.0:
        return None
    band = LEAN_BAND * (hi - lo)
    d = points[z >= hi - band].mean(axis=0) - points[z <= lo + band].mean(axis=0)
    if np.degrees(np.arctan2(np.hypot(d[0], d[1]), max(d[2], 1e-12))) < MIN_LEAN_DEG:
        return None
    return _horizontal(-d)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def estimate_walls(scene: Scene, params: WallParams = WallParams(), eye: np.ndarray | None = None,
                   attached: AttachedParams | None = None) -> WallEstimate:
    """The walls of a levelled (z-up) scene, from the panels hanging on them (module docstring).

    Parameters
    ----------
    scene
        Objects above a ground plane; its given :attr:`~phiscene.scene.Scene.structure`, if any, is kept as is.
    eye : (3,) float, optional
        The camera's centre in the scene frame: walls face it (else they face the centre of the free objects).
    attached
        Thresholds of the attachment decision that picks the evidence (default: its defaults).

    Returns
    -------
    WallEstimate
        No planes when disabled, when the scene gives structure, or when no group of evidence survives.
    """
    if not params.enabled or scene.structure:
        why = "disabled" if not params.enabled else "the scene gives its structure"
        return WallEstimate([], {"walls": [], "rejected": [], "skipped": why})
    attached = attached or AttachedParams()
    world = {o.id: o.world_mesh() for o in scene.objects}
    decided = attached_objects(scene, attached, world)
    free = [oid for oid in scene.ids if oid not in decided]
    centres = [world[o].bounds.mean(axis=0) for o in (free or scene.ids)]
    ref = np.asarray(eye, dtype=float) if eye is not None else np.mean(centres, axis=0)
    evidence = []
    for o in scene.objects:
        why = decided.get(o.id)
        if why in NOT_WALL_EVIDENCE or (why is None and not says_against_wall(object_text(o))):
            continue
        points = np.asarray(world[o.id].vertices, dtype=float)
        n = _lean_normal(points) if why is None else None  # a free object against a wall: the way it leans
        if n is None:
            axis = panel_normal(world[o.id], attached.thin_ratio)
            n = None if axis is None else _horizontal(axis)
            if n is not None and (ref - points.mean(axis=0)) @ n < 0.0:
                n = -n
        if n is None:
            continue
        evidence.append((o.id, n, float(world[o.id].convex_hull.area) / 2.0, points))
    groups: list[_Group] = []
    for oid, n, weight, points in sorted(evidence, key=lambda e: (-e[2], e[0])):
        for g in groups:
            gn = g.normal
            if _angle(n, gn) <= params.merge_deg and abs(float((points @ gn).min()) - g.back(gn)) <= params.merge_gap:
                g.add(oid, n, weight, points)
                break
        else:
            groups.append(_Group([oid], [n], [weight], [points]))
    planes, walls, rejected = [], [], []
    taken = set(scene.ids)
    for g in groups:
        n = g.normal
        back = g.back(n)
        behind = {o: float((np.asarray(world[o].vertices) @ n).min()) for o in free}
        deepest = min(behind, key=behind.get, default=None)
        depth = back - behind[deepest] if deepest is not None else 0.0
        if depth > params.max_behind:
            rejected.append({"evidence": g.ids, "why": f"{deepest} lies {depth:.3f} m behind it"})
            continue
        offset = -min(back, back - depth)
        k = len(planes)
        while f"wall_{k}" in taken:
            k += 1
        name = f"wall_{k}"
        taken.add(name)
        planes.append(Plane(name, "wall", tuple(float(v) for v in n), float(offset), estimated=True))
        walls.append({"id": name, "evidence": g.ids, "normal": [round(float(v), 6) for v in n],
                      "offset": round(float(offset), 6), "pushed_back": round(max(depth, 0.0), 6),
                      "pushed_by": deepest if depth > 0.0 else None})
    return WallEstimate(planes, {"walls": walls, "rejected": rejected})
