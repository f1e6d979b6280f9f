"""Joint rigid-body simulation (paper Tab. 6 "joint SDF + sim." and the simulation step of the lift baseline).

All objects are released together as dynamic compounds of their convex
proxies (mass properties at ``SimSettings.density``) in one
:class:`~phiscene.sim.bullet.BulletWorld` with a ground box whose top is
``scene.ground_height``, as :func:`phiscene.metrics.drift.drift_bullet`
releases a scene, but without the upward offset and with a stopping rule:
after every frame ``n >= w`` the paper's sliding-window criterion

    ||x_n - x_{n-w}|| < eps_pos   and   angle(r_n, r_{n-w}) < eps_rot

is tested for every object; the run stops at the first frame at which every
object meets it, or at ``max_frames``. There is no remedy stage (the
sequential method's damping ramp, :mod:`phiscene.assembly.settle`): a
baseline gets the plain criterion and the cap, and the log says which objects
had not settled.

:func:`joint_sdf_sim` chains :func:`~phiscene.baselines.joint_sdf.joint_sdf`
and :func:`joint_sim`.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.assembly.settle import window_motion
from phiscene.baselines.joint_sdf import JointSdfParams, joint_sdf
from phiscene.params import Params
from phiscene.proxies import Proxy, check_proxies, with_base
from phiscene.scene import Scene
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose

#: Format tag of the joint simulation log.
LOG_FORMAT = "phiscene.joint_sim_log/1"


@dataclass(frozen=True)
class JointSimParams(Params):
    """Stopping rule of the joint simulation (paper criterion values).

    Attributes
    ----------
    window
        Window length ``w`` in frames.
    eps_pos
        Translation threshold over a window (m).
    eps_rot
        Rotation threshold over a window (rad).
    max_frames
        Cap on simulated frames.
    """

    _label = "joint simulation parameters"

    window: int = 15
    eps_pos: float = 1e-4
    eps_rot: float = 1e-4
    max_frames: int = 240

    def check(self) -> None:
        """Reject ``window < 1`` and negative ``max_frames`` or thresholds (``ValueError``)."""
        if self.window < 1 or self.max_frames < 0 or self.eps_pos < 0 or self.eps_rot < 0:
            raise ValueError(f"joint simulation window must be >= 1, max_frames and thresholds >= 0: {self}")


@dataclass(frozen=True)
class JointSdfSimParams(Params):
    """Parameters of :func:`joint_sdf_sim`: the joint SDF solve, then the joint simulation.

    Attributes
    ----------
    sdf
        See :class:`~phiscene.baselines.joint_sdf.JointSdfParams`.
    sim
        See :class:`JointSimParams`.
    """

    _label = "joint SDF + simulation parameters"

    sdf: JointSdfParams = field(default_factory=JointSdfParams)
    sim: JointSimParams = field(default_factory=JointSimParams)


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def joint_sim(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, params: JointSimParams,
              cache_dir: str | Path) -> tuple[Scene, dict]:
    """Simulate all objects together until every one meets the window criterion (or the cap).

    Parameters
    ----------
    scene
        The scene to release (every object dynamic, but those ``attached`` to a wall or the ceiling: static).
    proxies
        Convex proxies by object id.
    sim
        Physical settings (density, friction, damping, frame time).
    params
        Window criterion and frame cap.
    cache_dir
        Folder for pybullet's hull files.

    Returns
    -------
    scene
        The scene at the last simulated frame.
    record
        JSON-ready log: ``format``, ``params``, ``sim``, ``frames``, ``all_settled``, ``unsettled`` (ids),
        ``objects`` (per id: ``settled`` (criterion met at the last frame), ``residual_translation`` m,
        ``residual_rotation`` rad (motion over the last window, ``None`` if fewer than ``w`` frames ran),
        ``displacement`` m, ``rotation_change`` rad; attached objects are left out), ``seconds``.

    Raises
    ------
    InputError
        An object has no proxy.
    """
    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld

    t0 = time.perf_counter()
    check_proxies(scene, proxies)
    ids = [o.id for o in scene.objects if o.attached is None]
    frames = 0
    with BulletWorld(sim, cache_dir) as world:
        world.add_ground(scene.ground_height)
        world.add_structure(scene.structure)  # walls and ceiling: static colliders
        for o in scene.objects:
            hulls = with_base(proxies[o.id], o.base).hulls  # its completed base: a piece of its collision shape
            world.add_body(o.id, hulls, o.pose, rigid_props(o.mesh(), hulls, sim.density, decompose(o.pose)[2],
                                                               o.com))
            if o.attached is not None:
                world.set_static(o.id)  # fixed to a wall or the ceiling: a collider, never released
        history = {oid: deque([world.pose(oid)], maxlen=params.window + 1) for oid in ids}
        motion = {oid: (float("inf"), float("inf")) for oid in ids}
        met = {oid: False for oid in ids}
        while frames < params.max_frames and not (ids and all(met.values())):
            world.step_frames(1)
            frames += 1
            for oid in ids:
                history[oid].append(world.pose(oid))
                if len(history[oid]) > params.window:
                    motion[oid] = window_motion(history[oid][0], history[oid][-1])
                dt, dr = motion[oid]
                met[oid] = dt < params.eps_pos and dr < params.eps_rot
        poses = {oid: world.pose(oid) for oid in ids}
    objects = {}
    for o in scene.objects:
        if o.attached is not None:
            continue
        moved, turned = window_motion(o.pose, poses[o.id])
        objects[o.id] = {"settled": met[o.id], "residual_translation": _finite(motion[o.id][0]),
                         "residual_rotation": _finite(motion[o.id][1]), "displacement": moved,
                         "rotation_change": turned}
    unsettled = [oid for oid in ids if not met[oid]]
    record = {"format": LOG_FORMAT, "params": params.to_dict(), "sim": sim.to_dict(), "frames": frames,
              "all_settled": not unsettled, "unsettled": unsettled, "objects": objects,
              "seconds": time.perf_counter() - t0}
    return scene.with_poses(poses), record


def joint_sdf_sim(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, params: JointSdfSimParams,
                  cache_dir: str | Path) -> tuple[Scene, dict]:
    """Joint SDF penetration resolution, then joint simulation (paper Tab. 6 "joint SDF + sim.").

    Parameters
    ----------
    scene
        The initial scene.
    proxies
        Convex proxies by object id.
    sim
        Physical settings of the simulation.
    params
        Both stages' parameters.
    cache_dir
        Cache root (SDF grids, hull OBJ files).

    Returns
    -------
    scene
        The simulated scene.
    record
        ``{"format", "sdf": joint_sdf log, "sim": joint_sim log, "seconds"}``.
    """
    t0 = time.perf_counter()
    check_proxies(scene, proxies)
    resolved, sdf_log = joint_sdf(scene, params.sdf, cache_dir)
    settled, sim_log = joint_sim(resolved, proxies, sim, params.sim, cache_dir)
    return settled, {"format": "phiscene.joint_sdf_sim_log/1", "sdf": sdf_log, "sim": sim_log,
                     "seconds": time.perf_counter() - t0}
