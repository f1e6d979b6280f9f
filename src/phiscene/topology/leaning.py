"""Leaning for the ``geometric`` backend: whether an object rests or tips, and what it tips onto.

The support test of :mod:`phiscene.topology.geometric` counts every sample within the contact tolerance
(a few centimetres, for the input's errors) as touching. A plank leaning at 35 deg has a long stretch within
that band of the floor, so its centre of mass looks held by the floor alone and the box it leans on is never
named. :func:`tipping` reads the contact the way a rigid body rests: only the samples within ``band`` of
each supporter's lowest gap touch; if the centre of mass lies outside their hull the object tips about its
edge, and :attr:`Tipping.fall` is how far it turns before its own surface reaches the supporting height. A
small fall (a box tilted a few degrees by a rotation error) is an input error that flushing corrects; a large
one (a plank, a book or a panel standing at 20 deg or more off its resting pose) is leaning, and
:func:`tipping_partner` names the object or wall it would fall onto, sweeping its samples about the tipping
edge: the input's depth errors often leave a leaning object centimetres away from what holds it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phiscene.topology.contacts import Body, Contact, hull_offset


@dataclass(frozen=True)
class Tipping:
    """How an object rests on the samples that touch its supporters.

    Attributes
    ----------
    distance
        How far the centre of mass (xy) lies outside the hull of the touching samples (m; <= 0 inside).
    direction : (2,) float
        Unit xy direction from that hull towards the centre of mass (zeros when inside).
    pivot : (3,) float
        A point of the tipping edge: the touching sample farthest along ``direction``.
    fall
        Degrees the object turns about the tipping edge before a sample beyond the edge reaches the pivot's
        height (90 when none lies beyond it; 0 when the object is held).
    """

    distance: float
    direction: np.ndarray
    pivot: np.ndarray
    fall: float

    def leans(self, margin: float, fall_deg: float) -> bool:
        """Whether the object leans: its centre of mass more than ``margin`` m outside the touching samples and a
        fall of at least ``fall_deg`` before it lies down (a smaller one is a rotation error)."""
        return self.distance > margin and self.fall >= fall_deg


def tipping(a: Body, supports: list[Contact], band: float, lever: float) -> Tipping:
    """How ``a`` rests on the samples within ``band`` (m) of each supporter's lowest gap.

    Parameters
    ----------
    a
        The object.
    supports
        Its contacts with the supporters from below (non-empty).
    band
        Samples whose gap is within this of their supporter's lowest gap touch.
    lever
        Samples less than this (m) beyond the tipping edge do not bound the fall (the edge's own samples).
    """
    index = np.concatenate([c.index[c.gap <= c.gap.min() + band] for c in supports if len(c)])
    touching = a.points[index]
    distance, direction = hull_offset(touching[:, :2], a.com[:2])
    if not np.any(direction):
        return Tipping(float(distance), direction, a.com.copy(), 0.0)
    along = touching[:, :2] @ direction
    pivot = touching[int(np.argmax(along))].copy()
    beyond = a.points[:, :2] @ direction - float(along.max())
    mask = beyond > lever
    if not mask.any():
        return Tipping(float(distance), direction, pivot, 90.0)
    height = np.maximum(a.points[mask, 2] - pivot[2], 0.0)
    fall = math.degrees(float(np.min(np.arctan2(height, beyond[mask]))))
    return Tipping(float(distance), direction, pivot, fall)


def rotate_about_edge(points: np.ndarray, pivot: np.ndarray, direction: np.ndarray, angle: float) -> np.ndarray:
    """``points`` (n, 3) turned by ``angle`` (rad) about the horizontal line through ``pivot`` (3,) normal to
    ``direction`` (2,), the side along ``direction`` going down."""
    from scipy.spatial.transform import Rotation

    axis = np.array([-direction[1], direction[0], 0.0])
    return Rotation.from_rotvec(angle * axis).apply(points - pivot) + pivot


def tipping_partner(a: Body, tip: Tipping, bodies: dict[str, Body], names, planes, step_deg: float, hit: float,
                    above: float, lower: float = 0.0) -> tuple[str, float] | None:
    """What ``a`` falls onto when it tips about its edge: the first object or wall its samples reach.

    A's samples higher than ``above`` (z, m) are turned about the tipping edge of ``tip`` in steps of
    ``step_deg`` up to (not including) ``tip.fall``; the first step at which one of them comes within ``hit``
    (m) of a sample of a body in ``names``, or crosses a wall plane (:class:`phiscene.scene.Plane` with
    ``kind == "wall"``), names the partner (ties: walls first, then by name). Samples already that close to a
    body, or behind a wall, before turning do not count for it: resting against something is not falling onto
    it. With ``lower`` > 0, A (its samples and ``tip.pivot``) is first moved down by that much (m; an object
    floating above its supporter, lowered onto it as grounding will); ``above`` is a height after lowering.

    Returns
    -------
    ``(name, angle_deg)`` of the partner and the angle turned, or ``None`` when A lies down first.
    """
    from scipy.spatial import cKDTree

    drop = np.array([0.0, 0.0, lower])
    pivot = tip.pivot - drop
    pts = a.points - drop
    pts = pts[pts[:, 2] > above]
    if not len(pts) or tip.fall <= 0.0:
        return None
    reach = float(np.max(np.linalg.norm(pts - pivot, axis=1))) + hit
    lo, hi = pivot - reach, pivot + reach
    near = [n for n in sorted(names) if np.all(bodies[n].bounds[0] <= hi) and np.all(bodies[n].bounds[1] >= lo)]
    trees = {n: cKDTree(bodies[n].points) for n in near}
    free = {n: ~np.isfinite(trees[n].query(pts, distance_upper_bound=hit)[0]) for n in near}
    walls = [p for p in planes if p.kind == "wall"]
    front = {p.id: p.signed_distance(pts) > 0.0 for p in walls}
    for angle in np.arange(step_deg, tip.fall, step_deg):
        q = rotate_about_edge(pts, pivot, tip.direction, math.radians(float(angle)))
        for wall in walls:
            if np.any(front[wall.id] & (wall.signed_distance(q) <= 0.0)):
                return wall.id, float(angle)
        for n in near:
            m = free[n]
            if m.any() and np.isfinite(trees[n].query(q[m], distance_upper_bound=hit)[0]).any():
                return n, float(angle)
    return None


def floating_tipping(a: Body, height: float, band: float, lever: float) -> tuple[Tipping, float]:
    """How ``a``, which touches nothing, would rest lowered straight down onto a level surface at ``height``
    (z, m): :func:`tipping` on its samples within ``band`` of its lowest one (the same in its own pose as
    lowered), and how far it is lowered (m; negative when it would rise).
    """
    z = a.points[:, 2]
    contact = Contact(np.arange(len(z)), z - height, np.tile([0.0, 0.0, 1.0], (len(z), 1)), np.full(len(z), height))
    return tipping(a, [contact], band, lever), float(z.min() - height)


def leaned_on(a: Body, supports: dict[str, Contact], band: float, lever: float, margin: float,
              fall_deg: float) -> list[str]:
    """The supporters from below that ``a`` leans on rather than stands on.

    With two or more supporters, ``a`` stands on the lowest one (the lowest median height of its contact
    samples; ties by name); when it tips on that one's touching samples alone (:func:`tipping`: its centre of
    mass more than ``margin`` m outside them) and would turn at least ``fall_deg`` to lie down on it, the
    others hold it up as a wall would (a book with one end on the floor and its side on a box's edge). A plank
    bridging two boxes lies level on each: it does not lean. Returns their names, sorted (empty otherwise).
    """
    if len(supports) < 2:
        return []
    low = min(sorted(supports), key=lambda k: float(np.median(a.points[supports[k].index, 2])))
    if tipping(a, [supports[low]], band, lever).leans(margin, fall_deg):
        return sorted(k for k in supports if k != low)
    return []
