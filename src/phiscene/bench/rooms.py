"""The ``rooms`` suite: 3D-FRONT-like rooms of 3-7 furniture-scale objects on a floor.

Each template furnishes one room type around an anchor piece: a bedroom (bed,
nightstands beside its head, wardrobe), a living room (sofa, coffee table in
front of it, TV stand facing it), a dining room (table with chairs around it)
and an office (desk with a chair in front of it). Further slots get either
extra furniture placed freely in the room or, with probability
``params.top_object_p``, a small object (lamp, vase, book, box, plate, blob)
on the top of a table, desk, nightstand, sideboard, TV stand or low shelf.

Furniture stands on the floor with non-overlapping footprints: every piece's
footprint (the oriented rectangle of its bounding box) keeps at least
``params.clearance`` from every other one (separating-axis test, so the true
distance is at least that). Free pieces get a random yaw and a random position
whose footprint lies inside the square room ``[-region, region]^2``; the room
grows by 10 % after ``scatter_tries`` failed draws, as in the contact suite.
Related pieces (a nightstand beside the bed, a chair facing the table) are put
``clearance`` to ``3 * clearance`` away from their anchor (possibly beyond the
room square), or placed freely when that spot is taken. Every object starts ``gap_min``-``gap_max`` above what
it should rest on; its intended supporters are the ground, or the piece under
a small object.

Suite defaults (:data:`ROOMS_DEFAULTS`, registered in
:data:`phiscene.bench.templates.SUITE_DEFAULTS`) scale the room, the
clearances and the degradation of the initial scene to furniture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phiscene.bench.assets import Asset, by_category
from phiscene.bench.furniture import rooms_library
from phiscene.bench.templates import (
    LIBRARIES,
    SUITE_DEFAULTS,
    Placement,
    TemplateError,
    TemplateParams,
    _choose,
    _gap,
    _yaw,
    pose_resting_on,
    register,
    top_half_extents,
    world_bounds,
)
from phiscene.transforms import rotation_z

SUITE = "rooms"

#: Default ``benchmark`` parameters of the rooms suite (see the module docstring). The degradation is
#: about three times the contact suite's: a foundation model's errors grow with object size.
ROOMS_DEFAULTS: dict = {
    "n_objects": [3, 7],
    "template": {"region": 2.0, "clearance": 0.1, "top_object_p": 0.5},
    "degrade": {"translation_xy_sigma": 0.05, "translation_z_sigma": 0.01, "vertical_offset_min": -0.04,
                "vertical_offset_max": 0.06, "rotation_sigma_deg": 3.0, "scale_sigma": 0.03, "truncate": 3.0},
}

#: What may stand on each kind of top (categories of :data:`phiscene.bench.furniture.TOP_CATEGORIES`).
TOPS_FOR: dict[str, tuple[str, ...]] = {
    "nightstand": ("lamp", "book", "vase", "box"),
    "desk": ("lamp", "book", "box", "vase"),
    "dining_table": ("plate", "vase", "box", "book"),
    "coffee_table": ("book", "plate", "vase", "box", "blob"),
    "sideboard": ("vase", "lamp", "box", "blob"),
    "tv_stand": ("box", "vase", "blob", "book"),
    "shelf": ("book", "box", "vase", "blob"),
}


# -- footprints ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Footprint:
    """Top view of a piece: the oriented rectangle of its local bounding box.

    Attributes
    ----------
    center : (2,) float
        World xy of the rectangle's centre.
    axes : (2, 2) float
        Columns: the world xy directions of the piece's local x and y axes.
    half : (2,) float
        Half extents along those axes (m).
    """

    center: np.ndarray
    axes: np.ndarray
    half: np.ndarray

    @classmethod
    def of(cls, asset: Asset, pose: np.ndarray) -> "Footprint":
        """Footprint of ``asset`` at a pose that only turns about z (its bounding box is centred at 0)."""
        return cls(np.asarray(pose[:2, 3], dtype=float), np.asarray(pose[:2, :2], dtype=float), asset.extents[:2] / 2)

    def corners(self) -> np.ndarray:
        """Corners (4, 2) in world xy, counter-clockwise."""
        signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
        return self.center + (signs * self.half) @ self.axes.T


def separation(a: Footprint, b: Footprint) -> float:
    """Largest gap (m) between two footprints along their edge normals (separating-axis test).

    Positive: the rectangles are disjoint and at least this far apart (a lower bound on their
    distance); zero or negative: they touch or overlap.
    """
    ca, cb = a.corners(), b.corners()
    best = -np.inf
    for axis in np.hstack([a.axes, b.axes]).T:
        pa, pb = ca @ axis, cb @ axis
        best = max(best, float(max(pb.min() - pa.max(), pa.min() - pb.max())))
    return best


@dataclass
class Room:
    """The floor being furnished: its current half-width and the footprints placed so far."""

    half: float
    footprints: list[Footprint]

    def fits(self, fp: Footprint, clearance: float, bounded: bool = True) -> bool:
        """At least ``clearance`` from every placed footprint and, when ``bounded``, inside the room."""
        if bounded and np.abs(fp.corners()).max() > self.half:
            return False
        return all(separation(fp, other) >= clearance for other in self.footprints)


def _on_floor(asset: Asset, yaw: float, xy, rng: np.random.Generator, params: TemplateParams) -> np.ndarray:
    return pose_resting_on(asset, rotation_z(yaw), xy, 0.0, _gap(rng, params))


def place_free(asset: Asset, room: Room, rng: np.random.Generator, params: TemplateParams) -> np.ndarray:
    """Pose (4, 4) of ``asset`` on the floor at a random yaw and free spot (the room grows when full)."""
    yaw = _yaw(rng)
    while True:
        for _ in range(params.scatter_tries):
            pose = _on_floor(asset, yaw, rng.uniform(-room.half, room.half, size=2), rng, params)
            fp = Footprint.of(asset, pose)
            if room.fits(fp, params.clearance):
                room.footprints.append(fp)
                return pose
        room.half *= 1.1


def place_relative(anchor: Placement, asset: Asset, local_xy, turn: float, room: Room, rng: np.random.Generator,
                   params: TemplateParams) -> np.ndarray:
    """Pose of ``asset`` at ``local_xy`` (2,) in the anchor's frame, turned by ``turn`` from it; free if taken.

    The spot may lie outside the room square (which only bounds free placements): a group
    stays together even when its anchor is near the edge.
    """
    R = anchor.pose[:3, :3]
    yaw = float(np.arctan2(R[1, 0], R[0, 0])) + turn
    xy = anchor.pose[:2, 3] + R[:2, :2] @ np.asarray(local_xy, dtype=float)
    pose = _on_floor(asset, yaw, xy, rng, params)
    fp = Footprint.of(asset, pose)
    if room.fits(fp, params.clearance, bounded=False):
        room.footprints.append(fp)
        return pose
    return place_free(asset, room, rng, params)


def place_anchor(asset: Asset, offset_y: float, room: Room, rng: np.random.Generator,
                 params: TemplateParams) -> np.ndarray:
    """Pose of a room's anchor piece so that its group (extending ``offset_y`` m to its -y) is centred.

    The group's centre, ``offset_y / 2`` in front of the anchor, is drawn within the middle third of
    the room at a random yaw; the anchor goes wherever it is free when that fails.
    """
    for _ in range(params.scatter_tries):
        yaw = _yaw(rng)
        centre = rng.uniform(-room.half / 3, room.half / 3, size=2)
        xy = centre - rotation_z(yaw)[:2, :2] @ np.array([0.0, -offset_y / 2])
        pose = _on_floor(asset, yaw, xy, rng, params)
        fp = Footprint.of(asset, pose)
        if room.fits(fp, params.clearance):
            room.footprints.append(fp)
            return pose
    return place_free(asset, room, rng, params)


def _anchor(offset_y: float, rng: np.random.Generator, params: TemplateParams):
    """``where`` for the anchor piece (:func:`place_anchor`)."""

    def where(out: list[Placement], asset: Asset, room: Room) -> np.ndarray:
        return place_anchor(asset, offset_y, room, rng, params)

    return where


def _spacing(rng: np.random.Generator, params: TemplateParams) -> float:
    """Distance between a related piece and its anchor: ``clearance`` to ``3 * clearance``."""
    return float(rng.uniform(params.clearance, 3 * params.clearance))


# -- small objects on tops ---------------------------------------------------------------------------------
def top_spot(host: Placement, asset: Asset, turn: float, rng: np.random.Generator,
             params: TemplateParams) -> np.ndarray | None:
    """Pose of ``asset`` resting on ``host``'s top, turned by ``turn`` from it, or ``None`` if it does not fit.

    The object's top-view box (in the host's frame) must fit in the host's top rectangle; its
    centre is offset from the rectangle's centre by up to ``stack_offset`` of the room left.
    """
    top = host.asset.meta["top"]
    mine = top_half_extents(asset, rotation_z(turn))
    room = np.asarray(top["half"], dtype=float) - mine
    if (room < 0).any():
        return None
    local = np.asarray(top["center"], dtype=float) + rng.uniform(-1, 1, size=2) * params.stack_offset * room
    R = host.pose[:3, :3]
    xy = host.pose[:2, 3] + R[:2, :2] @ local
    z = float(world_bounds(host.asset, host.pose)[1, 2])
    return pose_resting_on(asset, R @ rotation_z(turn), xy, z, _gap(rng, params))


def add_top(library: tuple, placements: list[Placement], host_index: int, rng: np.random.Generator,
            params: TemplateParams) -> bool:
    """Put a small object suited to the host on ``placements[host_index]``; ``False`` when none fits."""
    host = placements[host_index]
    pool = by_category(library, *TOPS_FOR[host.asset.category])
    for k in rng.permutation(len(pool)):
        pose = top_spot(host, pool[int(k)], _yaw(rng), rng, params)
        if pose is not None:
            placements.append(Placement(pool[int(k)], pose, "top", (host_index,)))
            return True
    return False


# -- furnishing ---------------------------------------------------------------------------------------------
def _asset(library: tuple, category: str, rng: np.random.Generator) -> Asset:
    return _choose(rng, by_category(library, category), category)


def furnish(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams,
            core: list, extras: tuple[str, ...]) -> list[Placement]:
    """Place a room's core pieces, then fill up to ``n_objects`` with extras and small objects on tops.

    Parameters
    ----------
    library
        The rooms asset library.
    n_objects
        Objects wanted (at least one; the core is cut to it).
    rng, params
        Random generator and placement parameters.
    core
        ``(category, where)`` pairs; ``where(placements, asset, room) -> pose`` places a piece
        (relative to earlier ones) or is ``None`` for a free spot.
    extras
        Categories of further free-standing pieces.
    """
    room = Room(params.region, [])
    out: list[Placement] = []

    def put(category: str, where) -> None:
        asset = _asset(library, category, rng)
        pose = place_free(asset, room, rng, params) if where is None else where(out, asset, room)
        out.append(Placement(asset, pose, "furniture" if out else "anchor"))

    n = max(1, n_objects)
    for category, where in core[:n]:
        put(category, where)
    while len(out) < n:
        topped = {p.supporters[0] for p in out if p.role == "top"}
        hosts = [i for i, p in enumerate(out) if p.role != "top" and i not in topped and p.asset.category in TOPS_FOR]
        want_top = bool(hosts) and (not extras or rng.random() < params.top_object_p)
        if want_top and add_top(library, out, hosts[int(rng.integers(len(hosts)))], rng, params):
            continue
        if not extras:
            raise TemplateError(f"no room for {n} objects: nothing more fits on the tops")
        put(extras[int(rng.integers(len(extras)))], None)
    for p in out:
        if p.role == "top":
            out[p.supporters[0]].role = "base"
    return out


def _beside(side: float, rng: np.random.Generator, params: TemplateParams):
    """``where`` for a nightstand beside the bed's head on ``side`` (+1: +x, -1: -x)."""

    def where(out: list[Placement], asset: Asset, room: Room) -> np.ndarray:
        bed = out[0]
        w, d = bed.asset.extents[:2]
        x = side * (w / 2 + _spacing(rng, params) + asset.extents[0] / 2)
        return place_relative(bed, asset, (x, d / 2 - asset.extents[1] / 2), 0.0, room, rng, params)

    return where


def _in_front(distance: float, turn: float, rng: np.random.Generator, params: TemplateParams, index: int = 0):
    """``where`` for a piece ``distance`` plus a spacing in front (-y) of ``out[index]``, turned by ``turn``."""

    def where(out: list[Placement], asset: Asset, room: Room) -> np.ndarray:
        anchor = out[index]
        y = anchor.asset.extents[1] / 2 + distance + _spacing(rng, params) + asset.extents[1] / 2
        return place_relative(anchor, asset, (0.0, -y), turn, room, rng, params)

    return where


def _at_table(seat: int, rng: np.random.Generator, params: TemplateParams):
    """``where`` for a chair facing the table (``out[0]``): seats 0-1 at the long sides, 2-3 at the ends."""

    def where(out: list[Placement], asset: Asset, room: Room) -> np.ndarray:
        table = out[0]
        w, d = table.asset.extents[:2]
        gap = _spacing(rng, params)
        # a chair's front is its -y side: turn it to face the table
        if seat < 2:
            s = 1.0 if seat == 0 else -1.0
            y = s * (d / 2 + gap + asset.extents[1] / 2)
            x = float(rng.uniform(-0.25, 0.25)) * w
            return place_relative(table, asset, (x, y), 0.0 if s > 0 else np.pi, room, rng, params)
        s = 1.0 if seat == 2 else -1.0
        x = s * (w / 2 + gap + asset.extents[1] / 2)
        return place_relative(table, asset, (x, 0.0), -s * np.pi / 2, room, rng, params)

    return where


#: Walkway (m) between a sofa and its coffee table, and between the coffee table and the TV stand
#: (both plus a spacing, see :func:`_spacing`).
SOFA_WALKWAY = 0.35
TV_DISTANCE = 0.6


@register(SUITE, "bedroom")
def bedroom(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """Bed, a nightstand beside its head, wardrobe; maybe a second nightstand, a shelf, a chair, lamps, books."""
    side = float(rng.choice([-1.0, 1.0]))
    core = [("bed", _anchor(0.0, rng, params)), ("nightstand", _beside(side, rng, params)), ("wardrobe", None),
            ("nightstand", _beside(-side, rng, params))]
    if n_objects < 5:  # the second nightstand only in larger rooms
        core = core[:3]
    return furnish(library, n_objects, rng, params, core, ("shelf", "bookcase", "chair", "desk"))


@register(SUITE, "living")
def living(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """Sofa, coffee table in front of it, TV stand beyond facing the sofa; maybe a bookcase, shelf, sideboard, chair."""
    core = [("sofa", _anchor(SOFA_WALKWAY + TV_DISTANCE + 1.0, rng, params)),
            ("coffee_table", _in_front(SOFA_WALKWAY, 0.0, rng, params)),
            ("tv_stand", _in_front(TV_DISTANCE, np.pi, rng, params, index=1))]
    return furnish(library, n_objects, rng, params, core, ("bookcase", "shelf", "sideboard", "chair"))


@register(SUITE, "dining")
def dining(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """Dining table with 2-4 chairs around it; maybe a sideboard or shelf; plates and vases on the table."""
    n_chairs = int(rng.integers(2, 5))
    core = [("dining_table", _anchor(0.0, rng, params)),
            *[("chair", _at_table(k, rng, params)) for k in range(n_chairs)]]
    return furnish(library, n_objects, rng, params, core, ("sideboard", "shelf", "bookcase"))


@register(SUITE, "office")
def office(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """Desk with a chair in front of it, a bookcase; maybe a shelf or sideboard; a lamp or books on the desk."""
    core = [("desk", _anchor(0.5, rng, params)), ("chair", _in_front(0.0, np.pi, rng, params)), ("bookcase", None)]
    return furnish(library, n_objects, rng, params, core, ("shelf", "sideboard", "bookcase"))


LIBRARIES[SUITE] = rooms_library
SUITE_DEFAULTS[SUITE] = ROOMS_DEFAULTS
