"""Scene templates: how a benchmark scene's objects are chosen and placed before simulation.

A template is a function ``(library, n_objects, rng, params) -> list[Placement]``
registered per suite with :func:`register`. It places a small contact group
(a stack, a leaning board, a bridge, a tray with contents, a tabletop) near
the origin, every object a few millimetres above what it should rest on, and
fills the scene up to ``n_objects`` with free-standing objects on the ground
around it. Placements carry the intended supporters so ground truth can
reject scenes whose objects did not end where the template meant them to.

Conventions: z up, metres, ground at z = 0; every pose is rigid (no scale).
The group is built in a canonical frame and then turned by a random yaw.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from phiscene.bench.assets import Asset, by_category
from phiscene.params import Params
from phiscene.transforms import make_pose, rotation_z

#: Intended-supporter index meaning "the ground".
GROUND = -1


@dataclass(frozen=True)
class TemplateParams(Params):
    """Placement parameters shared by every template.

    Attributes
    ----------
    gap_min, gap_max
        Range of the vertical gap (m) left between an object and what it should rest on.
    clearance
        Minimum horizontal clearance (m) between free-standing objects' footprint discs.
    region
        Initial half-width (m) of the square where free-standing objects are scattered;
        it grows by 10 % after every ``scatter_tries`` failed draws.
    scatter_tries
        Random draws per object before the region grows.
    pair_tries
        Random draws of an asset pair (leaning, bridge) before a template gives up.
    stack_min, stack_max
        Height range of stacks (objects).
    stack_twist_deg
        Largest yaw change between consecutive stacked objects (deg).
    stack_offset
        Horizontal offset of a stacked object: up to this fraction of the room its support leaves.
    lean_min_deg, lean_max_deg
        Range of a leaning board's angle from the horizontal.
    lean_face_min_deg
        Smallest angle of a board leaning on a supporter's face (a tall wall) rather than its top edge.
    lean_contact_min, lean_contact_max
        Where a supporter's top edge touches a board leaning on it: fraction of the board's
        length from its lower end.
    same_support_p
        Probability that a bridge's two supports are the same asset.
    top_object_p
        Probability of a small object on a level bridge (scenes of 4 or more objects).
    container_margin
        Clearance (m) kept between a container's inner walls and its contents.
    bridge_gap_min, bridge_gap_fraction
        Smallest free gap between the two supports of a bridge: the larger of this length (m)
        and this fraction of the plank's length.
    bridge_overlap_min
        Smallest length (m) of plank resting on each bridge support.
    max_height_difference
        Largest height difference (m) of two different bridge supports.
    """

    _label = "template parameters"

    gap_min: float = 0.002
    gap_max: float = 0.005
    clearance: float = 0.03
    region: float = 0.25
    scatter_tries: int = 40
    pair_tries: int = 50
    stack_min: int = 2
    stack_max: int = 4
    stack_twist_deg: float = 23.0
    stack_offset: float = 0.5
    lean_min_deg: float = 30.0
    lean_max_deg: float = 70.0
    lean_face_min_deg: float = 50.0
    lean_contact_min: float = 0.62
    lean_contact_max: float = 0.88
    same_support_p: float = 0.6
    top_object_p: float = 0.5
    container_margin: float = 0.006
    bridge_gap_min: float = 0.06
    bridge_gap_fraction: float = 0.25
    bridge_overlap_min: float = 0.035
    max_height_difference: float = 0.015


@dataclass
class Placement:
    """One object of a templated scene.

    Attributes
    ----------
    asset
        The object's model.
    pose : (4, 4) float
        Rigid local-to-world pose before simulation.
    role
        What the object is for in the template (``base``, ``top``, ``board``, ``deck``, ``content``, ...).
    supporters
        Indices (into the placement list) of the objects it should rest on; :data:`GROUND` for the ground;
        a string is the id of a structure plane (a wall it leans on or is fixed to).
    attached
        ``None`` for a free rigid body, else the id of the structure plane it is fixed to
        (:attr:`phiscene.scene.SceneObject.attached`).
    """

    asset: Asset
    pose: np.ndarray
    role: str
    supporters: tuple[int | str, ...] = (GROUND,)
    attached: str | None = None


class Layout(list):
    """A template's placements (a list of :class:`Placement`) plus the scene's walls.

    Templates of suites with walls return this instead of a plain list; ``structure`` holds the
    :class:`phiscene.scene.Plane` walls and ceiling (empty by default).
    """

    def __init__(self, placements=(), structure=()):
        super().__init__(placements)
        self.structure = list(structure)


class TemplateError(RuntimeError):
    """A template cannot be instantiated from this library (missing categories or sizes)."""


Template = Callable[[tuple, int, np.random.Generator, TemplateParams], list[Placement]]

#: Registered templates: ``TEMPLATES[suite][name]``.
TEMPLATES: dict[str, dict[str, Template]] = {}


def register(suite: str, name: str) -> Callable[[Template], Template]:
    """Decorator adding a template function to ``TEMPLATES[suite][name]``."""

    def deco(fn: Template) -> Template:
        TEMPLATES.setdefault(suite, {})[name] = fn
        return fn

    return deco


#: Asset library of each suite that does not use :func:`phiscene.bench.assets.asset_library`:
#: ``LIBRARIES[suite](seed, n, cache_dir) -> tuple[Asset, ...]``.
LIBRARIES: dict[str, Callable] = {}

#: Default ``benchmark`` parameters of a suite, merged under the given ones section by section
#: (see :func:`phiscene.bench.build.with_suite_defaults`); suites without an entry use the given ones as they are.
SUITE_DEFAULTS: dict[str, dict] = {}


def template_names(suite: str) -> list[str]:
    """Names of the templates of ``suite`` in registration order."""
    if suite not in TEMPLATES:
        raise KeyError(f"unknown benchmark suite {suite!r}; known: {sorted(TEMPLATES)}")
    return list(TEMPLATES[suite])


# -- geometry helpers ----------------------------------------------------------------------------------
def rotated_vertices(asset: Asset, R: np.ndarray) -> np.ndarray:
    """Asset vertices (n, 3) rotated by ``R`` (3, 3) about the local origin."""
    return np.asarray(asset.mesh.vertices, dtype=float) @ np.asarray(R).T


def pose_resting_on(asset: Asset, R: np.ndarray, xy, z_support: float, gap: float) -> np.ndarray:
    """Pose with rotation ``R`` whose lowest vertex is ``gap`` above ``z_support`` and origin at ``xy``.

    Returns
    -------
    (4, 4) float
    """
    v = rotated_vertices(asset, R)
    return make_pose(R, (float(xy[0]), float(xy[1]), z_support + gap - float(v[:, 2].min())))


def world_bounds(asset: Asset, pose: np.ndarray) -> np.ndarray:
    """World AABB (2, 3) of an asset at a rigid pose."""
    v = rotated_vertices(asset, pose[:3, :3]) + pose[:3, 3]
    return np.array([v.min(axis=0), v.max(axis=0)])


def footprint_radius(asset: Asset) -> float:
    """Radius of the smallest origin-centred disc that holds the asset's top view (m)."""
    v = np.asarray(asset.mesh.vertices, dtype=float)
    return float(np.linalg.norm(v[:, :2], axis=1).max())


def top_half_extents(asset: Asset, R: np.ndarray) -> np.ndarray:
    """Half extents (2,) in x and y of the asset rotated by ``R``."""
    v = rotated_vertices(asset, R)
    return 0.5 * (v[:, :2].max(axis=0) - v[:, :2].min(axis=0))


def rotation_y(angle: float) -> np.ndarray:
    """Rotation (3, 3) about the y axis; ``rotation_y(-a)`` tilts +x up by ``a``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def transform_group(placements: list[Placement], yaw: float, shift=(0.0, 0.0)) -> list[Placement]:
    """Turn a whole group about the world z axis by ``yaw`` and shift it in xy (in place)."""
    T = make_pose(rotation_z(yaw), (shift[0], shift[1], 0.0))
    for p in placements:
        p.pose = T @ p.pose
    return placements


def _gap(rng: np.random.Generator, params: TemplateParams) -> float:
    return float(rng.uniform(params.gap_min, params.gap_max))


def _choose(rng: np.random.Generator, assets: list[Asset], what: str) -> Asset:
    if not assets:
        raise TemplateError(f"the asset library has no {what}; use a larger n_assets")
    return assets[int(rng.integers(len(assets)))]


def _yaw(rng: np.random.Generator) -> float:
    return float(rng.uniform(-np.pi, np.pi))


# -- free-standing objects -------------------------------------------------------------------------------
#: Categories that may stand free on the ground as fillers.
FILLER_CATEGORIES = ("box", "book", "can", "blob", "prop", "plate")
#: Flat-topped categories that can carry another object.
FLAT_TOPPED = ("box", "book", "plate")
#: Categories that can be put on top of something or into a container.
SMALL = ("can", "blob", "prop", "book", "box")


def occupied_discs(placements: list[Placement]) -> list[tuple[np.ndarray, float]]:
    """Top-view discs (centre (2,), radius) of every placement's world AABB."""
    out = []
    for p in placements:
        b = world_bounds(p.asset, p.pose)
        out.append(((b[0, :2] + b[1, :2]) / 2, float(np.linalg.norm(b[1, :2] - b[0, :2]) / 2)))
    return out


def scatter(library: tuple, placements: list[Placement], count: int, rng: np.random.Generator,
            params: TemplateParams, categories=FILLER_CATEGORIES) -> list[Placement]:
    """Add ``count`` free-standing objects on the ground, clear of everything already placed.

    Each object gets a random asset of ``categories``, a random yaw and a position drawn
    in a square around the origin that grows until the object's footprint disc is at least
    ``params.clearance`` away from every other disc.
    """
    pool = by_category(library, *categories)
    discs = occupied_discs(placements)
    out = list(placements)
    half = params.region
    for _ in range(count):
        asset = _choose(rng, pool, f"object of categories {categories}")
        R = rotation_z(_yaw(rng))
        r = footprint_radius(asset)
        while True:
            for _ in range(params.scatter_tries):
                xy = rng.uniform(-half, half, size=2)
                if all(np.linalg.norm(xy - c) >= r + rc + params.clearance for c, rc in discs):
                    break
            else:
                half *= 1.1
                continue
            break
        out.append(Placement(asset, pose_resting_on(asset, R, xy, 0.0, _gap(rng, params)), "filler"))
        discs.append((xy, r))
    return out


# -- contact templates -----------------------------------------------------------------------------------
@register("contact", "stack")
def stack(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """A stack 2-4 high: flat-topped objects, largest footprint at the bottom, maybe a small object on top."""
    height = int(rng.integers(params.stack_min, params.stack_max + 1))
    height = max(2, min(height, n_objects))
    flat = by_category(library, *FLAT_TOPPED)
    small = by_category(library, "can", "blob", "prop")
    top_small = bool(rng.random() < 0.5) and bool(small)
    levels = [_choose(rng, flat, "flat-topped object (box/book/plate)") for _ in range(height - int(top_small))]
    levels.sort(key=lambda a: -float(a.extents[0] * a.extents[1]))
    if top_small:
        levels.append(_choose(rng, small, "small object"))
    out: list[Placement] = []
    xy = np.zeros(2)
    yaw = _yaw(rng)
    z = 0.0
    for k, asset in enumerate(levels):
        if k:
            yaw += float(np.radians(rng.uniform(-params.stack_twist_deg, params.stack_twist_deg)))
            below = out[-1]
            half = top_half_extents(below.asset, below.pose[:3, :3])
            mine = top_half_extents(asset, rotation_z(yaw))
            # room left on the support; a tenth of its size more so that equal sizes still get an offset
            room = params.stack_offset * (np.maximum(half - mine, 0.0) + 0.2 * half)
            xy = below.pose[:2, 3] + rng.uniform(-1, 1, size=2) * room
        R = rotation_z(yaw)
        pose = pose_resting_on(asset, R, xy, z, _gap(rng, params))
        out.append(Placement(asset, pose, "base" if k == 0 else "top" if k == len(levels) - 1 else "middle",
                             (GROUND,) if k == 0 else (k - 1,)))
        z = float(world_bounds(asset, pose)[1, 2])
    return scatter(library, out, n_objects - len(out), rng, params)


#: Accepted range of the exact edge-contact position along a leaning board (fraction of its length).
LEAN_CONTACT_BOUNDS = (0.5, 0.95)


def _lean_pose(board: Asset, H: float, rng: np.random.Generator,
               params: TemplateParams) -> np.ndarray | None:
    """Pose of a board leaning on a supporter whose face is the plane x = 0 (supporter at x > 0).

    The board rises toward +x at an angle from the horizontal in the configured range.
    If its upper end reaches below the supporter's top ``H`` it leans on the face with
    its upper corner; otherwise its underside rests on the supporter's top edge.
    Returns ``None`` when no angle in range works.
    """
    L, _, t = (float(v) for v in board.extents)
    lo, hi = np.radians(params.lean_min_deg), np.radians(params.lean_max_deg)
    g0, g1 = _gap(rng, params), _gap(rng, params)
    alpha = float(rng.uniform(max(lo, np.radians(params.lean_face_min_deg)), hi))
    cz = g0 + L / 2 * np.sin(alpha) + t / 2 * np.cos(alpha)
    top_corner_z = cz + L / 2 * np.sin(alpha) + t / 2 * np.cos(alpha)
    if top_corner_z < H - t:  # lean on the face with the upper lower-surface corner, below the top
        cx = -g1 - L / 2 * np.cos(alpha) - t / 2 * np.sin(alpha)
        return make_pose(rotation_y(-alpha), (cx, 0.0, cz))
    # rest the underside on the top edge (x=0, z=H) at a fraction f of the length from the lower end
    f = float(rng.uniform(params.lean_contact_min, params.lean_contact_max))
    ratio = H / (f * L)
    if ratio >= 1.0:
        return None
    alpha = float(np.arcsin(ratio))
    if not lo <= alpha <= hi:
        return None
    u = np.array([np.cos(alpha), 0.0, np.sin(alpha)])
    n = np.array([-np.sin(alpha), 0.0, np.cos(alpha)])
    cz = g0 + L / 2 * np.sin(alpha) + t / 2 * np.cos(alpha)
    s = (H + g1 * n[2] - cz + t / 2 * n[2]) / u[2] + L / 2  # exact contact position along the board
    if not LEAN_CONTACT_BOUNDS[0] * L <= s <= LEAN_CONTACT_BOUNDS[1] * L:
        return None
    cx = -g1 * n[0] + t / 2 * n[0] - (s - L / 2) * u[0]
    return make_pose(rotation_y(-alpha), (cx, 0.0, cz))


#: Lowest box (m) a board may lean on.
LEAN_BOX_MIN_HEIGHT = 0.08


@register("contact", "leaning")
def leaning(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """A plank (or book) leaning against a wall panel or a box; its lower end on the ground."""
    supporters = by_category(library, "wall") + [a for a in by_category(library, "box")
                                                 if a.extents[2] >= LEAN_BOX_MIN_HEIGHT]
    boards = by_category(library, "plank") + by_category(library, "book")
    for _ in range(params.pair_tries):
        sup = _choose(rng, supporters, f"wall or box of height >= {LEAN_BOX_MIN_HEIGHT} m")
        board = _choose(rng, boards, "plank or book")
        # supporter turned so that a face is the plane x = 0 and it extends to +x (a wall shows its broad face)
        turn = np.pi / 2 if sup.category == "wall" else float(rng.choice([0.0, np.pi / 2]))
        Rs = rotation_z(turn)
        half = top_half_extents(sup, Rs)
        sup_pose = pose_resting_on(sup, Rs, (half[0], 0.0), 0.0, _gap(rng, params))
        H = float(world_bounds(sup, sup_pose)[1, 2])
        if board.extents[1] > 2 * half[1]:
            continue
        pose = _lean_pose(board, H, rng, params)
        if pose is None:
            continue
        pose[1, 3] = float(rng.uniform(-1, 1)) * 0.5 * (half[1] - board.extents[1] / 2)
        group = [Placement(sup, sup_pose, "support"), Placement(board, pose, "board", (GROUND, 0))]
        transform_group(group, _yaw(rng))
        return scatter(library, group, n_objects - 2, rng, params)
    raise TemplateError("no plank/book and wall/box pair in the library leans within the angle range")


#: A bridge deck flatter than this (deg) may carry a small object.
BRIDGE_LEVEL_DEG = 2.0
#: Largest footprint radius (m) of an object on a bridge deck.
BRIDGE_TOP_MAX_RADIUS = 0.12


@register("contact", "bridge")
def bridge(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """A plank resting on two boxes with a free gap between them; maybe an object on top."""
    supports = by_category(library, "box")
    planks = by_category(library, "plank")
    for _ in range(params.pair_tries):
        plank = _choose(rng, planks, "plank")
        s1 = _choose(rng, supports, "box")
        if rng.random() < params.same_support_p:
            s2 = s1
        else:
            close = [a for a in supports if abs(a.extents[2] - s1.extents[2]) <= params.max_height_difference]
            s2 = _choose(rng, close, "support")
        R1, R2 = rotation_z(float(rng.choice([0.0, np.pi / 2]))), rotation_z(float(rng.choice([0.0, np.pi / 2])))
        a1, a2 = top_half_extents(s1, R1)[0], top_half_extents(s2, R2)[0]
        L, W, t = (float(v) for v in plank.extents)
        d_min = a1 + a2 + max(params.bridge_gap_min, params.bridge_gap_fraction * L)
        d_max = L + 2 * min(a1, a2) - 2 * params.bridge_overlap_min
        d_max = min(d_max, L - 2 * params.bridge_overlap_min)
        if d_min > d_max:
            continue
        d = float(rng.uniform(d_min, d_max))
        p1 = pose_resting_on(s1, R1, (-d / 2, 0.0), 0.0, _gap(rng, params))
        p2 = pose_resting_on(s2, R2, (d / 2, 0.0), 0.0, _gap(rng, params))
        H1, H2 = float(world_bounds(s1, p1)[1, 2]), float(world_bounds(s2, p2)[1, 2])
        beta = float(np.arctan2(H2 - H1, d))
        g = _gap(rng, params)
        z_mid = (H1 + H2) / 2 + g + (t / 2) / np.cos(beta)
        plank_pose = make_pose(rotation_y(-beta), (0.0, float(rng.uniform(-0.25, 0.25)) * (W / 2), z_mid))
        group = [Placement(s1, p1, "support"), Placement(s2, p2, "support"),
                 Placement(plank, plank_pose, "deck", (0, 1))]
        level = abs(beta) < np.radians(BRIDGE_LEVEL_DEG)
        if n_objects >= 4 and rng.random() < params.top_object_p and level:
            # something small enough to sit over the gap, near the middle of the deck
            small = [a for a in by_category(library, "can", "blob", "prop", "book")
                     if footprint_radius(a) < min(0.3 * d, BRIDGE_TOP_MAX_RADIUS)]
            if small:
                top = _choose(rng, small, "small object")
                z_top = float(world_bounds(plank, plank_pose)[1, 2])
                x_top = float(rng.uniform(-0.1, 0.1)) * d
                group.append(Placement(top, pose_resting_on(top, rotation_z(_yaw(rng)), (x_top, 0.0), z_top,
                                                            _gap(rng, params)), "top", (2,)))
        transform_group(group, _yaw(rng))
        return scatter(library, group, n_objects - len(group), rng, params)
    raise TemplateError("no plank in the library spans two supports with the configured gap and overlap")


@register("contact", "containment")
def containment(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """One to three small objects inside a tray or crate."""
    container = _choose(rng, by_category(library, "tray", "crate"), "tray or crate")
    inner = np.asarray(container.meta["inner"], dtype=float)
    R = rotation_z(_yaw(rng))
    c_pose = pose_resting_on(container, R, (0.0, 0.0), 0.0, _gap(rng, params))
    floor = float(c_pose[2, 3] + container.meta["floor"])
    margin = params.container_margin
    fits = [a for a in by_category(library, "can", "blob", "prop", "ball", "book", "box")
            if 2 * footprint_radius(a) + 2 * margin <= inner.min()]
    if not fits:
        raise TemplateError(f"no small object fits inside {container.name}")
    count = int(rng.integers(1, 4))
    count = max(1, min(count, n_objects - 1))
    group = [Placement(container, c_pose, "container")]
    discs: list[tuple[np.ndarray, float]] = []
    for _ in range(count):
        asset = _choose(rng, fits, "small object")
        r = footprint_radius(asset)
        room = inner / 2 - r - margin
        for _ in range(params.scatter_tries):
            local = rng.uniform(-1, 1, size=2) * room
            if all(np.linalg.norm(local - c) >= r + rc + margin for c, rc in discs):
                break
        else:
            continue
        discs.append((local, r))
        xy = R[:2, :2] @ local
        pose = pose_resting_on(asset, rotation_z(_yaw(rng)), xy, floor, _gap(rng, params))
        group.append(Placement(asset, pose, "content", (0,)))
    return scatter(library, group, n_objects - len(group), rng, params)


@register("contact", "tabletop")
def tabletop(library: tuple, n_objects: int, rng: np.random.Generator, params: TemplateParams) -> list[Placement]:
    """A few objects on the ground and one or two more resting on flat-topped ones."""
    n_top = int(rng.integers(1, 3))
    n_top = max(1, min(n_top, n_objects // 2))
    out = scatter(library, [], n_top, rng, params, categories=FLAT_TOPPED)
    out = scatter(library, out, n_objects - 2 * n_top, rng, params)
    small = by_category(library, *SMALL)
    for k in range(n_top):
        base = out[k]
        base.role = "base"
        half = top_half_extents(base.asset, base.pose[:3, :3])
        # smaller than the base's top face (in every turn), placed well inside it
        choices = [a for a in small if footprint_radius(a) <= 0.9 * float(np.linalg.norm(half))
                   and max(top_half_extents(a, np.eye(3))) <= 1.1 * float(half.max())]
        asset = _choose(rng, choices, f"object that fits on {base.asset.name}")
        R = rotation_z(_yaw(rng))
        mine = top_half_extents(asset, R)
        room = params.stack_offset * (np.maximum(half - mine, 0.0) + 0.2 * half)
        xy = base.pose[:2, 3] + rng.uniform(-1, 1, size=2) * room
        z = float(world_bounds(base.asset, base.pose)[1, 2])
        out.append(Placement(asset, pose_resting_on(asset, R, xy, z, _gap(rng, params)), "top", (k,)))
    return out
