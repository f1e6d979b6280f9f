"""The ``clutter`` suite: contact-rich room corners of 5-20 objects with walls, leaning and wall-fixed objects.

Every scene is a room corner: two walls (:class:`phiscene.scene.Plane` ``wall_0``, the plane ``x = 0``
with the room at ``x > 0``, and ``wall_1``, the plane ``y = 0`` with the room at ``y < 0``; both
at the far side of the reference camera) and a floor quadrant holding several contact groups:

* ``stack``: 3-5 flat-topped objects on each other (:func:`phiscene.bench.templates.stack`);
* ``lean_object``: a plank or book leaning on a box or wall panel (:func:`~phiscene.bench.templates.leaning`);
* ``bridge``: a plank bridging two supports (:func:`~phiscene.bench.templates.bridge`);
* ``container``: 1-3 objects in a tray or crate (:func:`~phiscene.bench.templates.containment`);
* ``bowl``: 1-3 objects in a bowl or a basket (:mod:`phiscene.bench.clutter_assets`);
* ``wall_lean``: a plank, book or panel leaning on a wall (supporters: the ground and the wall plane);
* ``shelf``: a low shelf against a wall with 1-3 objects on its lower levels (bottom and second board);
* ``table``: a dining table with one or two chairs tucked under it (seat under the top, back outside its
  edge) and maybe objects on the table;
* ``poster`` / ``frame``: a thin panel fixed to a wall (``attached = wall id``, a static body);
* ``wall_shelf``: a board fixed to a wall carrying one or two objects.

A template lists core groups (taken first, while they fit in ``n_objects``) and extra groups drawn
at random; the remaining objects are free-standing fillers. Wall groups are built against the plane
``x = 0`` and moved to a random free spot along one of the walls; floor groups are built around the
origin (as the contact templates build them) and moved, tallest first, to the free spot farthest
from the reference camera among ``scatter_tries`` random draws, so that small objects end in front
and stay visible. A spot is free when the group's world AABB, grown by ``params.clearance``,
overlaps no other group's and neither hides the other from the reference camera (:func:`hides`);
the quadrant grows by 10 % after a round of draws without one.

Suite defaults (:data:`CLUTTER_DEFAULTS`) set 5-20 objects, stacks of 3-5 and a larger render
(640 x 480) so small objects stay visible in a room-sized view.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from phiscene.bench.assets import Asset, by_category
from phiscene.bench.clutter_assets import clutter_library
from phiscene.bench.rooms import add_top
from phiscene.bench.templates import (
    FILLER_CATEGORIES,
    GROUND,
    LIBRARIES,
    SUITE_DEFAULTS,
    Layout,
    Placement,
    TemplateError,
    TemplateParams,
    _choose,
    _gap,
    _lean_pose,
    _yaw,
    bridge,
    containment,
    footprint_radius,
    leaning,
    pose_resting_on,
    register,
    stack,
    transform_group,
    world_bounds,
)
from phiscene.scene import Plane
from phiscene.transforms import make_pose, rotation_z

SUITE = "clutter"

#: The two walls of every clutter scene: a corner at the origin, room at x > 0 and y < 0.
WALLS = (Plane("wall_0", "wall", (1.0, 0.0, 0.0), 0.0), Plane("wall_1", "wall", (0.0, -1.0, 0.0), 0.0))
#: Yaw that turns a group built against the plane x = 0 (room at +x) to face each wall, and the world
#: axis along the wall (the direction of the group's shift).
WALL_FRAMES = {"wall_0": (0.0, np.array([0.0, -1.0])), "wall_1": (-np.pi / 2, np.array([1.0, 0.0]))}
#: Placeholder supporter of a wall group, replaced by the wall's id when the group is placed.
WALL = "WALL"


#: Height range (m) of the bottom of wall-fixed items.
MOUNT_HEIGHT = (1.05, 1.35)
#: Gap (m) between a wall-fixed item and its wall, and between a shelf's back and the wall.
WALL_GAP = (0.001, 0.02)
#: Categories that go on shelves (lower levels and wall shelves).
SHELF_ITEMS = ("book", "box", "can", "vase", "blob")

#: Default ``benchmark`` parameters of the clutter suite.
CLUTTER_DEFAULTS: dict = {
    "n_objects": [5, 20],
    "template": {"region": 0.9, "clearance": 0.04, "stack_min": 3, "stack_max": 5},
    "render": {"width": 640, "height": 480, "min_visible_pixels": 30},
}


# -- groups --------------------------------------------------------------------------------------------------
def _strip(group: list[Placement]) -> list[Placement]:
    """A contact template's group without its free-standing fillers (their indices come last)."""
    return [p for p in group if p.role != "filler"]


def stack_group(library, rng, params) -> list[Placement]:
    """A stack of ``stack_min``-``stack_max`` objects (the contact ``stack`` with that exact height)."""
    k = int(rng.integers(params.stack_min, params.stack_max + 1))
    return _strip(stack(library, k, rng, replace(params, stack_min=k, stack_max=k)))


def lean_object_group(library, rng, params) -> list[Placement]:
    """A plank or book leaning on a box or wall panel."""
    return _strip(leaning(library, 2, rng, params))


def bridge_group(library, rng, params) -> list[Placement]:
    """A plank on two supports, maybe with an object on it."""
    return _strip(bridge(library, 4, rng, params))


def container_group(library, rng, params) -> list[Placement]:
    """1-3 objects in a tray or crate."""
    return _strip(containment(library, 4, rng, params))


#: Categories that go into bowls and baskets.
BOWL_ITEMS = ("blob", "ball", "can", "prop", "box")
#: How far (m) an object in a bowl or basket must rise above its rim (so the reference view sees it).
RIM_CLEARANCE = 0.01
#: Objects drawn for a bowl or basket before it keeps what fitted.
CONTENT_TRIES = 10


def bowl_group(library, rng, params) -> list[Placement]:
    """1-3 small objects in a bowl or a basket (``contains`` in the ground truth)."""
    container = _choose(rng, by_category(library, "bowl", "basket"), "bowl or basket")
    R = rotation_z(_yaw(rng))
    c_pose = pose_resting_on(container, R, (0.0, 0.0), 0.0, _gap(rng, params))
    floor = float(c_pose[2, 3] + container.meta["floor"])
    inner = np.asarray(container.meta["inner"], dtype=float)
    rim = float(world_bounds(container, c_pose)[1, 2])
    round_ = bool(container.meta.get("round", False))
    margin = params.container_margin
    fits = [a for a in by_category(library, *BOWL_ITEMS) if 2 * footprint_radius(a) + 2 * margin <= inner.min()]
    group = [Placement(container, c_pose, "container")]
    discs: list[tuple[np.ndarray, float]] = []
    want = int(rng.integers(1, 4))
    for _ in range(CONTENT_TRIES):
        if not fits or len(group) > want:
            break
        asset = _choose(rng, fits, "object that fits in the container")
        r = footprint_radius(asset)
        room = inner / 2 - r - margin
        for _ in range(params.scatter_tries):
            local = rng.uniform(-1, 1, size=2) * room
            inside = np.linalg.norm(local) <= room.min() if round_ else True
            if inside and all(np.linalg.norm(local - c) >= r + rc + margin for c, rc in discs):
                break
        else:
            continue
        discs.append((local, r))
        pose = pose_resting_on(asset, rotation_z(_yaw(rng)), R[:2, :2] @ local, floor, _gap(rng, params))
        if world_bounds(asset, pose)[1, 2] < rim + RIM_CLEARANCE:  # below the rim it would be hidden in the render
            discs.pop()
            continue
        group.append(Placement(asset, pose, "content", (0,)))
    if len(group) == 1:
        raise TemplateError(f"nothing fits in {container.name}")
    return group


def wall_lean_group(library, rng, params) -> list[Placement]:
    """A plank, book or wall panel leaning on the wall plane ``x = 0`` (room at ``x > 0``), its foot on the ground."""
    boards = by_category(library, "plank", "book", "wall")
    board = _choose(rng, boards, "plank, book or panel")
    # _lean_pose leans on the face x = 0 of a supporter at x > 0: lean on a wall taller than any board,
    # then turn by 180 degrees so that the board stands in the room
    pose = _lean_pose(board, 10.0, rng, params)
    if pose is None:  # cannot happen on a face lean; kept for safety
        raise TemplateError(f"{board.name} cannot lean on a wall")
    group = [Placement(board, pose, "board", (GROUND, WALL))]
    return transform_group(group, np.pi)


def _boards(asset: Asset) -> list[tuple[float, float]]:
    """Boards of a ``shelf`` asset: ``(z of the top face, z of the bottom face)`` in its canonical frame, low first."""
    parts = asset.recipe["parts"]
    lo = np.min([np.asarray(c) - np.asarray(s) / 2 for _, s, c in parts], axis=0)
    hi = np.max([np.asarray(c) + np.asarray(s) / 2 for _, s, c in parts], axis=0)
    centre = (lo + hi) / 2
    out = [(c[2] + s[2] / 2 - centre[2], c[2] - s[2] / 2 - centre[2]) for _, s, c in parts if s[2] < s[0]]
    return sorted(out)


def shelf_group(library, rng, params) -> list[Placement]:
    """A low shelf with its back to the wall plane ``x = 0`` and 1-3 objects on its two lowest boards."""
    shelf = _choose(rng, by_category(library, "shelf"), "shelf")
    R = rotation_z(np.pi / 2)  # the shelf's back (+y) towards the wall (-x)
    depth, width = float(shelf.extents[1]), float(shelf.extents[0])
    pose = pose_resting_on(shelf, R, (float(rng.uniform(*WALL_GAP)) + depth / 2, 0.0), 0.0, _gap(rng, params))
    group = [Placement(shelf, pose, "shelf")]
    boards = _boards(shelf)
    side = 0.5 * (width - float(np.asarray(shelf.recipe["parts"][0][1])[0]) * 2)  # half inner width
    margin = params.container_margin
    discs: list[tuple[int, np.ndarray, float]] = []
    for _ in range(int(rng.integers(1, 4))):
        level = int(rng.integers(0, min(2, len(boards) - 1)))
        clear = boards[level + 1][1] - boards[level][0]
        fits = [a for a in by_category(library, *SHELF_ITEMS)
                if a.extents[2] < clear - 0.03 and 2 * footprint_radius(a) + 2 * margin < depth]
        if not fits:
            continue
        asset = _choose(rng, fits, "object that fits on a shelf board")
        r = footprint_radius(asset)
        room = np.array([side - r - margin, depth / 2 - r - margin])
        if (room < 0).any():
            continue
        for _ in range(params.scatter_tries):
            local = rng.uniform(-1, 1, size=2) * room
            if all(lv != level or np.linalg.norm(local - c) >= r + rc + margin for lv, c, rc in discs):
                break
        else:
            continue
        discs.append((level, local, r))
        xy = pose[:2, 3] + R[:2, :2] @ local
        z = float(pose[2, 3]) + boards[level][0]
        group.append(Placement(asset, pose_resting_on(asset, rotation_z(_yaw(rng)), xy, z, _gap(rng, params)),
                               "content", (0,)))
    if len(group) == 1:
        raise TemplateError(f"nothing fits on the lower boards of {shelf.name}")
    return group


#: Clear gap (m) range between a tucked chair's back and the table's edge.
TUCK_GAP = (0.015, 0.05)
#: Room (m) kept between a tucked chair's legs and the table's legs.
LEG_MARGIN = 0.03


def table_group(library, rng, params) -> list[Placement]:
    """A dining table with one or two chairs tucked under its long sides and maybe 1-2 objects on it."""
    table = _choose(rng, by_category(library, "dining_table"), "dining table")
    t_pose = pose_resting_on(table, np.eye(3), (0.0, 0.0), 0.0, _gap(rng, params))
    group = [Placement(table, t_pose, "table")]
    D = float(table.extents[1])
    parts = table.recipe["parts"]
    leg_x = abs(float(parts[1][2][0])) - float(parts[1][1][0]) / 2  # inner face of the legs
    for side in (1.0, -1.0)[: int(rng.integers(1, 3))]:
        chair = _choose(rng, by_category(library, "chair"), "chair")
        cw, cd = float(chair.extents[0]), float(chair.extents[1])
        back_t = float(chair.recipe["parts"][-1][1][1])
        x_room = leg_x - cw / 2 - LEG_MARGIN
        if x_room < 0:
            continue
        # the chair's back (+y local) faces away from the table: its inner face TUCK_GAP outside the edge
        y = D / 2 + float(rng.uniform(*TUCK_GAP)) + back_t - cd / 2
        R = rotation_z(0.0 if side > 0 else np.pi)
        xy = (float(rng.uniform(-1, 1)) * x_room, side * y)
        group.append(Placement(chair, pose_resting_on(chair, R, xy, 0.0, _gap(rng, params)), "chair"))
    for _ in range(int(rng.integers(0, 3))):
        add_top(library, group, 0, rng, params)
    transform_group(group, _yaw(rng))
    return group


def mounted_group(category: str):
    """Group builder of a wall-fixed item of ``category`` (poster, frame) on the wall plane ``x = 0``."""

    def build(library, rng, params) -> list[Placement]:
        item = _choose(rng, by_category(library, category), category)
        R = rotation_z(np.pi / 2)  # local +y (wall side) towards -x
        x = float(item.extents[1]) / 2 + float(rng.uniform(0.001, 0.003))
        z = float(rng.uniform(*MOUNT_HEIGHT)) + float(item.extents[2]) / 2
        return [Placement(item, make_pose(R, (x, 0.0, z)), "mounted", (WALL,), attached=WALL)]

    return build


def wall_shelf_group(library, rng, params) -> list[Placement]:
    """A shelf board fixed to the wall plane ``x = 0`` carrying one or two objects."""
    board = _choose(rng, by_category(library, "wall_shelf"), "wall shelf")
    R = rotation_z(np.pi / 2)
    L, depth = float(board.extents[0]), float(board.extents[1])
    pose = make_pose(R, (depth / 2 + 0.002, 0.0, float(rng.uniform(*MOUNT_HEIGHT)) + float(board.extents[2]) / 2))
    group = [Placement(board, pose, "mounted", (WALL,), attached=WALL)]
    top = float(world_bounds(board, pose)[1, 2])
    fits = [a for a in by_category(library, *SHELF_ITEMS) if 2 * footprint_radius(a) < depth - 0.01]
    used: list[tuple[float, float]] = []
    for _ in range(int(rng.integers(1, 3))):
        if not fits:
            break
        asset = _choose(rng, fits, "object that fits on a wall shelf")
        r = footprint_radius(asset)
        for _ in range(params.scatter_tries):
            s = float(rng.uniform(-1, 1)) * (L / 2 - r - 0.01)
            if all(abs(s - c) >= r + rc + params.container_margin for c, rc in used):
                break
        else:
            continue
        used.append((s, r))
        group.append(Placement(asset, pose_resting_on(asset, rotation_z(_yaw(rng)), (depth / 2 + 0.002, s), top,
                                                      _gap(rng, params)), "top", (0,)))
    return group


#: Group builders: name -> (builder, against a wall).
GROUPS = {
    "stack": (stack_group, False), "lean_object": (lean_object_group, False), "bridge": (bridge_group, False),
    "container": (container_group, False), "bowl": (bowl_group, False), "table": (table_group, False),
    "wall_lean": (wall_lean_group, True),
    "shelf": (shelf_group, True), "poster": (mounted_group("poster"), True), "frame": (mounted_group("frame"), True),
    "wall_shelf": (wall_shelf_group, True),
}


# -- layout ---------------------------------------------------------------------------------------------------
#: Horizontal direction (2,) from the scene towards the reference camera (``render.azimuth_deg`` -60 deg).
TOWARDS_CAMERA = np.array([np.cos(np.radians(-60.0)), np.sin(np.radians(-60.0))])
#: Elevation (deg) of the reference camera (``render.elevation_deg``).
CAMERA_ELEVATION_DEG = 35.0
#: Rounds of ``scatter_tries`` draws (the floor grows by 10 % after each) before a group is given up.
GROW_ROUNDS = 15


class Corner:
    """The room corner being filled: placed groups' AABBs and the current floor extent."""

    def __init__(self, params: TemplateParams):
        self.extent = params.region
        self.boxes: list[np.ndarray] = []
        self.params = params

    def free(self, box: np.ndarray) -> bool:
        """Whether an AABB (2, 3) lies in the room, keeps ``clearance`` from every placed one and hides none."""
        c = self.params.clearance
        if box[0, 0] < -1e-9 or box[1, 1] > 1e-9:
            return False
        return all(((box[1] + c <= b[0]).any() or (b[1] + c <= box[0]).any())
                   and not hides(box, b) and not hides(b, box) for b in self.boxes)

    def place(self, group: list[Placement], wall: str | None, rng: np.random.Generator) -> bool:
        """Move ``group`` to a free spot; ``False`` after :data:`GROW_ROUNDS` rounds.

        Along ``wall``: the first free one of random draws. On the floor: of ``scatter_tries`` random
        draws, the free one farthest from the reference camera (:data:`TOWARDS_CAMERA`).
        """
        if wall is not None:
            yaw, _ = WALL_FRAMES[wall]
            transform_group(group, yaw)
            for p in group:
                p.supporters = tuple(wall if s == WALL else s for s in p.supporters)
                if p.attached == WALL:
                    p.attached = wall
        box0 = _group_box(group)
        found: list[tuple[float, np.ndarray, np.ndarray]] = []
        for _ in range(GROW_ROUNDS):
            for _ in range(self.params.scatter_tries):
                if wall is None:
                    lo = np.array([self.params.clearance, -self.extent]) - box0[0, :2]
                    hi = np.array([self.extent, -self.params.clearance]) - box0[1, :2]
                    if (hi < lo).any():
                        break
                    shift = rng.uniform(lo, hi)
                else:
                    axis = WALL_FRAMES[wall][1]
                    along = box0[:, :2] @ axis
                    lo, hi = self.params.clearance - along.min(), self.extent - along.max()
                    if hi < lo:
                        break
                    shift = float(rng.uniform(lo, hi)) * axis
                box = box0 + [[shift[0], shift[1], 0.0]]
                if self.free(box):
                    found.append((float(box[:, :2].mean(axis=0) @ TOWARDS_CAMERA), shift, box))
                    if wall is not None:
                        break
            if found:  # the free spot farthest from the camera: the room fills back to front
                _, shift, box = min(found, key=lambda f: f[0])
                transform_group(group, 0.0, shift)
                self.boxes.append(box)
                return True
            self.extent *= 1.1
        return False


def hides(front: np.ndarray, back: np.ndarray) -> bool:
    """Whether AABB ``front`` (2, 3) stands between the reference camera and the lower part of AABB ``back``.

    Seen from the camera (:data:`TOWARDS_CAMERA`, :data:`CAMERA_ELEVATION_DEG`), ``front`` hides ``back`` when
    their extents across the view overlap, ``front`` is nearer, and the sight line over its top does not
    reach the bottom of ``back``: the gap between them along the view is below
    ``(top of front - bottom of back) / tan(elevation)``.
    """
    across = np.array([-TOWARDS_CAMERA[1], TOWARDS_CAMERA[0]])

    def spans(box):
        xy = np.array([[box[i, 0], box[j, 1]] for i in (0, 1) for j in (0, 1)])
        return xy @ TOWARDS_CAMERA, xy @ across

    (df, af), (db, ab) = spans(front), spans(back)
    if af.min() >= ab.max() or ab.min() >= af.max():
        return False
    gap = df.min() - db.max()
    return gap >= 0 and gap < (front[1, 2] - back[0, 2]) / np.tan(np.radians(CAMERA_ELEVATION_DEG))


def _group_box(group: list[Placement]) -> np.ndarray:
    b = np.array([world_bounds(p.asset, p.pose) for p in group])
    return np.array([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])


#: Most groups of one kind per scene.
MAX_REPEATS = 2


def compose(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams,
            core: tuple[str, ...], extras: tuple[str, ...]) -> Layout:
    """A room corner of exactly ``n_objects`` objects: core groups, extra groups, then fillers.

    Core groups (names of :data:`GROUPS`) are taken in order while they fit in ``n_objects``; then
    extra groups drawn at random (up to 3 tries of a group that does not fit, at most :data:`MAX_REPEATS`
    groups of a kind); the rest are free-standing fillers. A group whose builder fails
    (:class:`TemplateError`) is skipped. Groups are then placed back to front (:meth:`Corner.place`):
    wall groups first, then floor groups from the tallest down, so that small objects end in front.

    Raises
    ------
    TemplateError
        A group found no free spot.
    """
    corner = Corner(params)
    groups: list[tuple[list[Placement], str | None]] = []
    count = 0
    used: dict[str, int] = {}

    def take(name: str) -> bool:
        nonlocal count
        if used.get(name, 0) >= MAX_REPEATS:
            return False
        used[name] = used.get(name, 0) + 1
        build, on_wall = GROUPS[name]
        try:
            group = build(library, rng, params)
        except TemplateError:
            return False
        if count + len(group) > n_objects:
            return False
        groups.append((group, WALLS[int(rng.integers(len(WALLS)))].id if on_wall else None))
        count += len(group)
        return True

    for name in core:
        take(name)
    misses = 0
    while extras and misses < 3 and count < n_objects:
        misses = 0 if take(extras[int(rng.integers(len(extras)))]) else misses + 1
    fillers = by_category(library, *FILLER_CATEGORIES)
    for _ in range(n_objects - count):
        asset = _choose(rng, fillers, "filler")
        pose = pose_resting_on(asset, rotation_z(_yaw(rng)), (0.0, 0.0), 0.0, _gap(rng, params))
        groups.append(([Placement(asset, pose, "filler")], None))
    out = Layout(structure=WALLS)
    for group, wall in sorted(groups, key=lambda gw: (gw[1] is None, -_group_box(gw[0])[1, 2])):
        if not corner.place(group, wall, rng):
            raise TemplateError(f"no room for {n_objects} objects in the corner")
        base = len(out)
        for p in group:
            p.supporters = tuple(s + base if isinstance(s, int) and s != GROUND else s for s in p.supporters)
        out.extend(group)
    return out


def _template(core: tuple[str, ...], extras: tuple[str, ...], doc: str):
    def template(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> Layout:
        return compose(library, n_objects, rng, params, core, extras)

    template.__doc__ = doc
    return template


#: The clutter templates: name -> (core groups, extra groups).
CLUTTER_TEMPLATES = {
    "stacks": (("stack", "wall_lean", "poster", "stack"), ("container", "bowl", "lean_object", "frame")),
    "leaning": (("wall_lean", "lean_object", "frame", "wall_lean"), ("stack", "bridge", "container")),
    "bridges": (("bridge", "stack", "wall_shelf"), ("bridge", "lean_object", "bowl", "poster")),
    "storage": (("shelf", "bowl", "wall_shelf"), ("container", "bowl", "stack", "frame")),
    "dining": (("table", "wall_lean", "poster"), ("container", "bowl", "stack", "shelf")),
}

for _name, (_core, _extras) in CLUTTER_TEMPLATES.items():
    register(SUITE, _name)(_template(_core, _extras, f"Room corner: {', '.join(_core)}; then {', '.join(_extras)}."))

LIBRARIES[SUITE] = clutter_library
SUITE_DEFAULTS[SUITE] = CLUTTER_DEFAULTS
