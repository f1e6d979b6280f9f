"""Objects fixed to a wall or the ceiling: posters, paintings, windows, curtains, clocks, ceiling fans.

A gravity-only pipeline drops them to the floor. Every topology backend runs :func:`mark_attached` on its graph:
an object it decides is attached loses its support edges and gets one ``ground -> object`` edge of relation
``attached`` (the ground node stands for the fixed world: walls and ceiling included). The grounding keeps such
objects static where they are; metrics treat them as colliders and leave them out of drift averages.

The room's own meshes are attached wherever they are (reason ``structure``): a reconstruction that meshes its
floor, a wall or the ceiling as objects ("white wall", "wooden floor": the description's head noun,
:func:`~phiscene.topology.words.names_structure`). Dropped as free objects, a wall mesh falls over across the room
and takes the posters on it. Such a mesh holds what its surface carries from below (a chair on the floor mesh), not
what touches it from the side (a poster on the wall mesh is still attached).

For every other object the decision (:func:`attached_objects`) combines two signals, each of which can only *add*
an attachment when nothing holds the object from below (no other object's surface, and not the ground, within
``support_gap`` under its footprint):

* description: a wall or ceiling object (:data:`WALL_WORDS`, e.g. "poster", "painting", "curtain",
  "whiteboard", "ceiling fan") or an explicit "on the wall" / "hanging" phrase (:data:`MOUNT_PHRASES`);
* partial furniture: floor furniture (a chair, a cabinet: :func:`names_furniture`)
  whose bottom is at least ``min_height`` above the ground and higher above it than the object is tall, or at
  least ``partial_gap`` above it when its description says it is seen only in part ("partially visible",
  "occluded", "cut off": :data:`PARTIAL_WORDS`) (``partial``). Such a mesh is a fragment: the part of a chair
  seen over a table, a cabinet cut off by the frame of the photo. Its unseen lower part stands on the ground and
  holds it where it is. Dropping the fragment would put a chair's back on the floor, where it cannot stand. A whole
  piece of furniture lifted by a depth error rises less than its own height, so it is still grounded;
* geometry: a thin vertical panel (:func:`panel_normal`: the smallest extent of its minimum-volume oriented box
  <= ``thin_ratio`` times the largest, its thin axis within 30 degrees of horizontal, so a poster on a wall at any
  heading counts) whose bottom is at least ``min_height`` above the ground, or anything whose top is within
  ``ceiling_gap`` of the highest point of the scene while its bottom is above ``min_height`` (a ceiling
  fixture), when the scene is a room (its height is at least ``room_height``).

Objects resting on something stay free whatever their description says (a painting standing on a dresser); a
wall object other than a fixture holds nothing from below (posters overlapping on a wall do not hold each other
up); except
building fixtures (:data:`FIXTURE_WORDS`: windows, curtains, blinds, radiators), which are part of the room wherever
they reach: a window above a radiator, a floor-length curtain or a radiator on its wall brackets a hand's width above
the floor is attached whatever is under it and however low it starts. The
fixture word must name the object itself, in the description's head before its first preposition ("white curtains
on the left window" is a fixture, "plant on the window sill" is not). The word lists and the readers of
descriptions are in :mod:`phiscene.topology.words`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from phiscene.params import Params
from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph
from phiscene.topology.words import (
    names_fixture,
    names_furniture,
    names_structure,
    names_wall_object,
    says_mounted,
    says_partial,
)

#: Relation name of an attachment edge.
ATTACHED = "attached"
#: Reason of an attachment that keeps a fragment of floor furniture in place (:func:`is_fragment`).
PARTIAL = "partial"
#: Reason of an attachment that keeps a mesh of the room itself in place (its floor, a wall, the ceiling:
#: :func:`~phiscene.topology.words.names_structure`).
STRUCTURE = "structure"
#: A panel's thin axis is at most this far (deg) from horizontal (:func:`panel_normal`).
PANEL_TILT_DEG = 30.0


@dataclass(frozen=True)
class AttachedParams(Params):
    """Thresholds of the attachment decision (``config.yaml`` ``topology.attached``).

    Attributes
    ----------
    enabled
        Run the decision (false: no object is ever attached by inference).
    support_gap
        A surface within this distance (m) under an object's footprint holds it from below.
    min_height
        An attached object's bottom is at least this high (m) above the ground.
    thin_ratio
        A panel's smallest extent is at most this fraction of its largest.
    ceiling_gap
        A ceiling fixture's top is within this distance (m) of the scene's highest point.
    room_height
        Ceiling fixtures are only looked for in scenes at least this tall (m).
    samples
        Footprint points per object for the support test.
    wall_distance
        An attached object within this distance (m) of a wall or ceiling plane of the scene is fixed to that
        plane (its ``attached`` edge comes from the plane's id), otherwise to the ground node.
    partial
        Keep fragments of floor furniture where they are (reason ``partial``, module docstring); they are held
        by the ground.
    partial_gap
        Floor furniture whose description says it is seen only in part is a fragment when its bottom is at least
        this high (m) above the ground: beyond the vertical gaps that depth errors leave under whole furniture.
    """

    _label = "attachment parameters"

    enabled: bool = True
    support_gap: float = 0.03
    min_height: float = 0.3
    thin_ratio: float = 0.15
    ceiling_gap: float = 0.15
    room_height: float = 2.0
    samples: int = 64
    wall_distance: float = 0.05
    partial: bool = True
    partial_gap: float = 0.1

    def check(self) -> None:
        """Non-negative distances, a ratio in (0, 1), at least 4 samples (``ValueError``)."""
        if min(self.support_gap, self.min_height, self.ceiling_gap, self.room_height, self.wall_distance,
               self.partial_gap) < 0:
            raise ValueError("attachment distances must be >= 0")
        if not 0 < self.thin_ratio < 1 or self.samples < 4:
            raise ValueError("attachment 'thin_ratio' must be in (0, 1) and 'samples' >= 4")


def panel_normal(mesh, thin_ratio: float) -> np.ndarray | None:
    """The thin axis (3,) of a world-frame mesh that is a thin vertical panel, else ``None``.

    A panel: the smallest extent of the minimum-volume oriented bounding box of its convex hull is at most
    ``thin_ratio`` times the largest, and that thin axis lies within :data:`PANEL_TILT_DEG` of horizontal (a poster
    or a picture on a wall at any heading; a board lying flat is not one).
    """
    from phiscene.meshes import oriented_box

    try:
        box = oriented_box(mesh)
    except Exception:  # degenerate (flat or collinear) point sets: qhull and the OBB search both give up
        return None
    extents = np.asarray(box.primitive.extents, dtype=float)
    k = int(np.argmin(extents))
    if extents[k] > thin_ratio * extents.max():
        return None
    axis = np.asarray(box.primitive.transform, dtype=float)[:3, k]
    axis = axis / np.linalg.norm(axis)
    return axis if abs(axis[2]) <= np.sin(np.radians(PANEL_TILT_DEG)) else None


def _held_from_below(scene, oid: str, world: dict, ground: float, params: AttachedParams,
                     holds_nothing: frozenset = frozenset(), from_below_only: frozenset = frozenset()) -> bool:
    """Whether a surface (another object or the ground) lies within ``support_gap`` under ``oid``'s lowest points.

    Objects in ``holds_nothing`` (wall objects that are not building fixtures) are not looked at; those in
    ``from_below_only`` (the room's own meshes) hold only what their surface carries from below, not what touches
    them from the side (a poster on a wall mesh).
    """
    import trimesh

    mesh = world[oid]
    lo = float(mesh.bounds[0, 2])
    if lo - ground <= params.support_gap:
        return True
    # the object's lowest vertices (within 2 cm of its bottom), subsampled: rays cast downwards from them
    v = mesh.vertices[mesh.vertices[:, 2] <= lo + 0.02]
    if len(v) > params.samples:
        v = v[np.linspace(0, len(v) - 1, params.samples).astype(int)]
    for other, m in world.items():
        if other == oid or other in holds_nothing:
            continue
        (ox0, oy0, oz0), (ox1, oy1, oz1) = m.bounds
        near = (v[:, 0] >= ox0) & (v[:, 0] <= ox1) & (v[:, 1] >= oy0) & (v[:, 1] <= oy1)
        if not near.any() or oz1 < lo - params.support_gap or oz0 > float(mesh.bounds[1, 2]):
            continue
        origins = v[near] + [0.0, 0.0, 1e-3]
        hits = trimesh.ray.ray_triangle.RayMeshIntersector(m).intersects_location(
            origins, np.tile([0.0, 0.0, -1.0], (len(origins), 1)))[0]
        if len(hits) and (lo - hits[:, 2].max()) <= params.support_gap:
            return True
        # touching or interpenetrating from the side/below also holds it (e.g. a shelf board)
        if oz1 >= lo and m.bounds[0, 2] < lo and other not in from_below_only:
            inside = trimesh.proximity.signed_distance(m, v[near][: min(16, int(near.sum()))]) > -params.support_gap
            if inside.any():
                return True
    return False


def object_text(obj) -> str:
    """An object's description, or its id read as words."""
    return obj.description or obj.id.replace("_", " ")


def is_fragment(description: str, bottom: float, top: float, ground: float, params: AttachedParams) -> bool:
    """Whether an object is a fragment of floor furniture (module docstring, reason ``partial``).

    Its description names floor furniture, and its bottom (m) is at least ``params.min_height`` above the
    ``ground`` height and higher above it than the object is tall (``top - bottom``), or at least
    ``params.partial_gap`` above it when the description says it is seen only in part (:func:`says_partial`).
    """
    gap = bottom - ground
    high = gap >= params.min_height and gap > top - bottom
    return (high or (gap >= params.partial_gap and says_partial(description))) and names_furniture(description)


def attached_objects(scene, params: AttachedParams = AttachedParams(), world: dict | None = None) -> dict[str, str]:
    """Objects decided attached (module docstring) -> why (``structure``, ``fixture``, ``description``, ``partial``,
    ``panel`` or ``ceiling``).

    Objects already marked :attr:`~phiscene.scene.SceneObject.attached` in the scene are kept (reason ``given``).
    ``world``: the objects' world meshes by id when the caller has them (else they are built here).
    """
    out = {o.id: "given" for o in scene.objects if o.attached is not None}
    if not params.enabled:
        return out
    world = world if world is not None else {o.id: o.world_mesh() for o in scene.objects}
    ground = float(scene.ground_height)
    top = max(float(m.bounds[1, 2]) for m in world.values())
    room = top - ground >= params.room_height
    # what holds nothing from below: wall objects other than building fixtures (posters overlapping on a wall;
    # a window's sill or the top of a radiator does hold a plant)
    holds_nothing = frozenset(o.id for o in scene.objects
                              if names_wall_object(object_text(o)) and not names_fixture(object_text(o)))
    structure = frozenset(o.id for o in scene.objects if names_structure(object_text(o)))
    for o in scene.objects:
        if o.id in out:
            continue
        if o.id in structure:
            out[o.id] = STRUCTURE
            continue
        if names_fixture(object_text(o)):
            out[o.id] = "fixture"
            continue
        m = world[o.id]
        lo, hi = m.bounds
        fragment = params.partial and is_fragment(object_text(o), lo[2], hi[2], ground, params)
        if lo[2] - ground < params.min_height:
            why = PARTIAL if fragment else None  # low: only a fragment the description calls partial
        else:
            ceiling = room and top - hi[2] <= params.ceiling_gap
            why = "description" if says_mounted(object_text(o)) else PARTIAL if fragment else \
                "panel" if panel_normal(m, params.thin_ratio) is not None else "ceiling" if ceiling else None
        if why is None or _held_from_below(scene, o.id, world, ground, params, holds_nothing, structure):
            continue
        out[o.id] = why
    return out


def holder(scene, oid: str, max_distance: float) -> str:
    """What holds an attached object: its :attr:`~phiscene.scene.SceneObject.attached` value when given, else
    the structure plane (wall or ceiling) nearest to its mesh when within ``max_distance`` (m), else ``ground``."""
    obj = scene.get(oid)
    if obj.attached is not None:
        return obj.attached
    if not scene.structure:
        return GROUND
    v = obj.world_mesh().vertices
    dist = {p.id: float(p.signed_distance(v).min()) for p in scene.structure}
    best = min(dist, key=lambda k: abs(dist[k]))
    return best if abs(dist[best]) <= max_distance else GROUND


def mark_attached(scene, graph: SupportGraph, params: AttachedParams = AttachedParams()) -> SupportGraph:
    """``graph`` with every attached object's incoming edges replaced by one ``attached`` edge from its holder.

    The holder (:func:`holder`) is the wall or ceiling plane it is fixed to when the scene has structure planes
    (the plane becomes a ``structure`` node of the graph), else the ground node, which then stands for the fixed
    world; a fragment of furniture (reason ``partial``) is always held by the ground node, whatever wall is near
    it. Edges out of an attached object (what it carries, e.g. a wall shelf, the laptop on a cabinet fragment) are
    kept. The decision is recorded in ``graph.meta["attached"]`` (id -> reason).
    """
    decided = attached_objects(scene, params)
    if not decided:
        return replace(graph, meta={**graph.meta, "attached": {}})
    edges = [e for e in graph.edges if e.target not in decided]
    # a fragment stands on the ground through its unseen part, whatever wall is near it
    holders = {oid: GROUND if why == PARTIAL else holder(scene, oid, params.wall_distance)
               for oid, why in decided.items()}
    edges += [SupportEdge(holders[oid], oid, ATTACHED, 1.0,
                          "a fragment: its unseen lower part stands on the ground (partial)" if why == PARTIAL
                          else f"fixed to a wall or the ceiling ({why})")
              for oid, why in decided.items()]
    planes = [p.id for p in scene.structure if p.id in holders.values() or p.id in graph.structure]
    return replace(graph, edges=edges, meta={**graph.meta, "attached": decided}, structure=planes)


def attached_ids(graph: SupportGraph, holders: bool = False) -> list[str] | dict[str, str]:
    """Objects with an ``attached`` edge in a support graph, in node order (``holders``: id -> the edge's source)."""
    fixed = {e.target: e.source for e in graph.edges if e.relation == ATTACHED}
    if holders:
        return {o: fixed[o] for o in graph.object_ids if o in fixed}
    return [o for o in graph.object_ids if o in fixed]
