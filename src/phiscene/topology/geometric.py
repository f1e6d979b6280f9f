"""``geometric`` backend: load-bearing support inferred from the initial scene's geometry.

The offline default. Initial scenes (a 3D foundation model's output, or the
benchmark's degraded GT) have penetrations and gaps of a few centimetres and
poses a few degrees off, so support is read from *near* contact, not exact
contact. An edge ``B -> A`` means B carries part of A's weight.

1. **Samples** (:mod:`phiscene.topology.contacts`). Every object is sampled
   uniformly with its face normals; upward-facing and near-vertical samples
   each get a cKDTree. Object pairs are pruned by world AABBs first.
2. **Tolerance.** ``tol = clip(gap_rel * s, gap_abs, gap_max)`` with ``s``
   the longest OBB side of the smaller object of the pair (of A for the ground).
3. **Contacts.** A sample of A that faces down, near an upward-facing sample
   of B (``n_b.z >= up_cos``: the contact normal from B to A opposes
   gravity) with the two surfaces facing each other, is a *support* sample;
   its signed gap along B's normal may range from
   ``-penetration_scale * tol`` (penetration, counted only where the sample
   is inside B by winding number) to ``hide_scale * tol`` (the first tier
   stops at ``tol``). Samples near a near-vertical surface of B, with A's
   centre of mass in front of it, are *side* samples. The ground is a plane
   with normal +z and gap ``z - ground``.
4. **Raw graph.** B is a raw candidate for A with ``min_contact_points``
   first-tier support samples. Where two objects' upward surfaces each meet
   the other's downward surface (deep interpenetration), only the direction
   covering the larger fraction of the carried object's downward surface
   stays (:func:`drop_mutual`).
5. **Hiding** (:func:`resolve_hidden`). A sample of A near several
   supporters belongs to the one on top: if C supports B (transitively) in
   the raw graph, B's upward surface below a sample hides C there (an object
   always hides the ground: a box in a tray does not touch the floor);
   otherwise the higher surface wins.
6. **Supporters from below** (:func:`choose_supporters`). Supporters with
   enough first-tier samples, or with a large share (``tier2_fraction``) of
   A's samples up to ``hide_scale * tol``, whose contact's lowest sample is
   below A's centre of mass (within ``tol``); one that only grazes A
   (median gap clearly larger than another's, or few samples) is pruned
   when the others already hold A (:func:`prune_redundant`). Several
   supporters are allowed: a plank bridging two boxes keeps both.
7. **Statics.** A is held when its centre of mass (xy) lies within
   ``max(com_margin_abs, com_margin_rel * size)`` of the 2D convex hull of
   its support samples. If not, the other supporters up to
   ``hide_scale * tol`` are added, nearest first, until it is, then objects
   A passes into. If it still is not, side contacts above the support that
   push back against the tipping direction become ``leans_on`` edges (a
   plank leaning on a wall keeps the ground and the wall); so do the scene's
   wall planes (``Scene.structure``) that samples above the support touch
   (:func:`wall_leaning`). Side contacts of a held object are ignored (boxes
   touching side by side). An object held only within the tolerance is
   still leaning when it tips on the samples that touch (within
   ``lean_band`` of the lowest gap) and would turn at least
   ``lean_fall_deg`` to lie down (:func:`phiscene.topology.leaning.tipping`:
   a plank at 35 deg on the floor, not a box tilted by a rotation error).
   A leaning object with no side contact or wall within the tolerance leans
   on what it falls onto when turned about its resting edge
   (:func:`phiscene.topology.leaning.tipping_partner`; confidence
   ``0.5 * (1 - turned / fall)``): a depth error left it centimetres away.
   With two or more supporters from below, an object that would tip that far
   on its lowest supporter alone leans on the others
   (:func:`phiscene.topology.leaning.leaned_on`: a book with one end on the
   floor and its side on a box's edge; a bridged plank lies level on each).
8. **Fallback.** An object without any support sample gets one edge of
   confidence ``fallback_confidence``, as the paper's MLLM prompt does for
   undetermined support: from the object whose upward surface it passes
   through (too deep to count, or out the other side), else from the first
   upward surface straight below it (an object's, or the ground). An object
   on that last fallback that, lowered onto that surface, would tip and turn
   at least ``lean_fall_deg`` to lie down also leans on what it tips onto
   (:func:`phiscene.topology.leaning.floating_tipping`): a book standing 40
   deg off vertical that a depth error left 10 cm above the floor and away
   from the wall it leans on.
9. **Floor furniture** (:mod:`phiscene.topology.floor`): a chair, table, bed or cabinet (the description's
   head noun) whose bottom is within ``floor_reach`` of the ground stands on the ground, not on the higher
   objects a depth error slid it over (a table over two chairs' seats).
10. **Sunk floor objects** (:func:`sunk_floor_objects`): an object read as standing on the ground alone, its
    lowest point more than ``sink_lift`` below it (a bowl or a plate a depth error put 10 cm under the floor), is
    raised onto the ground, as grounding will raise it, and the objects read as standing on the ground alone (not
    raised themselves) are read again: the blob at the floor's height inside the sunk bowl is in the bowl. The
    others keep their first reading: their heights carry depth errors of their own.

Relations: ``supports``; ``contains`` when the supporter rises more than
``tol`` above the contact and A's centre is within its xy bounds (a tray, a
crate); ``leans_on`` for side contacts. Confidence:
``alignment * (1 - 0.5 * min(|median gap| / tol, 1))``, alignment being the
mean ``n_b.z`` of the support samples or the mean horizontal part
``sqrt(1 - n_b.z^2)`` of the side samples; ``fallback_confidence`` for
fallback edges and edges to objects A merely passes into.

Measured on the embedded benchmark's degraded contact scenes: see the
helper report; on a 10-object box scene inference takes about 0.2 s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phiscene.topology.attached import object_text
from phiscene.topology.contacts import (
    Body,
    Contact,
    aabbs_near,
    ground_contact,
    hull_offset,
    object_seed,
    pair_contacts,
    prepare_bodies,
    prepare_body,
)
from phiscene.topology.floor import floor_standing
from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph
from phiscene.topology.leaning import floating_tipping, leaned_on, tipping, tipping_partner
from phiscene.topology.order import break_cycles, finalize
from phiscene.topology.params import BackendParams
from phiscene.topology.words import says_against_wall


@dataclass(frozen=True)
class GeometricParams(BackendParams):
    """Parameters of the ``geometric`` backend (see the module docstring for their roles).

    Attributes
    ----------
    sample_spacing
        Target distance between surface samples (m).
    min_samples, max_samples
        Clamp on the number of surface samples per object.
    gap_abs, gap_rel, gap_max
        Contact tolerance ``tol = clip(gap_rel * size, gap_abs, gap_max)`` (m), ``size`` the
        longest OBB side of the smaller object of the pair (of A for the ground).
    penetration_scale
        Penetrations up to ``penetration_scale * tol`` still count as contact.
    hide_scale
        Second tier: support contacts up to ``hide_scale * tol`` away are used when the first
        tier does not hold A, and an upward surface that close below a sample of A hides the
        supporters under it (a box in a tray does not touch the ground).
    up_cos
        A supporter surface with normal z at least this faces up (default: within 35 deg of +z).
    face_cos
        Two surfaces face each other when ``n_a . n_b <= -face_cos``.
    down_cos
        A supported surface faces down when ``n_a.z <= -down_cos`` (default: within 60 deg of -z;
        the broad face of a book leaning at 20 deg from vertical does not rest on the ground).
    neighbours
        Samples of the supporter examined per sample of A.
    min_contact_points
        Fewest contact samples for a supporter.
    tier2_fraction
        A supporter with no first-tier contact is still kept when it has at least this fraction
        of A's support samples up to ``hide_scale * tol`` (one end of a bridged plank 3 cm above
        its box while the other rests on its box).
    redundant_gap, redundant_fraction
        A supporter whose median gap exceeds another's by ``redundant_gap * tol``, or that
        has less than ``redundant_fraction`` of the support samples, is dropped when the
        others hold the centre of mass (see :func:`prune_redundant`).
    com_margin_abs, com_margin_rel
        The centre of mass may lie this far (m; or this fraction of the object's size)
        outside the support hull and still count as statically supported.
    fallback_confidence
        Confidence of fallback edges (no contact at all) and of edges to objects that A
        merely passes into.
    lean_band
        The resting test (:func:`phiscene.topology.leaning.tipping`): samples within this (m) of their
        supporter's lowest gap touch it.
    lean_fall_deg
        An object that tips on its touching samples and turns at least this far (deg) before lying down is
        leaning, not tilted by a rotation error (measured on the seed-0 clutter inputs: 17 of the 23 leaning
        objects turn 18 to 64 deg, the others at most 11 or rest, found by the other tests or missed; objects that
        do not lean at most 14).
    lean_step_deg, lean_hit
        The partner sweep (:func:`phiscene.topology.leaning.tipping_partner`): angle step (deg) and the distance
        (m) at which a turned sample touches another object.
    floor_reach
        Floor furniture (a chair, a table, a bed: :mod:`phiscene.topology.floor`) whose bottom is within this
        distance (m) of the ground stands on the ground, not on higher objects it overlaps (0 = no prior).
    sink_lift
        An object the first pass stands on the ground alone, its lowest point more than this (m) below the
        ground, is raised onto it and the graph inferred again (:func:`sunk_floor_objects`; 0 = one pass).
    seed
        Seed of the surface sampling.
    """

    sample_spacing: float = 0.01
    min_samples: int = 400
    max_samples: int = 6000
    gap_abs: float = 0.02
    gap_rel: float = 0.10
    gap_max: float = 0.05
    penetration_scale: float = 2.0
    hide_scale: float = 2.0
    up_cos: float = math.cos(math.radians(35.0))
    face_cos: float = 0.3
    down_cos: float = 0.5
    neighbours: int = 8
    min_contact_points: int = 4
    redundant_gap: float = 1.0
    tier2_fraction: float = 0.25
    redundant_fraction: float = 0.1
    com_margin_abs: float = 0.01
    com_margin_rel: float = 0.05
    fallback_confidence: float = 0.2
    lean_band: float = 0.01
    lean_fall_deg: float = 20.0
    lean_step_deg: float = 2.0
    lean_hit: float = 0.015
    floor_reach: float = 0.15
    sink_lift: float = 0.02
    seed: int = 0


def contact_tolerance(size: float, params: GeometricParams) -> float:
    """``clip(gap_rel * size, gap_abs, gap_max)`` in metres."""
    return float(np.clip(params.gap_rel * size, params.gap_abs, params.gap_max))


@dataclass
class ObjectContacts:
    """Every near contact of one object A, before deciding its supporters.

    Attributes
    ----------
    near
        Supporter name (``ground`` included) -> samples of A within ``hide_scale * tol`` of
        its upward surface.
    side
        Object name -> samples of A within ``hide_scale * tol`` of its near-vertical surface.
    tol
        Supporter name -> contact tolerance of the pair (m).
    cover
        Supporter name -> samples of A its upward surface covers (see :func:`pair_contacts`).
    """

    near: dict[str, Contact]
    side: dict[str, Contact]
    tol: dict[str, float]
    cover: dict[str, np.ndarray]

    def support(self, name: str) -> Contact:
        """First-tier support samples of one supporter (gap at most ``tol``)."""
        return self.near[name].within(self.tol[name])

    def candidates(self, min_points: int) -> list[str]:
        """Supporters with at least ``min_points`` first-tier support samples."""
        return [k for k in self.near if len(self.support(k)) >= min_points]


def object_contacts(a: Body, bodies: dict[str, Body], ground_height: float,
                    params: GeometricParams) -> ObjectContacts:
    """Near contacts of ``a`` with the ground and every object whose AABB comes near."""
    tol = contact_tolerance(a.size, params)
    gc = ground_contact(a, ground_height, params.hide_scale * tol, params.down_cos)
    out = ObjectContacts({GROUND: gc}, {}, {GROUND: tol}, {GROUND: gc.index})
    for name in sorted(bodies):
        b = bodies[name]
        if name == a.id:
            continue
        tol = contact_tolerance(min(a.size, b.size), params)
        far, deep = params.hide_scale * tol, params.penetration_scale * tol
        if not aabbs_near(a.bounds, b.bounds, max(far, deep) + b.spacing):
            continue
        out.tol[name] = tol
        out.near[name], out.side[name], out.cover[name] = pair_contacts(a, b, far, deep, far, params)
    return out


def drop_mutual(contacts: dict[str, ObjectContacts], bodies: dict[str, Body], params: GeometricParams) -> None:
    """Where two objects each cover the other's downward surface, keep one direction only.

    Deep interpenetration (a mug sunk through the floor of a crate, a plate
    sunk into a book) can make each object's upward surface meet the other's
    downward surface. For objects A and B, the evidence that B carries A is
    the fraction of A's downward-facing samples that B's upward surface covers
    (a mug's whole bottom is covered by the crate floor; only a small part of
    the crate's bottom by the mug's inside). The direction with the smaller
    evidence is removed (equal evidence: the object with the lower centre of
    mass supports). Only pairs where at least one direction is a first-tier
    candidate are examined. Changes ``contacts`` in place.
    """
    m = params.min_contact_points
    down = {k: max(int(np.sum(b.normals[:, 2] <= -params.down_cos)), 1) for k, b in bodies.items()}
    pairs = set()
    for a, ca in contacts.items():
        for b in ca.candidates(m):
            if b != GROUND and len(contacts[b].cover.get(a, ())) >= m and len(ca.cover[b]) >= m:
                pairs.add(tuple(sorted((a, b))))
    for a, b in sorted(pairs):
        b_carries_a = len(contacts[a].cover[b]) / down[a]
        a_carries_b = len(contacts[b].cover[a]) / down[b]
        if b_carries_a != a_carries_b:
            upper, lower = (a, b) if b_carries_a > a_carries_b else (b, a)
        else:
            upper, lower = (a, b) if (bodies[a].com[2], a) > (bodies[b].com[2], b) else (b, a)
        contacts[lower].near[upper] = Contact.empty()
        contacts[lower].cover[upper] = np.zeros(0, int)


def raw_ancestors(contacts: dict[str, ObjectContacts], params: GeometricParams) -> dict[str, set[str]]:
    """Node -> its ancestors in the graph of every first-tier supporter candidate (before hiding).

    The ground counts as an ancestor of every object, so an object's surface always hides the ground.
    """
    import networkx as nx

    g = nx.DiGraph()
    g.add_nodes_from([GROUND, *contacts])
    for a, c in contacts.items():
        g.add_edges_from((s, a) for s in c.candidates(params.min_contact_points))
    return {n: nx.ancestors(g, n) | ({GROUND} if n != GROUND else set()) for n in g.nodes}


def resolve_hidden(sets: dict[str, Contact], covers: dict[str, np.ndarray],
                   ancestors: dict[str, set[str]]) -> dict[str, Contact]:
    """Give each support sample claimed by several supporters to the one on top.

    For two supporters B and C of A: if C (transitively) supports B in the raw
    contact graph and not the other way round, B lies between A and C, and C
    loses every sample of A that B covers (B's upward surface within
    ``hide_scale * tol`` below it); the ground supports everything, so an
    object always hides the ground. Otherwise, samples claimed by both go to
    the higher surface. Decisions are made pairwise on the original sets, so
    they do not depend on the supporters' order.

    Parameters
    ----------
    sets
        Supporter -> its claimed samples of A.
    covers
        Supporter -> the samples of A its upward surface covers.
    ancestors
        Node -> the nodes that support it directly or indirectly in the raw graph.
    """
    lose: dict[str, list[np.ndarray]] = {k: [] for k in sets}
    names = sorted(sets)
    for i, b in enumerate(names):
        for c in names[i + 1:]:
            b_over_c = c in ancestors.get(b, set()) and b not in ancestors.get(c, set())
            c_over_b = b in ancestors.get(c, set()) and c not in ancestors.get(b, set())
            if b_over_c:
                lose[c].append(covers[b])
            elif c_over_b:
                lose[b].append(covers[c])
            else:
                shared, ib, ic = np.intersect1d(sets[b].index, sets[c].index, return_indices=True)
                hb, hc = sets[b].height[ib], sets[c].height[ic]
                lose[b].append(shared[hb < hc])
                lose[c].append(shared[hc <= hb])
    return {k: v.without(np.concatenate(lose[k])) if lose[k] else v for k, v in sets.items()}


def holds_com(a: Body, contacts, margin: float) -> bool:
    """Whether support samples (an iterable of :class:`Contact`) hold ``a``'s centre of mass.

    True when the centre of mass (xy) is within ``margin`` of the 2D convex hull of the samples.
    """
    idx = [c.index for c in contacts]
    if not idx:
        return False
    return hull_offset(a.points[np.concatenate(idx), :2], a.com[:2])[0] <= margin


def prune_redundant(a: Body, kept: dict[str, Contact], tols: dict[str, float], margin: float,
                    params: GeometricParams) -> tuple[dict[str, Contact], list[str]]:
    """Drop supporters that only graze A while the others already hold it.

    A supporter is *marginal* when its median gap (penetration counting as 0)
    exceeds the smallest one of the others by more than ``redundant_gap * tol`` (A sits clearly
    lower on the others: a book on a plate whose corner overhangs the table),
    or when it holds fewer than ``redundant_fraction`` of the support samples.
    Marginal supporters are dropped one at a time, the largest gap first, as
    long as the remaining ones hold A's centre of mass.

    Returns
    -------
    kept
        The remaining supporters.
    pruned
        Names of the dropped ones, in order.
    """
    kept = dict(kept)
    pruned: list[str] = []
    while len(kept) > 1:
        gaps = {k: max(float(np.median(c.gap)), 0.0) for k, c in kept.items()}
        total = sum(len(c) for c in kept.values())
        for name in sorted(kept, key=lambda k: (-gaps[k], k)):
            best_other = min(g for k, g in gaps.items() if k != name)
            marginal = (gaps[name] - best_other > params.redundant_gap * tols[name]
                        or len(kept[name]) < params.redundant_fraction * total)
            if marginal and holds_com(a, [c for k, c in kept.items() if k != name], margin):
                del kept[name]
                pruned.append(name)
                break
        else:
            break
    return kept, pruned


def _add_until_held(a: Body, kept: dict[str, Contact], extra: dict[str, Contact], margin: float,
                    allow_partial: bool) -> dict[str, Contact]:
    """Add ``extra`` supporters in their order until A is held; keep them only if it then is.

    With ``allow_partial`` (nothing kept so far), all of them are kept even if A is not held.
    """
    trial = dict(kept)
    for name, c in extra.items():
        trial[name] = c
        if holds_com(a, trial.values(), margin):
            return trial
    return trial if allow_partial else kept


def intersecting(a: Body, bodies: dict[str, Body], names, min_points: int) -> dict[str, Contact]:
    """Objects that ``a`` passes into: name -> samples of ``a`` inside it (at least ``min_points``)."""
    out = {}
    for name in names:
        b = bodies[name]
        near = np.flatnonzero(np.all((a.points >= b.bounds[0]) & (a.points <= b.bounds[1]), axis=1))
        idx = near[b.contains(a.points[near])] if len(near) else near
        if len(idx) >= min_points:
            z = a.points[idx, 2]
            out[name] = Contact(idx, np.zeros(len(idx)), np.tile([0.0, 0.0, 1.0], (len(idx), 1)), z)
    return out


def choose_supporters(a: Body, contacts: ObjectContacts, ancestors: dict[str, set[str]], bodies: dict[str, Body],
                      params: GeometricParams) -> tuple[dict[str, Contact], dict]:
    """The supporters of one object from below, and diagnostics.

    Candidates are supporters with at least ``min_contact_points`` support
    samples up to ``hide_scale * tol`` (hidden ones removed) whose contact's
    lowest sample is below A's centre of mass, give or take ``tol`` (a plank
    leaning on a box edge touches it just above its centre). Kept at once are
    those with ``min_contact_points`` samples within ``tol`` (first tier) or
    with ``tier2_fraction`` of all candidate samples; redundant ones are then
    pruned. If the kept ones do not hold A's centre of mass, the other
    candidates are added, nearest first, until they do (all of them when
    nothing was kept; none when even all of them do not). If A is still not
    held, objects it passes into (a plank end sunk into a box that floated
    up) are added the same way, most samples inside first, unless A supports
    them.
    """
    covers = contacts.cover
    margin = max(params.com_margin_abs, params.com_margin_rel * a.size)

    def usable(sets: dict[str, Contact]) -> dict[str, Contact]:
        return {k: c for k, c in resolve_hidden(sets, covers, ancestors).items()
                if len(c) >= params.min_contact_points
                and a.points[c.index, 2].min() < a.com[2] + contacts.tol[k]}

    candidates = usable(contacts.near)
    total = sum(len(c) for c in candidates.values())
    kept = {k: c for k, c in candidates.items()
            if len(c.within(contacts.tol[k])) >= params.min_contact_points
            or len(c) >= params.tier2_fraction * total}
    kept, pruned = prune_redundant(a, kept, contacts.tol, margin, params)
    info = {"tolerance": contacts.tol[GROUND], "pruned": pruned, "second_tier": [], "intersecting": []}
    if not holds_com(a, kept.values(), margin):
        order = sorted((k for k in candidates if k not in kept),
                       key=lambda k: (float(np.median(candidates[k].gap)), k))
        before = set(kept)
        kept = _add_until_held(a, kept, {k: candidates[k] for k in order}, margin, allow_partial=not kept)
        info["second_tier"] = [k for k in kept if k not in before]
    if kept and not holds_com(a, kept.values(), margin):
        names = [k for k in sorted(contacts.tol) if k != GROUND and k not in kept and a.id not in ancestors.get(k, ())]
        inside = intersecting(a, bodies, names, params.min_contact_points)
        order = sorted(inside, key=lambda k: (-len(inside[k]), k))
        before = set(kept)
        kept = _add_until_held(a, kept, {k: inside[k] for k in order}, margin, allow_partial=False)
        info["intersecting"] = [k for k in kept if k not in before]
    return kept, info


def _object_below(a: Body, bodies: dict[str, Body], tol: float, ground_height: float,
                  exclude: frozenset[str] = frozenset()) -> tuple[str, float]:
    """Fallback parent of ``a``: the first upward surface below it, looking straight down, and its height.

    Among upward-facing samples of other objects (not in ``exclude``) inside
    ``a``'s xy bounds and at most ``tol`` above ``a``'s lowest point, the
    highest one names the parent (the third highest sample of each object is
    compared, so a stray sample does not decide; ties by name); the ground when
    there is none (an object below wins even if it sank below the ground plane).

    Returns
    -------
    ``(name, height)``: the parent and the z (m) of its surface there (the compared sample; ``ground_height``
    for the ground).
    """
    best, best_z = GROUND, -math.inf
    lo, hi = a.bounds
    for name in sorted(bodies):
        b = bodies[name]
        if name == a.id or name in exclude or not aabbs_near(a.bounds[:, :2], b.bounds[:, :2], 0.0):
            continue
        q = b.points[b.up.index]
        q = q[np.all((q[:, :2] >= lo[:2]) & (q[:, :2] <= hi[:2]), axis=1) & (q[:, 2] <= lo[2] + tol)]
        if len(q) >= 3:
            z = float(np.sort(q[:, 2])[-3])
            if z > best_z:
                best, best_z = name, z
    return best, (ground_height if best == GROUND else best_z)


def _support_relation(a: Body, c: Contact, b: Body | None, tol: float) -> str:
    """``contains`` when supporter ``b`` rises above the contact around A's centre, else ``supports``."""
    if b is None:
        return "supports"
    within = bool(np.all(a.com[:2] >= b.bounds[0, :2]) and np.all(a.com[:2] <= b.bounds[1, :2]))
    return "contains" if within and b.bounds[1, 2] > float(np.median(c.height)) + tol else "supports"


def _confidence(gap: np.ndarray, alignment: float, tol: float) -> float:
    g = abs(float(np.median(gap))) if len(gap) else tol
    return float(np.clip(alignment, 0.0, 1.0) * (1.0 - 0.5 * min(g / tol, 1.0)))


def supporters_of(a: Body, contacts: ObjectContacts, ancestors: dict[str, set[str]], bodies: dict[str, Body],
                  params: GeometricParams, planes, ground_height: float,
                  exclude: frozenset[str] = frozenset()) -> tuple[list[SupportEdge], dict]:
    """The support edges into one object (supporters from below, leaning on objects or on ``planes``, fallback).

    An object that touches nothing falls back on the first upward surface below it (not one of ``exclude``: the
    objects it carries, :func:`_supporters`); when, lowered onto it, it
    would tip and turn at least ``lean_fall_deg`` (a book or a plank standing far off any resting pose, moved
    away from what holds it by a depth error), it also leans on what it tips onto
    (:func:`phiscene.topology.leaning.floating_tipping`, :func:`phiscene.topology.leaning.tipping_partner`).

    ``planes`` are the scene's walls and ceiling (:class:`phiscene.scene.Plane`), ``ground_height`` the ground's z (m).

    Returns
    -------
    edges
        Edges ``supporter -> a.id``.
    info
        Diagnostics: tolerance, pruned and second-tier supporters, whether the support from
        below holds the centre of mass and how far outside its hull the centre lies.
    """
    kept, info = choose_supporters(a, contacts, ancestors, bodies, params)
    tols = contacts.tol
    margin = max(params.com_margin_abs, params.com_margin_rel * a.size)
    # an object A merely passes into is no evidence of leaning (a chair sunk into the box beside it)
    leaned = [k for k in leaned_on(a, kept, params.lean_band, a.spacing, margin, params.lean_fall_deg)
              if k not in info["intersecting"]]
    edges = []
    for name, c in kept.items():
        relation = "leans_on" if name in leaned else _support_relation(a, c, bodies.get(name), tols[name])
        if name in info["intersecting"]:
            conf, why = params.fallback_confidence, f"not held otherwise; {len(c)} samples inside it"
        else:
            conf = _confidence(c.gap, float(np.mean(c.normal[:, 2])), tols[name])
            why = f"{len(c)} contact samples below, median gap {100 * np.median(c.gap):.1f} cm"
        edges.append(SupportEdge(name, a.id, relation, conf, why))
    if not kept:
        covers = {k: len(v) for k, v in contacts.cover.items()
                  if k != GROUND and k not in exclude and len(v) >= params.min_contact_points}
        if covers:  # A passes through an object's upward surface (too deep to count as contact)
            parent = max(sorted(covers), key=lambda k: covers[k])
            why = "no contact within tolerance: the object whose upward surface A passes through"
        else:
            parent, height = _object_below(a, bodies, contacts.tol[GROUND], ground_height, exclude)
            why = "no contact within tolerance: the first upward surface straight below"
        edges.append(SupportEdge(parent, a.id, "supports", params.fallback_confidence, why))
        info.update(stable=False, fallback=True)
        if not covers:
            tip, lower = floating_tipping(a, height, params.lean_band, a.spacing)
            if tip.leans(margin, params.lean_fall_deg):
                edges += _tip_partner(a, tip, [parent], ancestors, bodies, params, planes, lower, info,
                                      f"lowered {100 * lower:.0f} cm onto {parent}, ")
        return edges, info

    idx = np.concatenate([c.index for c in kept.values()])
    dist, direction = hull_offset(a.points[idx, :2], a.com[:2])
    tip = tipping(a, list(kept.values()), params.lean_band, a.spacing)
    leans = tip.leans(margin, params.lean_fall_deg)
    if dist <= margin and leans:  # held within the tolerance, yet it stands far off its resting pose
        dist, direction = tip.distance, tip.direction
    info.update(stable=bool(dist <= margin), com_outside=round(max(dist, 0.0), 6), fallback=False,
                fall=round(tip.fall, 3))
    if dist <= margin:
        return edges, info
    support_z = float(np.mean(a.points[idx, 2]))
    leaning = {}
    for name in sorted(contacts.side):
        c = contacts.side[name]
        if len(c) < params.min_contact_points or name in kept:
            continue
        push = float(np.mean(c.normal[:, :2], axis=0) @ direction)
        if push < 0 and float(np.mean(a.points[c.index, 2])) > support_z:
            leaning[name] = c
    # side contacts within tol if there are any, else the second tier (up to hide_scale * tol)
    close = {k: c.within(tols[k]) for k, c in leaning.items()}
    close = {k: c for k, c in close.items() if len(c) >= params.min_contact_points}
    for name, c in (close or leaning).items():
        align = float(np.mean(np.sqrt(np.clip(1.0 - c.normal[:, 2] ** 2, 0.0, 1.0))))
        edges.append(SupportEdge(name, a.id, "leans_on", _confidence(c.gap, align, tols[name]),
                                 f"{len(c)} side contact samples hold the centre of mass, "
                                 f"{100 * dist:.1f} cm outside the support below"))
    edges += wall_leaning(a, planes, direction, support_z, tols[GROUND], dist, params)
    if leans and not any(e.relation == "leans_on" for e in edges):
        edges += _tip_partner(a, tip, list(kept), ancestors, bodies, params, planes, 0.0, info, "")
    return edges, info


def described_leaning(a: Body, planes, tol: float, params: GeometricParams) -> list[SupportEdge]:
    """``leans_on`` edges from the walls an object whose description says it leans against a wall touches.

    The geometry alone may read such an object as standing (a mattress whose foot a depth error sank 12 cm into
    the floor has a wide base); its description and a wall plane touching its upper part (``min_contact_points``
    of its samples above its lowest quarter within ``[-penetration_scale * tol, tol]`` of the plane) say it leans.
    """
    lo, hi = float(a.bounds[0, 2]), float(a.bounds[1, 2])
    edges = []
    for plane in planes:
        gaps = _against(a, plane, lo + 0.25 * (hi - lo), tol, params) if plane.kind == "wall" else ()
        if len(gaps):
            edges.append(SupportEdge(plane.id, a.id, "leans_on", _confidence(gaps, 1.0, tol),
                                     f"its description says it leans against a wall; {len(gaps)} samples "
                                     f"against {plane.id}"))
    return edges


def _against(a: Body, plane, above: float, tol: float, params: GeometricParams) -> np.ndarray:
    """The gaps (m) to ``plane`` of A's samples higher than ``above`` (z, m) that lie within
    ``[-penetration_scale * tol, tol]`` of it; empty when there are fewer than ``min_contact_points``."""
    gap = plane.signed_distance(a.points)
    near = (gap <= tol) & (gap >= -params.penetration_scale * tol) & (a.points[:, 2] > above)
    return gap[near] if int(near.sum()) >= params.min_contact_points else gap[:0]


def _tip_partner(a: Body, tip, supporters: list[str], ancestors: dict[str, set[str]], bodies: dict[str, Body],
                 params: GeometricParams, planes, lower: float, info: dict, why: str) -> list[SupportEdge]:
    """The ``leans_on`` edge to what ``a`` tips onto about the edge of ``tip`` (none when it lies down first),
    after lowering it by ``lower`` (m); ``info["tips_onto"]`` names the partner. Its ``supporters`` and its
    descendants are not candidates."""
    names = [k for k in bodies if k != a.id and k not in supporters and a.id not in ancestors.get(k, ())]
    found = tipping_partner(a, tip, bodies, names, planes, params.lean_step_deg, params.lean_hit,
                            tip.pivot[2] - lower + params.lean_band, lower)
    if found is None:
        return []
    name, angle = found
    info["tips_onto"] = name
    return [SupportEdge(name, a.id, "leans_on", 0.5 * (1.0 - angle / tip.fall),
                        f"{why}tips {angle:.0f} deg about its resting edge onto {name} "
                        f"(it would turn {tip.fall:.0f} deg to lie down)")]


def wall_leaning(a: Body, planes, direction: np.ndarray, support_z: float, tol: float, dist: float,
                 params: GeometricParams) -> list[SupportEdge]:
    """``leans_on`` edges from the walls (:class:`phiscene.scene.Plane`) holding up an object tipping in ``direction``.

    A wall counts when at least ``min_contact_points`` of A's samples above its support (``z > support_z``)
    lie within ``[-penetration_scale * tol, tol]`` of the plane and the wall's normal pushes back against
    the tipping direction (2,) (a plank leaning on a wall keeps the ground and the wall).
    """
    edges = []
    for plane in planes:
        n = np.asarray(plane.normal, dtype=float)
        gaps = _against(a, plane, support_z, tol, params) if float(n[:2] @ direction) < 0 else ()
        if not len(gaps):
            continue
        conf = _confidence(gaps, float(np.linalg.norm(n[:2])), tol)
        edges.append(SupportEdge(plane.id, a.id, "leans_on", conf,
                                 f"{len(gaps)} samples against {plane.id} hold the centre of mass, "
                                 f"{100 * dist:.1f} cm outside the support below"))
    return edges


def infer(scene, params: GeometricParams = GeometricParams()) -> SupportGraph:
    """Geometric support graph of ``scene`` with its placement order (see the module docstring).

    Where a floor object is sunk (:func:`sunk_floor_objects`), the support of the objects read as standing on the
    ground beside or inside it is read again with it raised onto the ground, as grounding will raise it; the
    graph's ``meta["raised"]`` gives the lifts (id -> m) and ``meta["reread"]`` the objects whose supporters
    changed.
    """
    bodies = prepare_bodies(scene, params)
    edges, diagnostics, floor = _supporters(scene, bodies, params)
    parents = _parents(edges)
    lifts = sunk_floor_objects(parents, bodies, scene.ground_height, params.sink_lift)
    meta = {"params": params.to_dict(), "objects": diagnostics, "floor_standing": floor}
    if lifts:
        # only the objects read as standing on the ground take the second reading (their neighbours' heights
        # carry depth errors of their own: an object already on the sunk one keeps its supporter); none, no reading
        on_ground = {oid for oid, ps in parents.items() if ps == ON_GROUND_ALONE and oid not in lifts}
        reread: list[str] = []
        if on_ground:
            raised = dict(bodies)
            for i, o in enumerate(scene.objects):
                if o.id in lifts:
                    pose = np.array(o.pose, dtype=float)
                    pose[2, 3] += lifts[o.id]
                    raised[o.id] = prepare_body(o.id, o.mesh(), pose, params, seed=object_seed(params.seed, i))
            again, diag_again, _ = _supporters(scene, raised, params)
            new = _parents(again)
            reread = sorted(oid for oid in on_ground if new.get(oid, set()) != ON_GROUND_ALONE)
            edges = [e for e in edges if e.target not in reread] + [e for e in again if e.target in reread]
            diagnostics.update({oid: diag_again[oid] for oid in reread})
        meta.update(raised={k: round(float(v), 6) for k, v in sorted(lifts.items())}, reread=reread)
    walls = [p.id for p in scene.structure if any(e.source == p.id for e in edges)]
    graph = SupportGraph(objects=[GROUND] + scene.ids, edges=edges, backend="geometric", meta=meta, structure=walls)
    return finalize(graph, areas={k: b.footprint for k, b in bodies.items()})


#: The (supporter, relation) pairs of an object standing on the ground alone (:func:`sunk_floor_objects`).
ON_GROUND_ALONE = frozenset({(GROUND, "supports")})


def _parents(edges: list[SupportEdge]) -> dict[str, set[tuple[str, str]]]:
    """Object id -> its (supporter, relation) pairs."""
    out: dict[str, set[tuple[str, str]]] = {}
    for e in edges:
        out.setdefault(e.target, set()).add((e.source, e.relation))
    return out


def sunk_floor_objects(parents: dict[str, set[tuple[str, str]]], bodies: dict[str, Body], ground_height: float,
                       sink_lift: float) -> dict[str, float]:
    """Objects standing on the ground alone whose lowest point lies more than ``sink_lift`` below it.

    A depth error moves an object along the camera's ray, which looks down: a plate, a bowl or a shelf ends
    centimetres to decimetres under the floor (down to 19 cm on the ``clutter`` suite's inputs), while what
    stands on it or in it, placed with errors of its own, may end at the floor's height beside or inside it: read
    as is, it stands on the ground. Grounding raises the sunk object out of the floor before anything is put on
    it.

    Parameters
    ----------
    parents
        Object id -> its (supporter, relation) pairs as read from the scene as it is.

    Returns
    -------
    Object id -> lift (m): the depth of its lowest point below the ground. Empty when ``sink_lift`` is 0.
    """
    if sink_lift <= 0:
        return {}
    lifts = {}
    for oid, body in bodies.items():
        depth = ground_height - float(body.bounds[0, 2])
        if parents.get(oid) == ON_GROUND_ALONE and depth > sink_lift:
            lifts[oid] = depth
    return lifts


def _supporters(scene, bodies: dict[str, Body], params: GeometricParams) -> tuple[list[SupportEdge], dict, list]:
    """The support edges of every object of ``scene`` read from prepared ``bodies`` (before cycles are broken),
    the per-object diagnostics and the floor-standing objects.

    An object that touches nothing takes a fallback supporter (:func:`supporters_of`), an edge of low confidence.
    When that edge closes a cycle and cycle breaking would drop it (an object sunk into a board from above reaches
    below the board's lowest point: the board's fallback names it), the object would be left on the ground alone
    (a board bridging two boxes, dropped to the floor with what it carries): such an object's fallback is taken
    again with the objects it carries through the kept edges passed over (``passed_over`` in its diagnostics).
    A fallback edge that survives cycle breaking is kept, even on a cycle: another edge of the cycle was weaker.
    """
    import networkx as nx

    contacts = {o.id: object_contacts(bodies[o.id], bodies, scene.ground_height, params) for o in scene.objects}
    drop_mutual(contacts, bodies, params)
    ancestors = raw_ancestors(contacts, params)
    found: dict[str, list[SupportEdge]] = {}
    diagnostics = {}
    bounds = {k: b.bounds for k, b in bodies.items()}

    def standing() -> tuple[list[SupportEdge], list[str]]:  # the edges found, in scene order, with the floor prior
        return floor_standing([e for o in scene.objects for e in found[o.id]], scene, bounds, params.floor_reach)

    def add(o, exclude: frozenset[str] = frozenset()) -> None:
        e, info = supporters_of(bodies[o.id], contacts[o.id], ancestors, bodies, params, scene.structure,
                                scene.ground_height, exclude)
        if says_against_wall(object_text(o)) and not any(x.relation == "leans_on" for x in e):
            e += described_leaning(bodies[o.id], scene.structure, contacts[o.id].tol[GROUND], params)
        found[o.id], diagnostics[o.id] = e, info

    for o in scene.objects:
        add(o)
    edges, floor = standing()
    kept, dropped = break_cycles(edges)
    redo = [o for o in scene.objects if diagnostics[o.id].get("fallback") and any(
        e.target == o.id and e.relation == "supports" and e.confidence == params.fallback_confidence for e in dropped)]
    if redo:
        g = nx.DiGraph([e.pair for e in kept])
        for o in redo:
            carried = frozenset(nx.descendants(g, o.id)) if o.id in g else frozenset()
            add(o, carried)
            diagnostics[o.id]["passed_over"] = sorted(carried)
        edges, floor = standing()
    return edges, diagnostics, floor
