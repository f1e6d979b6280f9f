"""Rigid-body settling of one active object against a fixed context (paper §3.1.3).

The active object is the only dynamic body of a :class:`~phiscene.sim.bullet.BulletWorld`;
its settled context (already frozen objects and the ground box) is static.
Frames of ``SimSettings.frame_dt`` are stepped and the paper's sliding-window
criterion is tested after every frame ``n >= w``:

    ||x_n - x_{n-w}|| < eps_pos   and   angle(r_n, r_{n-w}) < eps_rot

with ``x`` the translation and ``r`` the rotation of the object's pose.

An object that has not met the criterion by ``max_frames`` (paper: 120) is not
silently counted as settled. The remedy, in order:

1. ``extra_frames`` more frames with the same settings and criterion;
2. a damping ramp of ``ramp_frames`` frames: linear and angular damping rise
   linearly from the settings' values to ``ramp_damping`` (Bullet's damping,
   fraction of velocity removed per second, < 1), criterion tested every frame;
3. if the ramp met the criterion, the damping is restored and one more
   window of ``w`` frames is simulated (``verify``): the object counts as
   settled only if it still meets the criterion without extra damping.

Whatever the outcome, the result says which stage ended it (``remedy``) and
the motion over the last window (``residual_translation`` in m,
``residual_rotation`` in rad); ``settled`` is false when no stage met the
criterion.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from phiscene.params import Params
from phiscene.sim.bullet import BulletWorld
from phiscene.transforms import decompose, rotation_angle


@dataclass(frozen=True)
class SettleParams(Params):
    """Settling parameters (paper values for the criterion and the cap).

    Attributes
    ----------
    window
        Window length ``w`` in frames.
    eps_pos
        Translation threshold over a window (m).
    eps_rot
        Rotation threshold over a window (rad).
    max_frames
        Frames simulated before the remedy starts (paper: 120).
    extra_frames
        Remedy 1: further frames at unchanged settings.
    ramp_frames
        Remedy 2: frames of the damping ramp (0 = no ramp).
    ramp_damping
        Linear and angular damping reached at the end of the ramp (Bullet units, in [0, 1)).
    verify
        After a ramp that met the criterion, restore damping and re-test one window.
    """

    _label = "settle parameters"

    window: int = 15
    eps_pos: float = 1e-4
    eps_rot: float = 1e-4
    max_frames: int = 120
    extra_frames: int = 120
    ramp_frames: int = 60
    ramp_damping: float = 0.9
    verify: bool = True

    def check(self) -> None:
        """Reject ``window < 1``, negative frame counts and ``ramp_damping`` outside [0, 1) (``ValueError``)."""
        if self.window < 1 or min(self.max_frames, self.extra_frames, self.ramp_frames) < 0:
            raise ValueError(f"settle window must be >= 1 and frame counts >= 0: {self}")
        if not 0.0 <= self.ramp_damping < 1.0:
            raise ValueError(f"settle ramp_damping must be in [0, 1), got {self.ramp_damping}")


@dataclass
class SettleResult:
    """Outcome of settling one object.

    Attributes
    ----------
    pose : (4, 4) float
        Final pose (scale included).
    frames
        Frames simulated in total (remedy and verification included).
    settled
        Whether the window criterion was met (see the module docstring).
    remedy
        Stage that ended the run: ``none`` (within ``max_frames``), ``extra_frames``, ``damping``, or
        ``failed``.
    residual_translation, residual_rotation
        Motion over the last window (m, rad); ``inf`` if fewer than ``w`` frames ran (``None`` in
        :meth:`to_dict`).
    """

    pose: np.ndarray
    frames: int
    settled: bool
    remedy: str
    residual_translation: float
    residual_rotation: float

    def to_dict(self) -> dict:
        return {"frames": self.frames, "settled": self.settled, "remedy": self.remedy,
                "residual_translation": _finite(self.residual_translation),
                "residual_rotation": _finite(self.residual_rotation)}


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def window_motion(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Translation distance (m) and rotation angle (rad) between two poses, each (4, 4)."""
    Ra, ta, _ = decompose(a)
    Rb, tb, _ = decompose(b)
    return float(np.linalg.norm(tb - ta)), rotation_angle(Ra, Rb)


def moved_past(a: np.ndarray, b: np.ndarray, tol_pos: float, tol_rot_deg: float) -> bool:
    """Whether pose ``b`` (4, 4) lies farther than ``tol_pos`` (m) or ``tol_rot_deg`` from pose ``a``."""
    return beyond(window_motion(a, b), tol_pos, tol_rot_deg)


def beyond(motion: tuple[float, float], tol_pos: float, tol_rot_deg: float) -> bool:
    """Whether a motion ``(m, rad)`` (:func:`window_motion`) goes farther than ``tol_pos`` (m) or ``tol_rot_deg``."""
    moved, turned = motion
    return moved > tol_pos or np.degrees(turned) > tol_rot_deg


class _Window:
    """The last ``w + 1`` poses of one body and the window criterion on them."""

    def __init__(self, world: BulletWorld, name: str, params: SettleParams):
        self.world, self.name, self.params = world, name, params
        self.poses: deque = deque([world.pose(name)], maxlen=params.window + 1)
        self.frames = 0

    def step(self) -> bool:
        """Advance one frame; return whether the criterion holds now."""
        self.world.step_frames(1)
        return self.observe()

    def observe(self) -> bool:
        """Record the pose after a frame the world advanced; return whether the criterion holds now."""
        self.frames += 1
        self.poses.append(self.world.pose(self.name))
        return self.met()

    def motion(self) -> tuple[float, float]:
        """Motion over the current window (``inf`` while it is not full)."""
        if len(self.poses) <= self.params.window:
            return float("inf"), float("inf")
        return window_motion(self.poses[0], self.poses[-1])

    def met(self) -> bool:
        dt, dr = self.motion()
        return dt < self.params.eps_pos and dr < self.params.eps_rot

    def restart(self) -> None:
        """Forget the history (the next window starts from the current pose)."""
        self.poses.clear()
        self.poses.append(self.world.pose(self.name))


def _set_damping(world: BulletWorld, name: str, linear: float, angular: float) -> None:
    world.set_dynamics(name, linearDamping=linear, angularDamping=angular)


def settle_object(world: BulletWorld, name: str, params: SettleParams) -> SettleResult:
    """Simulate the dynamic body ``name`` until the window criterion holds (or every remedy is spent).

    Parameters
    ----------
    world
        A world in which ``name`` is the only dynamic body that matters (the context is static).
    name
        Body to settle.
    params
        Criterion, cap and remedy settings.

    Returns
    -------
    SettleResult
    """
    win = _Window(world, name, params)

    def run(frames: int) -> bool:
        for _ in range(frames):
            if win.step():
                return True
        return False

    if run(params.max_frames):
        return _result(world, name, win, True, "none")
    if run(params.extra_frames):
        return _result(world, name, win, True, "extra_frames")
    if params.ramp_frames == 0:
        return _result(world, name, win, False, "failed")
    s = world.settings
    met = False
    try:
        for k in range(1, params.ramp_frames + 1):
            f = k / params.ramp_frames
            _set_damping(world, name, s.linear_damping + f * (params.ramp_damping - s.linear_damping),
                         s.angular_damping + f * (params.ramp_damping - s.angular_damping))
            if win.step():
                met = True
                break
    finally:
        _set_damping(world, name, s.linear_damping, s.angular_damping)
    if met and params.verify:
        win.restart()
        met = run(params.window)
    return _result(world, name, win, met, "damping" if met else "failed")


def _result(world: BulletWorld, name: str, win: _Window, settled: bool, remedy: str) -> SettleResult:
    dt, dr = win.motion()
    return SettleResult(pose=world.pose(name), frames=win.frames, settled=settled, remedy=remedy,
                        residual_translation=dt, residual_rotation=dr)


def holds_when_tilted(world: BulletWorld, name: str, tilt_deg: float, frames: int, tol_pos: float,
                      tol_rot_deg: float, rest: SettleParams | None = None) -> tuple[bool, int]:
    """Whether body ``name``, at rest, stays put when gravity tilts by ``tilt_deg`` towards +x, -x, +y and -y.

    The settling criterion only says the object stopped moving; an object balanced on an edge, or with its
    centre of mass just inside its support, stops too, and topples at the first disturbance (the release of the
    whole scene, another simulator). Tilting gravity by ``d`` is tilting the whole context by ``d``: statics says
    a resting body stays when its centre of mass, projected along the tilted gravity, is still over its support
    (a margin of about ``h tan d`` for a centre of mass at height ``h``) and friction holds (``tan d`` below the
    friction coefficient). Each direction is simulated ``frames`` frames from the body's pose; it holds when it
    ends within ``tol_pos`` (m) and ``tol_rot_deg`` of the pose every time. Gravity and the pose are restored.

    With ``rest`` (the settling criterion), a direction ends early: as soon as the body is farther than the
    tolerance (released from rest, a body that tips or slides goes on; it does not come back), or as soon as it is
    within the tolerance and at rest by the window criterion (in equilibrium under the tilted gravity). Most of
    the cost of a test that holds is then one window per direction instead of ``frames``.

    Parameters
    ----------
    world
        The world (``name`` dynamic, its context static).
    name
        The body.
    tilt_deg
        Tilt of gravity from -z (deg).
    frames
        Frames per direction.
    tol_pos, tol_rot_deg
        How far it may end from its pose (m, deg).
    rest
        The window criterion for the early end (``None``: every direction runs ``frames`` frames).

    Returns
    -------
    held
        Whether it held in every direction (the first direction it does not hold in ends the test).
    frames
        Frames simulated in all.
    """
    start = world.pose(name)
    s, c = np.sin(np.radians(tilt_deg)), np.cos(np.radians(tilt_deg))
    held, spent = True, 0
    try:
        for dx, dy in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            world.set_pose(name, start)
            world.set_gravity((s * dx, s * dy, -c))
            if rest is None:
                world.step_frames(frames)
                spent += frames
            else:
                win = _Window(world, name, rest)
                while win.frames < frames:
                    if win.step() or moved_past(start, win.poses[-1], tol_pos, tol_rot_deg):
                        break
                spent += win.frames
            if moved_past(start, world.pose(name), tol_pos, tol_rot_deg):
                held = False
                break
    finally:
        world.set_gravity()
        world.set_pose(name, start)
    return held, spent


#: :func:`clear_overlaps`: an overlap whose normal is steeper than this (the horizontal part of the unit normal
#: is smaller: within 60 deg of vertical) is left alone: the object rests on it, or lowering stops on it.
CLEAR_MIN_HORIZONTAL = 0.5
#: :func:`clear_overlaps`, :func:`close_gaps`: horizontal moves tried before giving up.
CLEAR_ITERATIONS = 8


def clear_overlaps(world: BulletWorld, name: str, others: list[str], tol: float,
                   max_move: float) -> np.ndarray | None:
    """The horizontal move (3,) that takes body ``name``'s collision shape out of ``others``, if a short one does.

    A mesh's convex pieces reach beyond it (a plant's foliage, a chair between its legs), so two objects whose
    meshes are apart may overlap in the simulator, and the simulator pushes them apart at once: a potted plant
    whose foliage overlaps a curtain by 7 cm is knocked over before gravity acts. Each step moves the body
    horizontally out of its deepest overlap deeper than ``tol`` (m), along the horizontal part of its normal, by
    the depth over that part (what clears it along the normal); overlaps within 60 degrees of vertical
    (:data:`CLEAR_MIN_HORIZONTAL`) are left alone. The body's pose is restored.

    Returns
    -------
    The move (m, zero z), or ``None`` when nothing overlaps deeper than ``tol``, when clearing needs more than
    ``max_move`` (m), or when :data:`CLEAR_ITERATIONS` moves do not clear it (held on opposite sides).
    """

    def push() -> np.ndarray | None:
        # out of the deepest overlap (overlaps on one side would add up past the need)
        for dist, normal in sorted(world.deepest_overlaps(name, others, tol).values(), key=lambda d: d[0]):
            h, size = _horizontal(normal)
            if size >= CLEAR_MIN_HORIZONTAL:
                return h * (-dist / size)
        return None

    return _moved_horizontally(world, name, push, max_move)


def close_gaps(world: BulletWorld, name: str, partners: list[str], tol: float, clearance: float,
               max_move: float) -> np.ndarray | None:
    """The horizontal move (3,) that brings body ``name`` within ``tol`` of each of ``partners``, if a short one does.

    A depth error leaves a leaning object (a book against a wall, a plank against a box) centimetres short of what
    holds it up; released there, it turns until it falls onto it, far from the orientation it has in the input.
    Each step moves the body horizontally towards the nearest partner still farther than ``tol`` (m), along the
    horizontal part of Bullet's closest-point normal, by what leaves ``clearance`` (m) along that normal; a
    partner within 60 degrees of straight below or above (:data:`CLEAR_MIN_HORIZONTAL`) is not moved towards. The
    body's pose is restored.

    Returns
    -------
    The move (m, zero z), or ``None`` when every partner is already within ``tol``, when one is farther than
    ``max_move`` (m) or not moved towards, or when :data:`CLEAR_ITERATIONS` moves do not close the gaps.
    """

    def pull() -> np.ndarray | None:
        near = world.nearest(name, partners, max_move)
        if len(near) < len(set(partners) & set(world.bodies)):
            return np.full(3, np.inf)  # a partner out of reach
        far = sorted((v for v in near.values() if v[0] > tol), key=lambda v: v[0])
        if not far:
            return None
        dist, normal = far[0]
        h, size = _horizontal(normal)
        if size < CLEAR_MIN_HORIZONTAL:
            return np.full(3, np.inf)  # below or above it: no horizontal move closes the gap
        return -h * ((dist - clearance) / size)

    return _moved_horizontally(world, name, pull, max_move)


def _horizontal(normal: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit horizontal direction (3,) of ``normal`` (3,) and the length of its horizontal part."""
    h = np.array([normal[0], normal[1], 0.0])
    size = float(np.linalg.norm(h))
    return (h / size if size > 0 else h), size


def _moved_horizontally(world: BulletWorld, name: str, step: Callable[[], np.ndarray | None],
                        max_move: float) -> np.ndarray | None:
    """The sum of the moves ``step()`` asks for, body ``name`` moved by the sum so far before each call, until it
    asks for none (``None``); ``None`` when the sum passes ``max_move`` (m; an infinite step: no move does it), when
    the first call asks for none, or after :data:`CLEAR_ITERATIONS` moves. The body's pose is restored."""
    start = world.pose(name)
    shift = np.zeros(3)
    try:
        for _ in range(CLEAR_ITERATIONS):
            move = step()
            if move is None:
                return shift if shift.any() else None
            shift = shift + move
            if not np.linalg.norm(shift) <= max_move:
                return None
            moved = start.copy()
            moved[:3, 3] += shift
            world.set_pose(name, moved)
        return None
    finally:
        world.set_pose(name, start)


def load_carriers(world: BulletWorld, name: str, near: list[str], fixed, tol: float, depth: int) -> list[str]:
    """The placed bodies the load test (:func:`gives_way`) releases under ``name``.

    Level 1 is what ``name`` touches (``near``); each further level adds the bodies within ``tol`` of a carrier
    of the level above whose centre of mass lies lower than that carrier's (its supporters): a plank holds the
    book on it and the book holds the new box, but the plank tips under book and box together.

    Parameters
    ----------
    world
        The world, ``name`` and the placed bodies in it.
    name
        The body just settled.
    near
        The bodies ``name`` touches.
    fixed
        Ids never released (attached objects); bodies without mass properties (static context) neither.
    tol
        Contact distance (m).
    depth
        Levels (>= 1).

    Returns
    -------
    The carriers, level by level, each level sorted.
    """
    free = [q for q in world.bodies if q != name and q not in fixed and world.bodies[q].props is not None]
    chain = sorted(q for q in near if q in free)
    level = list(chain)
    for _ in range(depth - 1):
        rest = [q for q in free if q not in chain]
        if not level or not rest:
            break
        below: set[str] = set()
        for c in level:
            zc = world.com_position(c)[2]
            below |= {q for q in world.distances(c, rest, tol) if world.com_position(q)[2] < zc}
        level = sorted(below)
        chain += level
    return chain


def gives_way(world: BulletWorld, name: str, carriers: list[str], frames: int, tol_pos: float,
              tol_rot_deg: float, rest: SettleParams | None = None,
              motions: dict[str, tuple[float, float]] | None = None) -> tuple[list[str], int]:
    """Which of ``name`` and its ``carriers`` move when the carriers, frozen so far, are released under it.

    Sequential settling tests an object against a frozen context: a book leaning on a box, a plank on the edge of
    a stool, a box on a tray that overhangs its shelf, all hold there, and the whole scene collapses when it is
    released. Here the carriers (the placed objects ``name`` touches) become dynamic with ``name`` at rest on
    them and the world runs ``frames`` frames from new contacts, as a new world would
    (:meth:`~phiscene.sim.bullet.BulletWorld.forget_contacts`); a body that ends farther than ``tol_pos`` (m) or
    ``tol_rot_deg`` from where it was gives way. Poses are restored and the carriers frozen again.

    Parameters
    ----------
    world
        The world (``name`` dynamic and at rest, ``carriers`` static with their mass properties known).
    name
        The body just settled.
    carriers
        Static bodies to release under it.
    frames
        Frames simulated.
    tol_pos, tol_rot_deg
        How far a body may end from its pose (m, deg).
    rest
        The settling criterion: with it, the run ends early once every body is at rest by it (nothing moves
        any more; ``None``: always ``frames`` frames).
    motions
        Filled, when given, with each body's motion over the run: (m, deg).

    Returns
    -------
    moved
        The bodies that moved, ``name`` first when it did (empty: the carriers hold it).
    frames
        Frames simulated.
    """
    bodies = [name, *carriers]
    start = {b: world.pose(b) for b in bodies}
    try:
        for c in carriers:
            world.set_dynamic(c)
        for b in bodies:  # released as in a new world: not on the contacts Bullet kept of their rest
            world.forget_contacts(b)
        if rest is None:
            world.step_frames(frames)
            spent = frames
        else:
            windows = [_Window(world, b, rest) for b in bodies]
            spent = 0
            while spent < frames:
                world.step_frames(1)
                spent += 1
                if all([w.observe() for w in windows]):
                    break
        motion = {b: window_motion(start[b], world.pose(b)) for b in bodies}  # (m, rad), each body once
        moved_out = [b for b in bodies if beyond(motion[b], tol_pos, tol_rot_deg)]
        if motions is not None:
            motions.update({b: (moved, float(np.degrees(turned))) for b, (moved, turned) in motion.items()})
    finally:
        for c in carriers:
            world.set_static(c)
        for b in bodies:
            world.set_pose(b, start[b])
    return moved_out, spent
