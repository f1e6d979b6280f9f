"""Registry of drift simulators: the engines a scene is released in to measure post-simulation drift.

Every simulator follows one protocol (paper supplement): lift each free object by ``upward_offset``, simulate
``frames`` frames, and report per object and on average over the free objects the translation of the centre of
mass (m) and the rotation (degrees). A simulator is one :class:`DriftSimulator` entry: its name, the metrics
section its drift lands in, the column suffix of the cross-simulator table, whether that table ranks it, and (for
a simulator with a section of its own) the drift function. :func:`register_simulator` registers that section
(:mod:`phiscene.metrics.sections`), so the cross-simulator table (:mod:`phiscene.table_registry`) shows a new
engine with no other edit::

    register_simulator(DriftSimulator("bullet_pgs", section="bullet_pgs", column="bullet_pgs",
                                      drift=my_drift, settings=("physical", "sim", "bullet_pgs")))

pybullet's drift (:func:`drift_bullet`) is part of the ``physical`` section (it runs with the contact
metrics); MuJoCo's (:func:`drift_mujoco`) is the ``mujoco`` section. The drift functions live here, with the
metrics; :mod:`phiscene.sim` only builds and steps the worlds.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from phiscene.metrics.sections import MetricSection, SectionContext, register_section, unregister_section
from phiscene.scene import ground_below
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, make_pose, rotation_angle

if TYPE_CHECKING:
    from phiscene.proxies import Proxy
    from phiscene.scene import Scene
    from phiscene.sim.mujoco import MujocoParams

log = logging.getLogger(__name__)

#: Per-object and mean keys every drift result holds.
DRIFT_KEYS = ("drift_trans", "drift_rot")


@dataclass(frozen=True)
class DriftSimulator:
    """One engine of the drift protocol.

    Attributes
    ----------
    name
        Engine name (drift figure ``drift_<name>.png``).
    section
        Metrics section holding its ``drift_trans`` / ``drift_rot``.
    column
        Suffix of its cross-simulator table columns (``drift_trans_<column>``).
    ranked
        The cross-simulator table ranks its columns (engines independent of the grounding's own).
    drift
        ``drift(ctx) -> dict`` with :data:`DRIFT_KEYS` means and ``objects``; ``None`` when another section
        computes it (pybullet's drift is in ``physical``).
    settings, inputs
        What its section reads (see :class:`~phiscene.metrics.sections.MetricSection`).
    """

    name: str
    section: str
    column: str
    ranked: bool = True
    drift: Callable[[SectionContext], dict] | None = None
    settings: tuple[str, ...] = ("physical", "sim")
    inputs: tuple[str, ...] = ("proxies",)


#: Registered simulators by name, in registration order.
SIMULATORS: dict[str, DriftSimulator] = {}


def _drift_line(r: dict) -> str:
    return f"drift {r['drift_trans']:.4f} m / {r['drift_rot']:.2f} deg"


def register_simulator(sim: DriftSimulator) -> DriftSimulator:
    """Add a simulator (and its metrics section when it brings a drift function); return it."""
    if sim.name in SIMULATORS:
        raise ValueError(f"drift simulator {sim.name!r} is already registered")
    if sim.drift is not None:
        register_section(MetricSection(sim.section, sim.drift, sim.settings, sim.inputs, _drift_line))
    SIMULATORS[sim.name] = sim
    return sim


def unregister_simulator(name: str) -> None:
    """Remove a simulator and the section it registered (tests and temporary plugins)."""
    sim = SIMULATORS.pop(name, None)
    if sim is not None and sim.drift is not None:
        unregister_section(sim.section)


def table_simulators() -> list[DriftSimulator]:
    """The simulators of the cross-simulator table: ranked ones first, each group in registration order."""
    sims = list(SIMULATORS.values())
    return [s for s in sims if s.ranked] + [s for s in sims if not s.ranked]


class DriftParams(Protocol):
    """What the drift needs from the physical-metric parameters (e.g. ``PhysicalParams``).

    Attributes
    ----------
    upward_offset
        Lift (m) applied to every object before release.
    frames
        Number of frames of ``SimSettings.frame_dt`` simulated.
    """

    upward_offset: float
    frames: int


# -- pybullet ------------------------------------------------------------------------------------------
def drift_bullet(scene: "Scene", proxies: dict[str, "Proxy"], params: DriftParams, sim: SimSettings,
                 cache_dir: str | Path) -> dict:
    """Post-simulation drift of a scene in pybullet.

    Parameters
    ----------
    scene
        The scene to release.
    proxies
        Convex proxies by object id.
    params
        ``upward_offset`` and ``frames``.
    sim
        Simulation settings (``density`` for the mass properties).
    cache_dir
        Folder for pybullet's hull files.

    Returns
    -------
    ``{"drift_trans": mean m, "drift_rot": mean degrees, "ground_below": m,
    "objects": {id: {"drift_trans": m, "drift_rot": degrees}}}``

    Raises
    ------
    InputError
        An object has no proxy.
    """
    from phiscene.inertia import rigid_props
    from phiscene.proxies import check_proxies, with_bases
    from phiscene.sim.bullet import BulletWorld

    check_proxies(scene, proxies)
    proxies = with_bases(scene, proxies)  # completed bases: pieces of the collision shapes
    offset = np.array([0.0, 0.0, float(params.upward_offset)])
    floor = ground_below(scene, proxies)
    with BulletWorld(sim, cache_dir) as world:
        world.add_ground(floor)
        world.add_structure(scene.structure)  # walls and ceiling: static colliders (a leaning board stays up)
        for o in scene.objects:
            hulls = proxies[o.id].hulls
            _, _, scale = decompose(o.pose)
            lifted = np.array(o.pose, dtype=float)
            if o.attached is None:
                lifted[:3, 3] += offset
            world.add_body(o.id, hulls, lifted, rigid_props(o.mesh(), hulls, sim.density, scale, o.com))
            if o.attached is not None:
                world.set_static(o.id)
        com0 = {o.id: world.com_position(o.id) - offset for o in scene.objects if o.attached is None}
        world.step_frames(int(params.frames))
        per = {}
        for o in scene.objects:
            if o.attached is not None:
                per[o.id] = {"drift_trans": 0.0, "drift_rot": 0.0, "attached": o.attached}
                continue
            R0, _, _ = decompose(o.pose)
            R1, _, _ = decompose(world.pose(o.id))
            per[o.id] = {"drift_trans": float(np.linalg.norm(world.com_position(o.id) - com0[o.id])),
                         "drift_rot": math.degrees(rotation_angle(R0, R1))}
    return {**free_means(per, ("drift_trans", "drift_rot")), "ground_below": floor, "objects": per}


def free_means(per: dict[str, dict], keys: tuple[str, ...]) -> dict[str, float]:
    """Means of ``keys`` over the per-object entries that are not ``attached`` (0 when every object is)."""
    free = [v for v in per.values() if "attached" not in v]
    return {k: float(np.mean([v[k] for v in free])) if free else 0.0 for k in keys}


# -- MuJoCo -------------------------------------------------------------------
#: :func:`drift_mujoco`: a release whose contacts overflow the arena MuJoCo sized for the model (a reconstruction's
#: objects through one another: 343 contacts, 2058 constraint rows) runs again from the start with an arena this many
#: times larger, at most this many times (the release itself does not depend on the arena's size).
MUJOCO_ARENA_GROWTH = 4
MUJOCO_ARENA_RETRIES = 3


def drift_mujoco(scene: "Scene", proxies: dict[str, "Proxy"], params: DriftParams, sim: SimSettings,
                 mj: MujocoParams | None = None) -> dict:
    """Post-simulation drift of a scene in MuJoCo (same protocol as the pybullet drift).

    Parameters
    ----------
    scene
        The scene to release.
    proxies
        Convex proxies by object id.
    params
        Any object with ``upward_offset`` (m) and ``frames``.
    sim
        Shared simulation settings.
    mj
        MuJoCo contact and solver settings.

    Returns
    -------
    ``{"drift_trans": mean m, "drift_rot": mean degrees, "ground_below": m,
    "objects": {id: {"drift_trans": m, "drift_rot": degrees}}}`` (the structure
    of the pybullet drift); translation drift is measured from the centre of
    mass before the lift, ``ground_below`` is the ground height used.
    """
    import mujoco

    from phiscene.proxies import with_bases
    from phiscene.sim.mujoco import ArenaFull, body_poses, build_spec, compile_model, step_frames

    offset = float(params.upward_offset)
    frames = int(params.frames)
    if not (math.isfinite(offset) and offset >= 0.0):
        raise ValueError(f"upward_offset must be finite and >= 0, got {params.upward_offset}")
    if frames < 0:
        raise ValueError(f"frames must be >= 0, got {params.frames}")
    lift = make_pose(translation=[0.0, 0.0, offset])
    lifted = scene.with_poses({o.id: lift @ o.pose for o in scene.objects if o.attached is None})
    proxies = with_bases(scene, proxies)  # completed bases: pieces of the collision shapes
    floor = ground_below(scene, proxies)
    spec = build_spec(lifted, proxies, sim, floor, mj)
    for attempt in range(MUJOCO_ARENA_RETRIES + 1):
        model = compile_model(spec, sim)
        data = mujoco.MjData(model)
        try:
            mujoco.mj_forward(model, data)
            start = body_poses(model, data, scene.ids)
            step_frames(model, data, frames, sim)
            break
        except (mujoco.FatalError, ArenaFull) as exc:  # the arena MuJoCo sized for the model holds too few contacts
            full = isinstance(exc, ArenaFull) or "out of memory" in str(exc)
            if not full or attempt == MUJOCO_ARENA_RETRIES:
                raise
            spec.memory = MUJOCO_ARENA_GROWTH * int(model.narena)
            log.info("MuJoCo drift of %s: its contacts overflow the arena (%s); again with %d MB", scene.source,
                     " ".join(str(exc).split())[:80], spec.memory // 2**20)
    end = body_poses(model, data, scene.ids)
    objects = {}
    for o in scene.objects:
        name = o.id
        if o.attached is not None:
            objects[name] = {"drift_trans": 0.0, "drift_rot": 0.0, "attached": o.attached}
            continue
        com0 = start[name][:3, 3] - [0.0, 0.0, offset]
        objects[name] = {
            "drift_trans": float(np.linalg.norm(end[name][:3, 3] - com0)),
            "drift_rot": math.degrees(rotation_angle(start[name][:3, :3], end[name][:3, :3])),
        }
    return {**free_means(objects, ("drift_trans", "drift_rot")), "ground_below": floor, "objects": objects}


def _mujoco(ctx: SectionContext) -> dict:
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.sim.mujoco import MujocoParams

    return drift_mujoco(ctx.scene, ctx.proxies(), ctx.params(PhysicalParams, "physical"), ctx.sim(),
                        ctx.params(MujocoParams, "mujoco"))


register_simulator(DriftSimulator("pybullet", section="physical", column="bullet", ranked=False))
register_simulator(DriftSimulator("mujoco", section="mujoco", column="mujoco", drift=_mujoco,
                                  settings=("physical", "sim", "mujoco")))
