"""MuJoCo worlds built with ``mujoco.MjSpec`` for the cross-simulator drift check (paper Tab. 3).

This module builds, compiles and steps the worlds; the drift metric itself is
:func:`phiscene.metrics.drift.drift_mujoco`. The drift protocol is the one of the pybullet drift (paper supplement,
"Post-simulation stability"): every object is a free body, all dynamic
together; a ground plane is placed right below the scene (its top at the
lowest world z of the free objects' collision proxies, :func:`phiscene.scene.ground_below`); every object is
lifted by a small upward offset so that it settles down into contact; the world runs
``frames`` frames of ``SimSettings.frame_dt``; translation drift is the
distance between the final centre of mass and the original (pre-lift) one,
rotation drift the relative rotation angle in degrees; scene drift is the
mean over objects.

Bodies and mass properties
    One free body per object whose frame is the object's principal inertial
    frame (centre of mass, principal axes), like pybullet's COM frame. Each
    convex proxy is a mesh asset (vertices only: MuJoCo takes the convex hull
    of a mesh geom for collision), scaled by the pose's uniform scale. Mass,
    COM and principal moments are set explicitly from
    :func:`phiscene.inertia.rigid_props` at ``SimSettings.density``
    (``inertiafromgeom`` is off), so both engines share the same inertia.

Friction
    pybullet combines the friction of two bodies as the product
    ``f_a * f_b`` (Bullet's default rule), MuJoCo takes the maximum. To give
    both engines the same effective Coulomb coefficient every geom gets
    ``friction**2`` (0.64 for the default 0.8), which is what pybullet
    applies between any two phiscene bodies (see :func:`contact_friction`;
    a cube sliding down a 40 degree slope moves 0.188 m in 0.5 s in
    pybullet, 0.187 m in MuJoCo and 0.187 m by Coulomb's law with 0.64).

Damping
    Bullet scales velocities by ``(1 - damping) ** dt`` every step: an
    exponential decay at rate ``-ln(1 - damping)`` per second, independent
    of mass. MuJoCo's joint damping is a force ``-c * qvel`` per degree of
    freedom, so the same decay needs ``c = rate * mass`` on the three
    translational and ``c = rate * I_k`` on the three rotational degrees of
    freedom of each free joint (the body frame is the principal frame, so
    they decouple). An ``MjSpec`` joint holds one damping value, so the spec
    (and any exported MJCF) carries the translational value and
    :func:`compile_model` sets the exact per-DOF values on the model.

Contacts (see :class:`MujocoParams`)
    Margin 0 (a positive margin makes resting bodies float by the margin: a
    5 mm margin gives a two-box stack 15 mm of drift), near-hard impedance
    ``solimp = (0.95, 0.99, 1 mm)``, critically damped reference
    ``solref = (10 ms, 1)`` (restitution 0; the time constant is at least
    twice the step, MuJoCo's stability bound), the ``implicitfast``
    integrator, a converged Newton solver, elliptic friction cones with
    ``impratio = 10`` and 10 no-slip iterations. The resting penetration is
    about ``g (1 - d) / (d k)`` with ``k = 1 / (d_max * timeconst *
    dampratio) ** 2``: 5e-5 m, far below the drift scale. A box and a
    two-box stack stay at rest (drift ~3e-5 m) even with MuJoCo's default
    settings; what the friction settings buy is Coulomb sticking: a cube
    on a 25 degree slope (below atan(mu)) creeps 7 mm in 120 frames with
    MuJoCo's defaults, 0.1 mm without no-slip, 0.03 mm with these settings.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from phiscene.atomic import write_text
from phiscene.errors import InputError
from phiscene.inertia import RigidProps, rigid_props
from phiscene.params import Params
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import decompose, make_pose, matrix_to_quat_wxyz

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # heavy import only for type checkers
    import mujoco

    from phiscene.proxies import Proxy
    from phiscene.scene import Scene

#: Name of the ground geom (object ids may not use it).
GROUND_NAME = "ground"


@dataclass(frozen=True)
class MujocoParams(Params):
    """MuJoCo-specific contact and solver settings (what pybullet has no counterpart for).

    Attributes
    ----------
    timeconst
        Contact reference time constant ``solref[0]`` in seconds; raised to
        ``2 * timestep`` when smaller (MuJoCo's stability bound).
    dampratio
        Contact damping ratio ``solref[1]``; 1 is critically damped (restitution 0).
    solimp
        Contact impedance ``(d0, dwidth, width, midpoint, power)``: ``d`` rises
        from 0.95 at first touch to 0.99 at 1 mm penetration (near-hard contact).
    margin
        Geom contact margin (m). 0: contacts activate at touch, bodies rest on the surface.
    cone
        Friction cone, ``elliptic`` (exact Coulomb) or ``pyramidal``.
    impratio
        Ratio of frictional to normal constraint impedance (elliptic cones only); > 1 makes
        friction harder than the normal contact, so sliding follows Coulomb's law closely.
    integrator
        ``implicitfast``, ``implicit``, ``euler`` or ``rk4``.
    iterations
        Newton solver iterations per step.
    tolerance
        Solver tolerance.
    noslip_iterations
        Iterations of MuJoCo's no-slip post-solver (0: off). Soft frictional contacts creep
        slowly below the friction limit; no-slip removes most of that creep.
    """

    _label = "MuJoCo settings"
    _coerce = {"solimp": lambda v: tuple(float(x) for x in v)}

    timeconst: float = 0.01
    dampratio: float = 1.0
    solimp: tuple[float, float, float, float, float] = (0.95, 0.99, 0.001, 0.5, 2.0)
    margin: float = 0.0
    cone: str = "elliptic"
    impratio: float = 10.0
    integrator: str = "implicitfast"
    iterations: int = 100
    tolerance: float = 1e-10
    noslip_iterations: int = 10

    def check(self) -> None:
        """Reject a ``solimp`` without 5 values and unknown ``cone`` / ``integrator`` names (``ValueError``)."""
        if len(self.solimp) != 5:
            raise ValueError(f"solimp needs 5 values (d0, dwidth, width, midpoint, power), got {self.solimp}")
        if self.cone not in ("elliptic", "pyramidal"):
            raise ValueError(f"cone must be elliptic or pyramidal, got {self.cone!r}")
        if self.integrator not in ("implicitfast", "implicit", "euler", "rk4"):
            raise ValueError(f"integrator must be implicitfast, implicit, euler or rk4, got {self.integrator!r}")


# -- small helpers ----------------------------------------------------------------------
def _set_first(value, x: float):
    """Set a scalar spec field that is an array in some MuJoCo versions (e.g. joint damping in 4.x)."""
    if isinstance(value, np.ndarray):
        value[...] = 0.0
        value[0] = x
        return value
    return x


def damping_rate(damping: float) -> float:
    """Exponential decay rate (1/s) of Bullet's per-step velocity factor ``(1 - damping) ** dt``."""
    if not 0.0 <= damping < 1.0:
        raise ValueError(f"damping must be in [0, 1), got {damping}")
    return -math.log1p(-damping)


def contact_friction(sim: SimSettings) -> np.ndarray:
    """Per-geom ``(sliding, torsional, rolling)`` friction that reproduces pybullet's contact friction.

    Bullet combines two bodies' coefficients as ``f_a f_b`` (sliding) and
    ``r_a f_b + r_b f_a`` (rolling, spinning); MuJoCo takes the larger geom
    value. Every phiscene body has the same settings, so each geom gets the
    combined value. (Rolling and spinning coefficients are defined
    differently in the two engines; both are 0 by default.)

    Returns
    -------
    (3,) float
    """
    f = sim.friction
    return np.array([f * f, 2.0 * f * sim.spinning_friction, 2.0 * f * sim.rolling_friction], dtype=float)


def body_frame(pose: np.ndarray, props: RigidProps) -> np.ndarray:
    """World pose (4, 4, rigid) of an object's principal inertial frame.

    Parameters
    ----------
    pose : (4, 4) float
        Local-to-world pose (uniform scale allowed).
    props
        Mass properties at the pose's scale.
    """
    R, t, _ = decompose(pose)
    return make_pose(R, t) @ make_pose(props.principal_axes, props.com)


# -- building ---------------------------------------------------------------------------
def _option(spec: "mujoco.MjSpec", sim: SimSettings, mj: MujocoParams) -> None:
    import mujoco

    o = spec.option
    o.timestep = sim.frame_dt / sim.substeps
    o.gravity = [0.0, 0.0, -GRAVITY]
    o.integrator = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
                    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
                    "euler": mujoco.mjtIntegrator.mjINT_EULER,
                    "rk4": mujoco.mjtIntegrator.mjINT_RK4}[mj.integrator]
    o.cone = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}[mj.cone]
    o.impratio = mj.impratio
    o.iterations = mj.iterations
    o.tolerance = mj.tolerance
    o.noslip_iterations = mj.noslip_iterations
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE


def _contact(geom, sim: SimSettings, mj: MujocoParams, condim: int) -> None:
    timestep = sim.frame_dt / sim.substeps
    geom.friction = contact_friction(sim)
    geom.condim = condim
    geom.margin = mj.margin
    geom.gap = 0.0
    geom.solref = [max(mj.timeconst, 2.0 * timestep), mj.dampratio]
    geom.solimp = list(mj.solimp)


def _frame_with_z(z: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose third column is the unit vector ``z`` (a MuJoCo plane's normal is its local z)."""
    z = np.asarray(z, dtype=float) / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def build_spec(scene: "Scene", proxies: dict[str, "Proxy"], sim: SimSettings, ground_height: float,
               mj: MujocoParams | None = None) -> "mujoco.MjSpec":
    """A MuJoCo model spec of the scene at its current poses, above a ground plane.

    Parameters
    ----------
    scene
        Objects and poses (local-to-world, uniform scale allowed).
    proxies
        Convex proxies by object id (unscaled local hull vertices).
    sim
        Shared simulation settings (time step, friction, damping, density).
    ground_height
        z of the ground plane (m).
    mj
        MuJoCo contact and solver settings (defaults: :class:`MujocoParams`).

    Returns
    -------
    An uncompiled ``mujoco.MjSpec``: one free body per object named by its id
    (frame = principal inertial frame), mesh geoms ``<id>/hull<k>``, a plane ``ground`` and one plane
    per wall or ceiling of ``scene.structure`` named by its id.
    """
    import mujoco

    from phiscene.proxies import with_base

    mj = mj or MujocoParams()
    if not scene.objects:
        raise InputError(scene.source, "objects", "scene has no objects")
    spec = mujoco.MjSpec()
    spec.modelname = "phiscene"
    _option(spec, sim, mj)
    condim = 6 if sim.rolling_friction > 0 else 4 if sim.spinning_friction > 0 else 3

    ground = spec.worldbody.add_geom()
    ground.name = GROUND_NAME
    ground.type = mujoco.mjtGeom.mjGEOM_PLANE
    ground.size = [0.0, 0.0, 1.0]  # infinite plane
    ground.pos = [0.0, 0.0, float(ground_height)]
    _contact(ground, sim, mj, condim)
    for plane in scene.structure:  # walls and ceiling: static half-spaces, solid behind the plane
        n = np.asarray(plane.normal, dtype=float)
        wall = spec.worldbody.add_geom()
        wall.name = plane.id
        wall.type = mujoco.mjtGeom.mjGEOM_PLANE
        wall.size = [0.0, 0.0, 1.0]
        wall.pos = -float(plane.offset) * n
        wall.quat = matrix_to_quat_wxyz(_frame_with_z(n))
        _contact(wall, sim, mj, condim)

    lin_rate = damping_rate(sim.linear_damping)
    for i, o in enumerate(scene.objects):
        where = f"objects[{i}]"
        if o.id == GROUND_NAME:
            raise InputError(scene.source, f"{where}.id", f"{GROUND_NAME!r} is reserved")
        proxy = proxies.get(o.id)
        if proxy is None or not proxy.hulls:
            raise InputError(scene.source, f"{where}.id", f"no convex proxies for object {o.id!r}")
        proxy = with_base(proxy, o.base)  # its completed base, a piece of its collision shape
        _, _, scale = decompose(o.pose)
        props = rigid_props(o.mesh(), proxy.hulls, sim.density, scale, o.com)
        frame = body_frame(o.pose, props)
        body = spec.worldbody.add_body()
        body.name = o.id
        body.pos = frame[:3, 3]
        body.quat = matrix_to_quat_wxyz(frame[:3, :3])
        body.mass = props.mass
        body.ipos = [0.0, 0.0, 0.0]
        body.iquat = [1.0, 0.0, 0.0, 0.0]
        body.inertia = props.principal_moments
        body.explicitinertial = True
        if o.attached is None:  # attached objects are welded to the world (no joint)
            joint = body.add_freejoint()
            joint.name = f"{o.id}/free"
            joint.damping = _set_first(joint.damping, lin_rate * props.mass)
        # object link frame seen from the body (principal) frame; hulls are link-frame vertices times scale
        link = make_pose(props.principal_axes.T, -props.principal_axes.T @ props.com)
        for k, hull in enumerate(proxy.hulls):
            mesh = spec.add_mesh()
            mesh.name = f"{o.id}/hull{k}"
            mesh.uservert = np.asarray(hull, dtype=float).ravel()
            mesh.scale = [scale] * 3
            mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
            geom = body.add_geom()
            geom.name = f"{o.id}/hull{k}"
            geom.type = mujoco.mjtGeom.mjGEOM_MESH
            geom.meshname = mesh.name
            geom.pos = link[:3, 3]
            geom.quat = matrix_to_quat_wxyz(link[:3, :3])
            _contact(geom, sim, mj, condim)
    return spec


def _log_warning(message: str) -> None:
    log.warning("MuJoCo: %s", " ".join(str(message).split()))


def route_warnings() -> None:
    """Send MuJoCo's own warnings (an arena too small, :class:`ArenaFull`) to the ``phiscene.sim.mujoco`` logger
    (the job's log) instead of stderr and a ``MUJOCO_LOG.TXT`` written into the working directory."""
    import mujoco

    if mujoco.get_mju_user_warning() is not _log_warning:
        mujoco.set_mju_user_warning(_log_warning)


def compile_model(spec: "mujoco.MjSpec", sim: SimSettings) -> "mujoco.MjModel":
    """Compile ``spec`` and set Bullet-equivalent damping on every free joint's six DOFs.

    Translational DOFs get ``rate * mass``, rotational ones ``rate * I_k``
    (principal moments: body frames are principal frames), with ``rate`` from
    :func:`damping_rate`.
    """
    import mujoco

    route_warnings()
    try:
        model = spec.compile()
    except ValueError as exc:  # MuJoCo names the offending element, e.g. mesh '<id>/hull<k>'
        raise RuntimeError(f"MuJoCo could not compile the scene: {' '.join(str(exc).split())}") from None
    lin, ang = damping_rate(sim.linear_damping), damping_rate(sim.angular_damping)
    for j in range(model.njnt):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            continue
        b, d = model.jnt_bodyid[j], model.jnt_dofadr[j]
        model.dof_damping[d:d + 3] = lin * model.body_mass[b]
        model.dof_damping[d + 3:d + 6] = ang * model.body_inertia[b]
    return model


def step_frames(model: "mujoco.MjModel", data: "mujoco.MjData", frames: int, sim: SimSettings) -> None:
    """Advance ``frames`` frames of ``sim.frame_dt`` (``sim.substeps`` MuJoCo steps each).

    Raises
    ------
    RuntimeError
        When MuJoCo reported a divergence (it then silently resets the state,
        which would read as zero drift) or ran out of contact/constraint memory.
    """
    import mujoco

    mujoco.mj_step(model, data, nstep=int(frames) * sim.substeps)
    check_warnings(data)


#: MuJoCo warnings that invalidate a simulation result.
_FATAL_WARNINGS = {
    "mjWARN_BADQACC": "the simulation diverged (bad acceleration) and MuJoCo reset the state",
    "mjWARN_BADQPOS": "a position became NaN or huge and MuJoCo reset the state",
    "mjWARN_BADQVEL": "a velocity became NaN or huge and MuJoCo reset the state",
    "mjWARN_CONTACTFULL": "the contact buffer is full (contacts were dropped)",
    "mjWARN_CNSTRFULL": "the constraint buffer is full (constraints were dropped)",
}


#: Of those, the ones that say the arena (``<size memory>``, ``MjSpec.memory``) was too small: :class:`ArenaFull`.
_ARENA_WARNINGS = ("mjWARN_CONTACTFULL", "mjWARN_CNSTRFULL")


class ArenaFull(RuntimeError):
    """MuJoCo's arena held too few contacts or constraints for the scene (they were dropped, or its stack
    overflowed): the same simulation with a larger ``MjSpec.memory`` is valid."""


def check_warnings(data: "mujoco.MjData") -> None:
    """Raise ``RuntimeError`` if MuJoCo flagged a warning that invalidates the result (:class:`ArenaFull` for
    contacts or constraints dropped)."""
    import mujoco

    for name, why in _FATAL_WARNINGS.items():
        w = data.warning[int(getattr(mujoco.mjtWarning, name))]
        if w.number > 0:
            kind = ArenaFull if name in _ARENA_WARNINGS else RuntimeError
            raise kind(f"MuJoCo: {why} ({name} x{w.number}, first at step info {w.lastinfo})")


def body_poses(model: "mujoco.MjModel", data: "mujoco.MjData", names: list[str]) -> dict[str, np.ndarray]:
    """World poses (4, 4, rigid) of the named bodies' frames (= centre-of-mass principal frames)."""
    import mujoco

    out = {}
    for name in names:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        out[name] = make_pose(data.xmat[b].reshape(3, 3).copy(), data.xpos[b].copy())
    return out


def write_mjcf(spec: "mujoco.MjSpec", path: str | Path) -> Path:
    """Write the spec as MJCF XML (``spec.to_xml()``, meshes inline) atomically; return the path.

    MuJoCo's XML writer prints 6 significant digits, so positions, quaternions
    and the time step are rounded to about 1e-6 relative. The free joints carry
    the translational damping only (per-DOF damping lives on the compiled model,
    see :func:`compile_model`).
    """
    path = Path(path)
    write_text(path, spec.to_xml())
    return path
