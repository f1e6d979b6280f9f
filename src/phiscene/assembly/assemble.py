"""The sequential physical assembly loop (paper §3.1): for each object in topological order,
SDF penetration resolution against the settled context and the ground, then rigid settling, then freeze.

One :class:`~phiscene.sim.bullet.BulletWorld` is built per scene: the ground
box first, then each object is added when its turn comes (dynamic), settled
and frozen in place (:meth:`~phiscene.sim.bullet.BulletWorld.set_static`).
So the active object only ever meets the ground and the objects placed before
it, exactly the paper's pre-settled support context; objects not yet placed
are not in the world.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.assembly import faithful as fa
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.penetration import (
    PenetrationParams,
    SdfBody,
    resolve_penetration,
    sdf_body,
    vertical_clearance,
)
from phiscene.assembly.settle import (
    SettleParams,
    clear_overlaps,
    close_gaps,
    gives_way,
    holds_when_tilted,
    load_carriers,
    settle_object,
    window_motion,
)
from phiscene.errors import InputError
from phiscene.meshes import sample_surface
from phiscene.params import Params
from phiscene.proxies import Proxy, check_proxies, with_base, with_bases
from phiscene.scene import Scene
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, transform_points

log = logging.getLogger(__name__)

#: Format tag of the assembly log.
LOG_FORMAT = "phiscene.assembly_log/1"
#: When no start is accepted, at most this many fallback results are tilt-tested, in rank order, for one that holds.
FALLBACK_TILTS = 4


@dataclass(frozen=True)
class AssemblyParams(Params):
    """Settings of the assembly; the two switches give the paper's ablations.

    Attributes
    ----------
    penetration
        Run SDF penetration resolution (off: "sim only").
    settle
        Run rigid settling (off: "SDF only").
    penetration_params
        See :class:`~phiscene.assembly.penetration.PenetrationParams`.
    settle_params
        See :class:`~phiscene.assembly.settle.SettleParams`.
    faithful
        See :class:`~phiscene.assembly.faithful.FaithfulParams` (off: the paper's loop exactly).
    """

    _label = "assembly parameters"

    penetration: bool = True
    settle: bool = True
    penetration_params: PenetrationParams = field(default_factory=PenetrationParams)
    settle_params: SettleParams = field(default_factory=SettleParams)
    faithful: FaithfulParams = field(default_factory=FaithfulParams)

    def check(self) -> None:
        """Reject ``penetration`` / ``settle`` switches that are not booleans (``ValueError``)."""
        for key in ("penetration", "settle"):
            if not isinstance(getattr(self, key), bool):
                raise ValueError(f"assembly parameter {key!r} must be true or false, got {getattr(self, key)!r}")


def full_order(scene: Scene, order: list[str]) -> tuple[list[str], list[str]]:
    """Validate a placement order and append the scene objects it misses (in scene order).

    ``ground`` entries are ignored.

    Returns
    -------
    order
        Every object id exactly once.
    appended
        The ids that were missing from ``order``.

    Raises
    ------
    InputError
        Unknown or repeated ids (field ``order``).
    """
    ids = scene.ids
    given = [o for o in order if o != "ground"]
    unknown = sorted(set(given) - set(ids))
    if unknown:
        raise InputError(scene.source, "order", f"ids not in the scene: {unknown}")
    repeated = sorted({o for o in given if given.count(o) > 1})
    if repeated:
        raise InputError(scene.source, "order", f"ids listed more than once: {repeated}")
    appended = [o for o in ids if o not in set(given)]
    return given + appended, appended


def _round(v, digits: int = 9) -> float | None:
    """``v`` rounded for the log; ``None`` for missing or non-finite values (JSON has no NaN)."""
    return None if v is None or not np.isfinite(v) else float(round(float(v), digits))


def ground_scene(scene: Scene, order: list[str], proxies: dict[str, Proxy], params: AssemblyParams,
                 sim: SimSettings, cache_dir: Path, progress: Callable[[str], None] | None = None,
                 graph=None, attached: dict[str, str] | None = None,
                 eye: np.ndarray | None = None,
                 visible: Callable[[], dict[str, float]] | None = None) -> tuple[Scene, dict]:
    """Physically ground a scene by topology-ordered penetration resolution and settling.

    Parameters
    ----------
    scene
        The initial scene.
    order
        Placement order (supporters first); missing objects are appended (logged).
    proxies
        Convex proxies per object id (needed when ``params.settle``).
    params
        Assembly settings.
    sim
        Physical settings of the settling world (density for masses, friction, damping, frame time).
    cache_dir
        Cache root (SDF grids, hull OBJ files).
    progress
        Called with one line per object.
    attached
        Objects fixed in place (id -> what holds them, :attr:`phiscene.scene.SceneObject.attached`): placed first,
        static at their input pose (never moved, settled or dropped), context for the others; the result
        carries the attachment.
    graph
        The support graph (:class:`~phiscene.topology.graph.SupportGraph`) whose supporters the faithful
        variant keeps; without it every object is taken to stand on the ground.
    eye : (3,) float, optional
        The photo's camera centre in the scene's frame, for the faithful remedy ``ray``
        (:func:`~phiscene.assembly.faithful.ray_corrected`; skipped without it).
    visible
        Returns object id -> share of it the photo's camera sees in the input
        (:func:`phiscene.render.visible_shares`), for the faithful remedy ``hidden``
        (``FaithfulParams.hidden_share``; skipped without it); called once, when the first object reaches that
        remedy (most scenes never do). An object it keeps is added to the attachments (to the ground) and listed
        in the summary under ``hidden``.

    Returns
    -------
    scene
        The grounded scene (only poses differ).
    record
        Assembly log (JSON-ready): ``order``, ``appended``, ``params``, ``sim``, per-object entries under
        ``objects`` (``sdf_iterations``, ``sdf_initial_loss``, ``sdf_final_loss``, ``sdf_translation`` (3,),
        ``sdf_context``, ``sdf_grid_error`` (max grid error near the surface, m), ``settle_frames``,
        ``settled``, ``settle_remedy``, ``residual_translation``, ``residual_rotation``,
        ``settle_translation``, ``settle_rotation``, ``displacement``, ``rotation_change``, ``seconds`` per
        stage) and a ``summary``; with ``params.faithful.enabled`` also ``flush_angle`` (and ``ray_shift``, m,
        with ``ray`` and ``eye``) and a
        ``certificate`` per object (:func:`~phiscene.assembly.faithful.certificate`), and the summary lists the
        lost supporters, the remedies, the objects not stable in the final release (``joint_unstable``) and
        those that end a gross failure from their input (``gross``: id -> what happened,
        :func:`~phiscene.assembly.faithful.gross_failures`; also logged as a warning and a progress line).
    """
    from phiscene.sim.bullet import BulletWorld

    t_start = time.perf_counter()
    order, appended = full_order(scene, order)
    shares = functools.cache(visible) if visible is not None else None
    attached = dict(attached or {})
    order = [o for o in order if o in attached] + [o for o in order if o not in attached]
    if appended:
        log.warning("objects not in the placement order, appended at the end: %s", ", ".join(appended))
    if params.settle:
        check_proxies(scene, proxies, order)
    proxies = with_bases(scene, proxies)  # the input's completed bases, pieces of the collision shapes
    pp = params.penetration_params
    poses: dict[str, np.ndarray] = {}
    placed: list[SdfBody] = []
    objects: dict[str, dict] = {}
    coms: dict[str, np.ndarray] = {}  # faithful: centre of mass per object, local frame
    # declared centres of mass (the input's, and the remedy ballast's), local frame
    masses: dict[str, np.ndarray] = {o.id: np.asarray(o.com, dtype=float) for o in scene.objects if o.com is not None}
    # completed bases (the input's, and the remedy base's), local frame
    bases: dict[str, np.ndarray] = {o.id: np.asarray(o.base, dtype=float) for o in scene.objects if o.base is not None}
    surfaces: dict[str, np.ndarray] = {}  # faithful: upward surface samples per placed object (remedy onto)
    world_meshes: dict[str, object] = {}  # faithful: placed supporters' meshes at their grounded poses
    world_cm = BulletWorld(sim, cache_dir) if params.settle else contextlib.nullcontext()
    with world_cm as world:
        if params.settle:
            world.add_ground(scene.ground_height)
            world.add_structure(scene.structure)  # walls and ceiling: static colliders
        for index, oid in enumerate(order):
            obj = scene.get(oid)
            initial = np.asarray(obj.pose, dtype=float)
            pose = initial.copy()
            rec: dict = {"index": index, "seconds": {}}

            if oid in attached:
                if params.faithful.enabled and params.faithful.flush:
                    pose = _flush_attached(scene, oid, obj, proxies.get(oid), attached[oid],
                                           params.faithful.max_flush_angle, cache_dir, rec)
                _fix(world if params.settle else None, oid, obj.mesh(), proxies.get(oid), pose, sim, rec,
                     masses.get(oid))
                total, turned = window_motion(initial, pose)
                rec.update(displacement=_round(total), rotation_change=_round(turned))
                poses[oid] = pose
                if params.penetration:
                    placed.append(sdf_body(oid, obj.mesh(), pose, pp.n_context, pp, cache_dir))
                objects[oid] = rec
                if progress is not None:
                    progress(f"[{index + 1}/{len(order)}] {oid}: attached to {attached[oid]}, kept in place")
                continue

            fp = params.faithful
            info = None
            if fp.enabled:
                t0 = time.perf_counter()
                pose, info = _faithful_start(scene, oid, proxies.get(oid), graph, poses, world_meshes, surfaces,
                                             attached, fp, pp.seed, cache_dir, rec, eye)
                info.update(visible=None if shares is None else (lambda o=oid: shares().get(o)), input=initial)
                rec["seconds"]["flush"] = time.perf_counter() - t0

            t0 = time.perf_counter()
            if params.penetration:
                if info is not None:
                    pose = _resolve_faithful(scene, oid, pose, placed, poses, world_meshes, pp, fp, cache_dir, rec,
                                             info)
                else:
                    pose = _resolve(oid, obj.mesh(), pose, placed, scene.ground_height, pp, cache_dir, rec,
                                    scene.structure)
            else:
                rec.update(sdf_iterations=0, sdf_initial_loss=None, sdf_final_loss=None,
                           sdf_translation=[0.0, 0.0, 0.0], sdf_context=[], sdf_grid_error=None)
            rec["seconds"]["sdf"] = time.perf_counter() - t0

            t0 = time.perf_counter()
            if params.settle and info is not None:
                pose = _settle_faithful(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params,
                                        fp, info, rec, masses.get(oid))
                _kept(masses, bases, oid, rec, obj)
                if rec["settle_remedy"] == "hidden":  # static where it was put from now on, as if attached
                    attached[oid] = "ground"
                    log.warning("%s: no start held it and %.0f %% of it is visible in the photo: kept where it "
                                "was put, static", oid, 100 * rec["visible_share"])
            elif params.settle:
                pose = _settle(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params, rec,
                               masses.get(oid))
            else:
                rec.update(settle_frames=0, settled=None, settle_remedy=None, residual_translation=None,
                           residual_rotation=None, settle_translation=0.0, settle_rotation=0.0)
            rec["seconds"]["settle"] = time.perf_counter() - t0

            t0 = time.perf_counter()
            poses[oid] = pose
            if params.penetration:
                placed.append(sdf_body(oid, obj.mesh(), pose, pp.n_context, pp, cache_dir))
            rec["seconds"]["context"] = time.perf_counter() - t0
            total, turned = window_motion(initial, pose)
            rec.update(displacement=_round(total), rotation_change=_round(turned))
            if info is not None:
                moved = float(np.linalg.norm(fa.com_world(pose, info["com"]) - fa.com_world(initial, info["com"])))
                coms[oid] = info["com"]
                rec["certificate"] = fa.certificate(
                    rec["settled"], rec["settle_remedy"] or "none", info["below"], info["leaning"],
                    rec.get("touching", []),
                    moved, np.degrees(turned), info["flush_angle"], rec.get("reason", ""))
            rec["seconds"] = {k: _round(v, 6) for k, v in rec["seconds"].items()}
            objects[oid] = rec
            if progress is not None:
                progress(_progress_line(index, len(order), oid, rec))
    if params.faithful.enabled and params.settle and params.faithful.joint_settle_frames > 0:
        poses = _joint_settle(_as_grounded(scene.with_poses(poses), attached, masses, bases), proxies, sim,
                              cache_dir, params.faithful, params.settle_params, objects, coms,
                              {o: np.asarray(scene.get(o).pose, float) for o in order})
        if params.faithful.reground:
            poses = _reground_collapsed(scene, order, proxies, params, sim, cache_dir, graph, attached, poses,
                                        objects, coms, masses, bases, progress, eye)
    if params.faithful.enabled and params.settle and params.faithful.joint_frames > 0:
        _joint_check(_as_grounded(scene.with_poses(poses), attached, masses, bases), proxies, sim, cache_dir,
                     params.faithful, objects)
    unsettled = [o for o, r in objects.items() if r["settled"] is False]
    summary = {"objects": len(order), "settled": sum(r["settled"] is True for r in objects.values()),
               "unsettled": unsettled,
               "sdf_iterations": int(sum(r["sdf_iterations"] for r in objects.values())),
               "settle_frames": int(sum(r["settle_frames"] for r in objects.values())),
               "seconds": _round(time.perf_counter() - t_start, 6)}
    certs = {o: r["certificate"] for o, r in objects.items() if "certificate" in r}
    if certs:
        summary["supporters_lost"] = {o: c["lost"] for o, c in certs.items() if c["lost"]}
        summary["remedies"] = {o: c["remedy"] for o, c in certs.items() if c["remedy"] != "none"}
        summary["joint_unstable"] = [o for o, c in certs.items() if c.get("joint_stable") is False]
        summary["gross"] = fa.gross_failures(certs, params.faithful)
        summary["hidden"] = sorted(o for o, r in objects.items() if r.get("settle_remedy") == "hidden")
        for oid, what in summary["gross"].items():
            log.warning("%s ends far from its input: %s", oid, what)
            if progress is not None:
                progress(f"far from its input: {oid} {what}")
    if unsettled:
        log.warning("objects that did not meet the settling criterion: %s", ", ".join(unsettled))
    summary["attached"] = sorted(attached)
    record = {"format": LOG_FORMAT, "order": order, "appended": appended, "params": params.to_dict(),
              "sim": sim.to_dict(), "objects": objects, "summary": summary}
    return _as_grounded(scene.with_poses(poses), attached, masses, bases), record


def _flush_attached(scene: Scene, oid: str, obj, proxy: Proxy | None, holder: str, max_angle_deg: float,
                    cache_dir: Path, rec: dict) -> np.ndarray:
    """The pose (4, 4) of an attached object made flush with the wall or ceiling holding it
    (:func:`~phiscene.assembly.faithful.flush_attached`; its input pose when the holder is not a plane of
    ``scene.structure``, the ground standing for an unknown wall, or is an estimated one, which is where the
    objects it comes from are), then lifted out of the floor when its mesh
    reaches at most ``ATTACH_REACH`` below it (a floor-length curtain a depth error pushed through the floor;
    lifting it slides it along its wall). Fills ``rec`` (``flush_angle`` deg, ``attach_shift`` m,
    ``attach_lift`` m)."""
    pose = np.asarray(obj.pose, dtype=float)
    plane = next((q for q in scene.structure if q.id == holder and not q.estimated), None)
    out = pose if plane is None else _flushed_on(plane, obj, proxy, pose, max_angle_deg, cache_dir, rec)
    below = scene.ground_height - float(transform_points(out, np.asarray(obj.mesh().vertices))[:, 2].min())
    lift = below if 0.0 < below <= fa.ATTACH_REACH else 0.0
    if lift:
        out = out.copy()
        out[2, 3] += lift
    rec["attach_lift"] = _round(lift)
    return out


def _shape_points(proxy: Proxy | None, mesh) -> np.ndarray:
    """The vertices (n, 3), local, of an object's collision shape: its convex pieces', else its mesh's."""
    return np.vstack(proxy.hulls) if proxy is not None and proxy.hulls else np.asarray(mesh.vertices)


def _flushed_on(plane, obj, proxy: Proxy | None, pose: np.ndarray, max_angle_deg: float, cache_dir: Path,
                rec: dict) -> np.ndarray:
    """``pose`` made flush with ``plane`` (:func:`~phiscene.assembly.faithful.flush_attached`); fills ``rec``."""
    import trimesh

    hull = trimesh.convex.convex_hull(_shape_points(proxy, obj.mesh()))
    normals = _resting_normals(hull.vertices, cache_dir)
    out, angle, shift = fa.flush_attached(pose, normals, np.asarray(hull.center_mass), hull.vertices,
                                          np.asarray(plane.normal, dtype=float), plane.offset, plane.kind == "wall",
                                          max_angle_deg)
    rec.update(flush_angle=_round(angle), attach_shift=_round(shift))
    return out


def _faithful_start(scene: Scene, oid: str, proxy: Proxy | None, graph, poses: dict[str, np.ndarray],
                    world_meshes: dict[str, object], surfaces: dict[str, np.ndarray], attached: dict[str, str],
                    fp: FaithfulParams, seed: int, cache_dir: Path, rec: dict,
                    eye: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """The faithful variant's start for ``oid`` among the placed objects ``poses`` (id -> (4, 4)): its input pose
    carried with its supporter, moved along the camera ray from ``eye`` (remedy ``ray``, when on and ``eye`` is
    given) and turned flush onto it, and what the later stages need
    (:func:`_faithful_info`, with ``surfaces`` and ``fixed``). ``world_meshes`` and ``surfaces`` are per-id caches
    shared between calls on the same placed poses. Fills ``rec`` (``carried_by``, ``flush_angle``)."""
    obj = scene.get(oid)
    pose = np.asarray(obj.pose, dtype=float).copy()
    info = _faithful_info(scene, oid, obj, proxy, graph, poses, world_meshes, cache_dir)
    info["surfaces"] = lambda names: _surfaces(scene, poses, names, seed, surfaces)
    info["fixed"] = set(attached)  # static for good: never released under a load
    carrier = next((q for q in info["below"] if q in poses), None)
    if fp.carry and carrier is not None:
        pose = fa.carried(pose, info["com"], np.asarray(scene.get(carrier).pose, float), poses[carrier])
        rec["carried_by"] = carrier
    if fp.ray and eye is not None and info["below"] and not info["leaning"]:
        pose, shift = fa.ray_corrected(pose, info["points"], info["com"], info["below_world"], scene.ground_height,
                                       eye, fp)
        rec["ray_shift"] = _round(shift)
    if fp.flush and info["flushable"]:
        turned, info["flush_angle"] = fa.flush_pose(pose, info["normals"], info["com"], info["up"],
                                                    fp.max_flush_angle)
        info["flush_rotation"] = decompose(turned)[0] @ decompose(pose)[0].T  # world frame, about the centre of mass
        pose = turned
    rec["flush_angle"] = _round(info["flush_angle"])
    return pose, info


def _add_static(world, oid: str, mesh, proxy: Proxy, pose: np.ndarray, sim: SimSettings,
                com: np.ndarray | None = None) -> None:
    """``oid`` as a static collider at ``pose`` in ``world`` (its mass properties, with its declared centre of
    mass ``com`` (3,) local when it has one, kept for a later release)."""
    from phiscene.inertia import rigid_props

    world.add_body(oid, proxy.hulls, pose, rigid_props(mesh, proxy.hulls, sim.density, decompose(pose)[2], com))
    world.set_static(oid)


def _fix(world, oid: str, mesh, proxy: Proxy | None, pose: np.ndarray, sim: SimSettings, rec: dict,
         com: np.ndarray | None = None) -> None:
    """An attached object: a static collider at ``pose`` (when settling); fills ``rec``."""
    if world is not None:
        _add_static(world, oid, mesh, proxy, pose, sim, com)
    rec.update(sdf_iterations=0, sdf_initial_loss=None, sdf_final_loss=None, sdf_translation=[0.0, 0.0, 0.0],
               sdf_context=[], sdf_grid_error=None, settle_frames=0, settled=True, settle_remedy="attached",
               residual_translation=0.0, residual_rotation=0.0, settle_translation=0.0, settle_rotation=0.0)


def _resolve(oid: str, mesh, pose: np.ndarray, placed: list[SdfBody], ground_height: float,
             pp: PenetrationParams, cache_dir: Path, rec: dict, planes=(), planar: bool = False,
             yaw_only: bool = False) -> np.ndarray:
    """SDF stage: the pose (4, 4) moved clear of ``placed``, the ground and ``planes``; fills ``rec``.

    ``planar``: pushed out of ``placed`` horizontally only (an object standing on the floor alone);
    ``yaw_only``: the rotation solve (``pp.rotate_over``) turns it about the vertical only.
    """
    active = sdf_body(oid, mesh, pose, pp.n_active, pp, cache_dir)
    x, info = resolve_penetration(active, placed, ground_height, pp, planes, planar, yaw_only)
    rec.update(sdf_planar=planar, sdf_iterations=info["iterations"], sdf_initial_loss=_round(info["initial_loss"]),
               sdf_final_loss=_round(info["final_loss"]), sdf_searched=info["searched"],
               sdf_translation=[_round(v) for v in x], sdf_rotation=[_round(v) for v in info["rotation"]],
               sdf_context=info["context"],
               sdf_grid_error=_round(active.scale * active.grid.error.get("max_abs", float("nan"))))
    out = turned_about(pose, np.asarray(info["rotation"]), np.asarray(info["pivot"]))
    out[:3, 3] += x
    return out


def _resolve_faithful(scene: Scene, oid: str, pose: np.ndarray, placed: list[SdfBody],
                      poses: dict[str, np.ndarray], world_meshes: dict[str, object], pp: PenetrationParams,
                      fp: FaithfulParams, cache_dir: Path, rec: dict, info: dict) -> np.ndarray:
    """The faithful variant's SDF stage: :func:`_resolve`, horizontally only for an object on the floor alone
    (:func:`_on_the_floor`), lifted straight up instead where that is much shorter, at most ``max_shift``, and
    leaves it resting on placed objects (``FaithfulParams.floor_lift``: ``info["below"]`` becomes those objects,
    ``rec["sdf_lifted"]`` says so). ``poses`` are the placed objects' (id -> (4, 4)), ``world_meshes`` a cache
    of their world meshes."""
    mesh = scene.get(oid).mesh()
    planar = _on_the_floor(mesh, pose, info, scene.ground_height, fp.planar_floor)
    out = _resolve(oid, mesh, pose, placed, scene.ground_height, pp, cache_dir, rec, scene.structure, planar,
                   yaw_only=bool(info["below"]))
    pushed = float(np.linalg.norm(out[:3, 3] - pose[:3, 3])) if rec["sdf_final_loss"] == 0.0 else math.inf
    if not planar or fp.floor_lift <= 0 or pushed <= fp.max_slide:
        return out
    active = sdf_body(oid, mesh, pose, pp.n_active, pp, cache_dir)
    lift = vertical_clearance(active, placed, scene.ground_height, pp, scene.structure,
                              min(fp.floor_lift * pushed, fp.max_shift, pp.search_reach))
    if lift is None:
        return out
    lifted = pose.copy()
    lifted[2, 3] += lift
    near = {q: _placed_mesh(scene, q, poses, world_meshes) for q in rec["sdf_context"] if q in poses}
    bottom = np.vstack([info["points"], sample_surface(mesh, fa.RESTING_SAMPLES, pp.seed)])
    holders = fa.resting_on(transform_points(lifted, bottom), fa.com_world(lifted, info["com"]), near,
                            scene.ground_height, pp.eps + fp.contact_tol)
    if not holders:
        return out
    rec["sdf_lifted"] = {"onto": holders, "planar_translation": [_round(v) for v in out[:3, 3] - pose[:3, 3]]}
    rec.update(sdf_planar=False, sdf_final_loss=0.0, sdf_translation=[0.0, 0.0, _round(lift)],
               sdf_rotation=[0.0, 0.0, 0.0])
    info["below"] = holders
    info["below_world"] = {q: near[q] for q in holders}
    return lifted


def _placed_mesh(scene: Scene, oid: str, poses: dict[str, np.ndarray], world_meshes: dict[str, object]):
    """The world mesh (trimesh) of the placed object ``oid`` at its pose in ``poses``, kept in ``world_meshes``
    (id -> mesh) so that its spatial index is built once per placed pose."""
    if oid not in world_meshes:
        world_meshes[oid] = scene.get(oid).mesh().copy().apply_transform(poses[oid])
    return world_meshes[oid]


def turned_about(pose: np.ndarray, rotvec: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """``pose`` (4, 4) turned by the rotation vector ``rotvec`` (3,, rad) about the world point ``pivot`` (3,)."""
    from scipy.spatial.transform import Rotation

    if not np.any(rotvec):
        return pose.copy()
    R = Rotation.from_rotvec(rotvec).as_matrix()
    turn = np.eye(4)
    turn[:3, :3] = R
    turn[:3, 3] = pivot - R @ pivot
    return turn @ pose


def _on_the_floor(mesh, pose: np.ndarray, info: dict, ground_height: float, reach: float) -> bool:
    """Whether an object stands on the floor alone: the ground is its only supporter from below, it leans on
    nothing, and its lowest point (at ``pose`` (4, 4)) is at most ``reach`` (m) above the ground
    (``FaithfulParams.planar_floor``)."""
    if reach <= 0 or info["below"] != ["ground"] or info["leaning"]:
        return False
    return float(transform_points(pose, np.asarray(mesh.vertices))[:, 2].min()) - ground_height <= reach


def _settle(world, oid: str, mesh, proxy: Proxy, pose: np.ndarray, sim: SimSettings, sp: SettleParams,
            rec: dict, com: np.ndarray | None = None) -> np.ndarray:
    """Settling stage: add ``oid`` dynamic at ``pose`` (with its declared centre of mass ``com`` (3,) local, if
    any), settle it, freeze it; fills ``rec``; returns its pose."""
    from phiscene.inertia import rigid_props

    props = rigid_props(mesh, proxy.hulls, sim.density, decompose(pose)[2], com)
    world.add_body(oid, proxy.hulls, pose, props)
    result = settle_object(world, oid, sp)
    world.set_static(oid)
    moved, turned = window_motion(pose, result.pose)
    rec.update(settle_frames=result.frames, settled=result.settled, settle_remedy=result.remedy,
               residual_translation=_round(result.residual_translation, 12),
               residual_rotation=_round(result.residual_rotation, 12),
               settle_translation=_round(moved), settle_rotation=_round(turned))
    return result.pose


def _progress_line(index: int, n: int, oid: str, rec: dict) -> str:
    parts = [f"[{index + 1}/{n}] {oid}:"]
    if rec["sdf_final_loss"] is not None:
        shift = float(np.linalg.norm(rec["sdf_translation"]))
        parts.append(f"sdf {rec['sdf_iterations']} it, loss {rec['sdf_final_loss']:.3g}, shift {shift:.4f} m;")
    if rec["settled"] is not None:
        state = "settled" if rec["settled"] else "NOT settled"
        if rec["settle_remedy"] == "hidden":
            state = f"{100 * rec['visible_share']:.0f} % visible, kept static"
        parts.append(f"{state} after {rec['settle_frames']} frames ({rec['settle_remedy']}),"
                     f" moved {rec['settle_translation']:.4f} m;")
    parts.append(f"{sum(rec['seconds'].values()):.2f} s")
    return " ".join(parts)


def _faithful_info(scene: Scene, oid: str, obj, proxy: Proxy | None, graph, poses: dict[str, np.ndarray],
                   world_meshes: dict[str, object], cache_dir: Path) -> dict:
    """What the faithful stages need about ``oid``: supporters, their normal, resting facets, centre of mass.

    ``world_meshes`` caches each placed supporter's world-frame mesh (id -> trimesh; its spatial index is built
    once, not once per object it carries); resting facets are cached in ``cache_dir`` by hull.
    """
    import trimesh

    if graph is not None:
        edges = [e for e in graph.edges if e.target == oid]
    else:
        edges = []
    parents = [e.source for e in edges] or ["ground"]
    leaning = any(e.relation == "leans_on" for e in edges)
    below = [e.source for e in edges if e.relation in fa.BELOW] or (["ground"] if not edges else [])
    mesh = obj.mesh()
    _, _, scale = decompose(obj.pose)
    points = _shape_points(proxy, mesh)
    hull = trimesh.convex.convex_hull(points)
    com = np.asarray(hull.center_mass, dtype=float)
    parents_world = {}
    for p in below:
        if p == "ground":
            parents_world[p] = None
        elif p in poses:
            parents_world[p] = _placed_mesh(scene, p, poses, world_meshes)
    world_mesh = hull.copy().apply_transform(np.asarray(obj.pose, dtype=float))
    up = fa.support_normal(world_mesh, parents_world)
    flushable = not leaning and bool(below)
    normals = _resting_normals(hull.vertices, cache_dir) if flushable else np.zeros((0, 3))
    leaning_ids = [e.source for e in edges if e.relation == "leans_on"]
    return {"parents": parents, "below": below, "leaning": leaning_ids, "up": up, "normals": normals, "com": com,
            "flushable": flushable, "given_base": obj.base is not None, "flush_angle": 0.0,
            "flush_rotation": np.eye(3),
            "diag": float(np.linalg.norm(mesh.extents) * scale),
            "placed": list(poses), "input": np.asarray(obj.pose, dtype=float),
            "walls": [q for q in scene.structure if q.kind == "wall"], "cache_dir": cache_dir,
            "points": points, "below_world": parents_world}


#: Part of the key of the cached resting normals: changed when :func:`~phiscene.assembly.faithful.resting_normals`
#: answers differently for the same hull.
RESTING_VERSION = b"v2"


def _resting_normals(hull_points: np.ndarray, cache_dir: Path, com: np.ndarray | None = None) -> np.ndarray:
    """:func:`~phiscene.assembly.faithful.resting_normals` of a hull (k, 3) with centre of mass ``com`` (3,)
    (default the uniform solid's), cached in ``cache_dir/resting`` by the hull's vertices, ``com`` and
    :data:`RESTING_VERSION`."""
    import hashlib

    from phiscene.atomic import atomic_path

    points = np.ascontiguousarray(hull_points, dtype=float)
    extra = (b"" if com is None else b"com" + np.ascontiguousarray(com, dtype=float).tobytes()) + RESTING_VERSION
    key = hashlib.sha256(points.tobytes() + str(points.shape).encode() + extra).hexdigest()[:20]
    path = Path(cache_dir) / "resting" / f"{key}.npy"
    if path.exists():
        try:
            cached = np.load(path)
            if cached.ndim == 2 and cached.shape[1] == 3:
                return cached
        except (OSError, ValueError):
            pass  # unreadable: recompute and rewrite
    normals = fa.resting_normals(points, com)
    with atomic_path(path) as tmp:
        np.save(tmp, normals)
    return normals


def _surfaces(scene: Scene, poses: dict[str, np.ndarray], names: list[str], seed: int,
              cache: dict[str, np.ndarray]) -> np.ndarray:
    """Upward surface samples (k, 3) of the placed objects ``names`` at their grounded poses (cached per id)."""
    for q in names:
        if q not in cache:
            cache[q] = fa.upward_samples(scene.get(q).mesh().copy().apply_transform(poses[q]), fa.ONTO_SAMPLES,
                                         seed)
    parts = [cache[q] for q in names]
    return np.vstack(parts) if parts else np.zeros((0, 3))


def _settle_faithful(world, oid: str, mesh, proxy: Proxy, pose: np.ndarray, sim: SimSettings, sp: SettleParams,
                     fp: FaithfulParams, info: dict, rec: dict, com: np.ndarray | None = None) -> np.ndarray:
    """Guarded settling (see :mod:`phiscene.assembly.faithful`); fills ``rec``; returns the frozen pose.

    Every start (the corrected pose, then that pose moved out of proxy overlaps (``clear``), then the nearest
    resting poses, then a damped run, then the pose moved onto the
    nearest supporting surface, then horizontal shifts when every start so far went farther than ``max_shift`` or
    lost its supporters, or none came to rest level) is lowered onto what lies beneath and settled with the paper's
    settling; the first result within the slide/drop/turn bounds that keeps the graph's supporters is taken, else,
    avoiding gross failures (turned past ``max_stable_angle`` or moved past ``onto_reach``) where a start did, the
    closest settled one that stayed in place (on its supporters if one did), else the closest. The final pose is
    always the outcome of free settling.

    The body has the declared centre of mass ``com`` (3,) local, if any. When no start came to rest level, one
    more start with its centre of mass declared lower (from the photo's orientation, the corrected pose with the
    flush turn undone, when that turn exceeded ``max_turn``; remedy ``ballast``,
    :func:`~phiscene.assembly.faithful.ballast_com`) comes before the shifted ones; accepted, ``rec`` gets
    ``ballast`` (``com``: the declared centre, local; ``lowered``: m), else the body is a uniform solid again.
    """
    from phiscene.inertia import rigid_props

    scale = decompose(pose)[2]
    props = rigid_props(mesh, proxy.hulls, sim.density, scale, com)
    world.add_body(oid, proxy.hulls, pose, props)
    context = [b for b in world.bodies if b != oid]

    def touching() -> list[str]:
        return sorted(world.distances(oid, context, fp.contact_tol))

    tried: list[dict] = []
    own = props.com / scale  # its centre of mass as it came (local, unscaled)
    # the centre of mass the body in the world has (declared, local; None: uniform), and its completed base
    body = {"com": com, "base": None}

    def mass(declared: np.ndarray | None, base: np.ndarray | None = None) -> None:
        # the body again, with another centre of mass (and completed base, remedy base)
        if declared is not body["com"] or base is not body["base"]:
            hulls = with_base(proxy, base).hulls
            world.remove_body(oid)
            world.add_body(oid, hulls, pose, rigid_props(mesh, hulls, sim.density, scale, declared))
            body.update(com=declared, base=base)

    def attempt(label: str, start: np.ndarray, damped: bool = False, origin: np.ndarray | None = None) -> dict:
        # origin: where the slide bound is measured from (a shifted start: the start itself)
        origin = pose if origin is None else origin
        lowered = _lowered(world, oid, start, context, fp.contact_tol / 2)
        # lowered farther than onto_reach: nothing it could stand on was beneath it (beside its shelf); a fall
        fell = float(start[2, 3] - lowered[2, 3])
        fell = fell if 0 < fp.onto_reach < fell else 0.0
        start = lowered
        world.set_pose(oid, start)
        frames = 0
        if damped:
            world.set_dynamics(oid, linearDamping=fp.retry_damping, angularDamping=fp.retry_damping,
                               rollingFriction=fp.retry_rolling_friction, spinningFriction=fp.retry_rolling_friction)
            first = settle_object(world, oid, sp)
            world.restore_dynamics(oid)
            frames += first.frames
            world.set_pose(oid, first.pose)  # at rest; then normal settings decide whether it stays
        result = settle_object(world, oid, sp)
        frames += result.frames
        ok, moved, turned = fa.within_bounds(origin, result.pose, info["com"], info["diag"], fp, start=lowered)
        if fell:
            ok, moved = False, max(moved, fell)
        near = touching()
        lost = fa.lost_supporters(info["below"], info["leaning"], near)
        # in place: within the bounds, still leaning where it leans (the graph may name the wrong supporter
        # from below: an object that rests where it was put, on something else, is in place all the same)
        in_place = ok and not any(p in lost for p in info["leaning"])
        robust = True  # tested only where it decides: a settled result in place (the fallback: below)
        tested = result.settled and in_place and fp.tilt_test > 0 and not info["leaning"]  # leaning: friction
        if tested:
            robust, spent = holds_when_tilted(world, oid, fp.tilt_test, fp.tilt_frames, fp.joint_tol,
                                              fp.joint_tol_deg, sp)
            frames += spent
        gave: list[str] = []  # the placed objects it touches (and their supporters), released under it, hold it
        if result.settled and in_place and robust and fp.load_frames > 0:
            carriers = load_carriers(world, oid, near, info["fixed"], fp.contact_tol, fp.load_depth)
            if carriers:
                gave, spent = gives_way(world, oid, carriers, fp.load_frames, fp.joint_tol, fp.joint_tol_deg, sp)
                frames += spent
        whys = ["" if ok else f"moved {moved:.3f} m / {turned:.1f} deg",
                f"lost supporters {lost}" if lost else "", "" if result.settled else "not settled",
                "" if robust else f"marginal: tips when tilted {fp.tilt_test:g} deg",
                f"gives way when released: {gave}" if gave else ""]
        stayed = ok and not lost
        # a gross failure: turned beyond any resting pose tried, or went farther than the onto remedy moves
        gross = fa.gross_failure(moved, turned, fp)
        out = {"label": label, "result": result, "frames": frames, "gross": gross, "turned": turned,
               "ok": stayed and result.settled and robust and not gave, "lost": bool(lost), "robust": robust,
               "loaded": not gave,
               "stayed": stayed, "in_place": in_place, "travel": moved if not lost else math.inf,
               "cost": fa.closeness(pose, result.pose, info["com"], info["diag"], start=lowered) + fell,
               "why": "; ".join(w for w in whys if w), "touching": near, "com": body["com"], "base": body["base"],
               "tilt_tested": tested}
        tried.append(out)
        return out

    def holds(t: dict) -> bool:
        # tilt-test a settled result where it came to rest, with the body it had (once): whether it holds
        if not t["tilt_tested"] and fp.tilt_test > 0:
            mass(t["com"], t["base"])
            world.set_pose(oid, t["result"].pose)
            t["tilt_tested"] = True
            t["robust"], spent = holds_when_tilted(world, oid, fp.tilt_test, fp.tilt_frames, fp.joint_tol,
                                                   fp.joint_tol_deg, sp)
            t["frames"] += spent
            if not t["robust"]:
                t["why"] = "; ".join(w for w in (t["why"], f"marginal: tips when tilted {fp.tilt_test:g} deg") if w)
        return t["robust"]

    best = attempt("none", pose)
    if not best["ok"] and fp.clear:
        # out of what it neither stands nor leans on, where its convex pieces overlap it (its mesh is clear of
        # it): the simulator shoves it out at once; the remaining starts are taken from there
        holders = {"ground", *info["below"], *info["leaning"]}
        world.set_pose(oid, pose)
        shift = clear_overlaps(world, oid, [b for b in context if b not in holders], fp.contact_tol, fp.max_shift)
        if shift is not None:
            pose = pose.copy()
            pose[:3, 3] += shift
            rec["proxy_clear"] = [_round(v) for v in shift]
            best = attempt("clear", pose)
    if not best["ok"] and fp.lean and info["leaning"]:
        # short of what it leans on (depth error): lowered, then moved sideways until it touches it
        lowered = _lowered(world, oid, pose, context, fp.contact_tol / 2)
        world.set_pose(oid, lowered)
        shift = close_gaps(world, oid, info["leaning"], fp.contact_tol, fp.contact_tol / 2, fp.onto_reach)
        if shift is not None:
            start = lowered.copy()
            start[:3, 3] += shift
            rec["lean_shift"] = [_round(v) for v in shift]
            best = attempt(f"lean {np.linalg.norm(shift):.3f} m", start, origin=start)
    if not best["ok"]:
        starts = fa.resting_candidates(pose, info["normals"], info["com"], info["up"], fp.max_stable_angle)
        for start, angle in [c for c in starts if c[1] > 0.5][: fp.max_candidates]:
            if attempt(f"stable {angle:.1f} deg", start)["ok"]:
                break
        if not any(t["ok"] for t in tried):
            attempt("damped", pose, damped=True)
        if not any(t["ok"] or (t["in_place"] and t["result"].settled and t["robust"] and t["loaded"])
                   for t in tried) and fp.onto_reach > 0:
            # fell or slid off every time, only balances on an edge or its carriers give way under it: its input
            # is off its supporter or over its edge (depth error); move it onto the nearest supporting surface,
            # inside its edge (the graph may name the wrong supporter), from where the input put it: carried
            # by a supporter the graph got wrong, it may have gone far. Any surface nearer than where it went
            # anyway (a can over nothing falls a metre to the floor; the wall shelf its depth error took it off
            # is 31 cm away) is nearer to the input than that
            here = pose.copy()
            here[:3, 3] += fa.com_world(info["input"], info["com"]) - fa.com_world(pose, info["com"])
            points = transform_points(here, info["points"])
            went = [t["travel"] for t in tried if math.isfinite(t["travel"])]
            reach = max(fp.onto_reach, min(went)) if went else fp.onto_reach
            onto = fa.onto_start(here, info["com"], points, info["surfaces"](info["placed"]), reach,
                                 fp.contact_tol / 2, info["walls"])
            if onto is not None and onto[1] > 1e-3:
                attempt(f"onto {onto[1]:.3f} m", onto[0], origin=onto[0])
        if fp.ballast and not any(t["ok"] for t in tried) and all(
                t["turned"] > fp.max_turn or not t["result"].settled or not t["robust"] for t in tried):
            # none came to rest level: at rest in the photo, so not a uniform solid (flowers outweighing a vase).
            # A flush within the turn bound corrects the input's rotation error; a larger one was chosen for the
            # uniform solid and contradicts the photo, which shows the object at rest: that turn undone
            points = info["points"]  # its convex pieces' vertices (local)
            undone = info["flush_angle"] > fp.max_turn
            start = _unflushed(world, oid, pose, info, context, fp.contact_tol / 2) if undone else pose
            declared = fa.ballast_com(start, own, points, fp.ballast_height)
            angle = 0.0  # the flush turn of these starts (from the photo's orientation when undone)
            if declared is not None and fp.flush and info["flushable"]:
                # flush on the facet it rests on with that centre of mass (a vase's base is no resting facet of
                # the uniform solid), then the centre over that base
                start, angle = fa.flush_pose(start, _resting_normals(points, info["cache_dir"], declared), declared,
                                             info["up"], fp.max_flush_angle)
                if angle > 0:
                    declared = fa.ballast_com(start, own, points, fp.ballast_height)
            if declared is not None:
                mass(declared)
                t = attempt("ballast", start, origin=start)
                if undone:
                    t["flush"] = angle
                if not t["ok"]:  # the flush is a correction, as for none
                    mass(com)  # the other starts as it came; the ballast result may still be the closest
            if fp.base and info["flushable"] and not info["given_base"] and not any(t["ok"] for t in tried) \
                    and not _rests(tried, fa.slide_bound(info["diag"], fp), holds):
                mass(com)  # the body as it came (a tilt test may have changed it)
                # nor with its mass low, and no start came to rest where it was put, however turned (a can
                # tilted by a rotation error stands upright on its bottom, a resting pose 28 deg away): its
                # bottom is a guess that cannot stand (a jug, a fruit guessed round underneath); complete it
                # flat where it stands, level, with its mass as low
                declared = com if declared is None else declared
                flat = fa.flat_base(start, proxy.hulls, own if declared is None else declared, info["up"],
                                    fp.tilt_test)
                if flat is not None:
                    mass(declared, flat[0])
                    t = attempt(f"base {flat[1]:g}", start, origin=start)
                    if undone:
                        t["flush"] = angle
                    if not t["ok"]:
                        mass(com)
            elif not any(t["ok"] for t in tried):
                mass(com)  # the body as it came (a tilt test may have changed it)
        travelled = min(t["travel"] for t in tried)
        # every start went far, or none came to rest level (tipped over, or still moving: a book whose depth error
        # put it over its supporter's edge): one nearby
        tipped = all(t["turned"] > fp.max_turn or not t["result"].settled for t in tried)
        if (travelled > fp.max_shift or tipped) and not any(t["ok"] for t in tried):
            step = fa.slide_bound(info["diag"], fp)
            for r, ring in fa.shifted_starts(pose, step, fp.max_shift, fp.shift_directions):
                # nearest ring first; stop at an accepted start, or after a ring
                done = [attempt(f"shifted {r:.3f} m", s, origin=s) for s in ring]  # where one rests in place
                if any(t["ok"] for t in done) or any(t["in_place"] and t["result"].settled for t in done):
                    break
    ok = [t for t in tried if t["ok"]]
    if not ok and fp.tilt_test > 0 and not info["leaning"]:
        # the fallback: tilt-test the settled results in rank order (only those in place were tested), up to
        # the first that holds; one that only balances would roll off at the first disturbance
        for t in sorted(tried, key=fa.fallback_rank)[:FALLBACK_TILTS]:
            if t["gross"] or not t["result"].settled or t["tilt_tested"]:
                continue
            if holds(t):
                break
    best = ok[0] if ok else min(tried, key=fa.fallback_rank)
    share = info["visible"]() if not ok and info.get("visible") is not None else None
    if share is not None and share < fp.hidden_share:  # nan (outside the image): no
        # mostly unseen, and its guessed shape held by no start: kept where it was put, on what lies beneath it,
        # unless the fallback ends nearer to the input (the corrected pose may have been carried far, or fall far
        # when lowered), nothing is beneath it, or the placed objects it touches, released, do not stay (static,
        # it would shove them: its convex pieces may reach into them)
        mass(com)
        kept = _lowered(world, oid, pose, context, fp.contact_tol / 2)
        world.set_pose(oid, kept)
        near = touching()
        far = lambda p: fa.closeness(info["input"], p, info["com"], info["diag"], start=info["input"])  # noqa: E731
        world.set_static(oid)
        carriers = load_carriers(world, oid, near, info["fixed"], fp.contact_tol, fp.load_depth)
        if near and far(kept) < far(best["result"].pose) and not (
                carriers and gives_way(world, oid, carriers, fp.load_frames, fp.joint_tol, fp.joint_tol_deg, sp)[0]):
            rec["touching"] = near
            moved, turned = window_motion(pose, kept)
            reason = "; ".join(f"{t['label']}: {t['why']}" for t in tried)
            rec.update(settle_frames=sum(t["frames"] for t in tried), settled=True, settle_remedy="hidden",
                       residual_translation=0.0, residual_rotation=0.0, settle_translation=_round(moved),
                       settle_rotation=_round(turned), reason=f"{reason}; kept: {share:.0%} visible",
                       attempts=len(tried), visible_share=_round(share))
            return kept
    result = best["result"]
    if "flush" in best:  # started from the photo's orientation: the flush of _faithful_start undone
        info["flush_angle"] = best["flush"]
        rec["flush_angle"] = _round(best["flush"])
    if not best["ok"]:
        remedy = "closest"
    else:
        remedy = result.remedy if best["label"] == "none" else best["label"].split()[0]
    reason = "; ".join(f"{t['label']}: {t['why']}" for t in tried if t is not best or not best["ok"])
    final = result.pose
    mass(best["com"], best["base"])
    if best["com"] is not None and best["com"] is not com and best["label"].split()[0] in ("ballast", "base"):
        # declared by the remedy (a base start keeps the input's own declared centre when the ballast had none)
        lowered = fa.com_world(final, own)[2] - fa.com_world(final, best["com"])[2]
        rec["ballast"] = {"com": [_round(v, 12) for v in best["com"]], "lowered": _round(lowered)}
    if best["base"] is not None:
        rec["base"] = {"points": np.asarray(best["base"]).round(12).tolist(), "share": float(best["label"].split()[1])}
    world.set_pose(oid, final)
    rec["touching"] = best["touching"]
    world.set_static(oid)
    moved, turned = window_motion(pose, final)
    rec.update(settle_frames=sum(t["frames"] for t in tried), settled=result.settled, settle_remedy=remedy,
               residual_translation=_round(result.residual_translation, 12),
               residual_rotation=_round(result.residual_rotation, 12),
               settle_translation=_round(moved), settle_rotation=_round(turned), reason=reason,
               attempts=len(tried))
    return final


def _unflushed(world, oid: str, pose: np.ndarray, info: dict, below: list[str], clearance: float) -> np.ndarray:
    """``pose`` with the flush turn of :func:`_faithful_start` (``info["flush_rotation"]``) undone about the centre
    of mass, raised out of ``below`` (and the ground) where the turn takes it into them, to ``clearance`` (m)."""
    from scipy.spatial.transform import Rotation

    back = Rotation.from_matrix(info["flush_rotation"].T).as_rotvec()
    out = turned_about(pose, back, fa.com_world(pose, info["com"]))
    world.set_pose(oid, out)
    gaps = world.distances(oid, _stoppers(world, below), clearance)
    if gaps and min(gaps.values()) < 0:
        out[2, 3] += clearance / 2 - min(gaps.values())
    return out


def _rests(tried: list[dict], bound: float, holds: Callable[[dict], bool]) -> bool:
    """Whether a start of ``tried`` (the attempts of :func:`_settle_faithful`) came to rest where it was put, however
    turned: settled, its centre of mass within ``bound`` (m) of its start, and ``holds`` (tilt-tested) it."""
    return any(t["result"].settled and t["travel"] <= bound and holds(t) for t in tried)


def _stoppers(world, below: list[str]) -> list[str]:
    """What a body moved straight up or down meets: ``below``, and the ground whatever the graph says."""
    return list(dict.fromkeys([*below, *(["ground"] if "ground" in world.bodies else [])]))


def _lowered(world, oid: str, pose: np.ndarray, below: list[str], clearance: float) -> np.ndarray:
    """``pose`` moved straight down until within ``clearance`` of the nearest of ``below`` (or of the ground).

    Each step lowers by the Euclidean gap (a lower bound of the vertical gap), so it never penetrates. The ground
    always stops it: a supporter that is no longer beneath the object (it moved, or the graph was wrong) must not
    let it sink through the floor.
    """
    stoppers = _stoppers(world, below)
    out = pose.copy()
    for _ in range(8):
        world.set_pose(oid, out)
        gaps = world.distances(oid, stoppers, 1.0)
        gap = min(gaps.values()) if gaps else 0.0
        if gap <= clearance:
            break
        out[2, 3] -= gap - clearance / 2
    return out


def _keep(store: dict[str, np.ndarray], oid: str, chosen, given: np.ndarray | None) -> None:
    """Record in ``store`` (id -> array, local frame) what ``oid`` was grounded with: what a remedy ``chosen``
    (the ``ballast``'s declared centre of mass, the ``base``'s completed base), else its input's ``given`` one,
    else nothing (a uniform solid, its proxies alone)."""
    if chosen is not None:
        store[oid] = np.asarray(chosen, dtype=float)
    elif given is not None:
        store[oid] = np.asarray(given, dtype=float)
    else:
        store.pop(oid, None)


def _kept(masses: dict[str, np.ndarray], bases: dict[str, np.ndarray], oid: str, rec: dict, obj) -> None:
    """Record the centre of mass and the completed base ``oid`` (``obj``) was grounded with (:func:`_keep`)."""
    _keep(masses, oid, rec.get("ballast", {}).get("com"), obj.com)
    _keep(bases, oid, rec.get("base", {}).get("points"), obj.base)


def _as_grounded(scene: Scene, attached: dict[str, str], masses: dict[str, np.ndarray] | None = None,
                 bases: dict[str, np.ndarray] | None = None) -> Scene:
    """``scene`` with what grounding knows of its objects' bodies set on them: the attachments of ``attached``
    (id -> what holds it), the declared centres of mass of ``masses`` (id -> (3,) local, remedy ``ballast``) and
    the completed bases of ``bases`` (id -> (k, 3) local, remedy ``base``)."""
    for o in scene.objects:
        if o.id in attached:
            o.attached = attached[o.id]
        if masses and o.id in masses:
            o.com = np.asarray(masses[o.id], dtype=float)
        if bases is not None:
            o.base = np.asarray(bases[o.id], dtype=float) if o.id in bases else None
    return scene


def _joint_settle(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, cache_dir: Path, fp: FaithfulParams,
                  sp: SettleParams, objects: dict[str, dict], coms: dict[str, np.ndarray],
                  inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Release the sequentially grounded scene as a whole until every object is at rest; the poses it ends at.

    Sequential settling tests each object against a frozen context: a supporter is never tested under the load
    of what was placed on it later (a book that tips under the box put on its edge). One joint simulation
    (:func:`~phiscene.baselines.joint_sim.joint_sim`, attached objects static) ends that: objects that were
    at rest do not move, the others find the rest their neighbours allow. Each moved object's record gets
    ``joint_settle`` ([m, deg]) and its displacement and rotation change from ``inputs`` (id -> input pose
    (4, 4)) are updated, certificate included (its centre-of-mass displacement with ``coms``: id -> (3,) local).
    """
    from phiscene.baselines.joint_sim import JointSimParams, joint_sim

    params = JointSimParams(window=sp.window, eps_pos=sp.eps_pos, eps_rot=sp.eps_rot,
                            max_frames=fp.joint_settle_frames)
    settled, log_ = joint_sim(scene, proxies, sim, params, cache_dir)
    poses = {o.id: np.asarray(o.pose, dtype=float) for o in settled.objects}
    for oid, entry in log_["objects"].items():
        rec = objects[oid]
        rec["joint_settle"] = [_round(entry["displacement"]), _round(np.degrees(entry["rotation_change"]), 6)]
        total, turned = window_motion(inputs[oid], poses[oid])
        rec.update(displacement=_round(total), rotation_change=_round(turned))
        cert = rec.get("certificate")
        if cert is not None:
            com = coms[oid]
            cert["displacement"] = _round(float(np.linalg.norm(fa.com_world(poses[oid], com)
                                                               - fa.com_world(inputs[oid], com))))
            cert["rotation_change"] = _round(np.degrees(turned), 6)
            if entry["displacement"] > fp.joint_tol or np.degrees(entry["rotation_change"]) > fp.joint_tol_deg:
                cert["remedy"] = f"{cert['remedy']}+joint"
    log.info("joint settling: %d frames, %s", log_["frames"],
             "all at rest" if log_["all_settled"] else f"not at rest: {', '.join(log_['unsettled'])}")
    return poses


def _collapsed(rec: dict, fp: FaithfulParams) -> bool:
    """Whether joint settling undid an object's placement: it turned past ``max_stable_angle`` (toppled) or moved
    farther than ``reground_move`` (fell) when the whole scene was released."""
    moved = rec.get("joint_settle")
    return moved is not None and (moved[1] > fp.max_stable_angle or moved[0] > fp.reground_move)


def _reground_collapsed(scene: Scene, order: list[str], proxies: dict[str, Proxy], params: "AssemblyParams",
                        sim: SimSettings, cache_dir: Path, graph, attached: dict[str, str],
                        poses: dict[str, np.ndarray], objects: dict[str, dict], coms: dict[str, np.ndarray],
                        masses: dict[str, np.ndarray], bases: dict[str, np.ndarray],
                        progress: Callable[[str], None] | None,
                        eye: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Ground again, from its input, each object that joint settling toppled or dropped, against the rest of the
    scene where joint settling left it; then settle the scene jointly once more.

    Sequential settling tests an object on supporters frozen where they were placed; released together, the
    supporters may shift under its load (a mug across two boxes that part) and it falls. Its own placement is
    then redone with the same stages (carried, along the camera ray from ``eye`` when remedy ``ray`` is on, flush,
    SDF, guarded settling) on the supporters as they now rest;
    the new pose replaces the collapsed one when it is closer to the input (:func:`~phiscene.assembly.faithful.
    closeness`). The record gets ``reground`` (the new attempt's settling record and whether it was kept) and the
    certificate's remedy a ``+reground``.

    Returns
    -------
    The poses (id -> (4, 4)) after the final joint settling (``poses`` when nothing was kept).
    """
    from phiscene.sim.bullet import BulletWorld

    fp, pp = params.faithful, params.penetration_params
    kept = []
    for oid in [o for o in order if o not in attached and _collapsed(objects[o], fp)]:
        obj = scene.get(oid)
        initial = np.asarray(obj.pose, dtype=float)
        context = {q: poses[q] for q in order if q != oid}
        rec: dict = {"seconds": {}}
        with BulletWorld(sim, cache_dir) as world:
            world.add_ground(scene.ground_height)
            world.add_structure(scene.structure)
            for q, p in context.items():
                _add_static(world, q, scene.get(q).mesh(), with_base(proxies[q], bases.get(q)), p, sim,
                            masses.get(q))
            pose, info = _faithful_start(scene, oid, proxies[oid], graph, context, {}, {}, attached, fp, pp.seed,
                                         cache_dir, rec, eye)
            if params.penetration:
                placed = [sdf_body(q, scene.get(q).mesh(), p, pp.n_context, pp, cache_dir) for q, p in context.items()]
                pose = _resolve_faithful(scene, oid, pose, placed, context, {}, pp, fp, cache_dir, rec, info)
            new = _settle_faithful(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params, fp, info,
                                   rec, obj.com)
        closer = (fa.closeness(initial, new, info["com"], info["diag"])
                  < fa.closeness(initial, poses[oid], info["com"], info["diag"]))
        objects[oid]["reground"] = {"kept": bool(closer), "settled": rec["settled"], "remedy": rec["settle_remedy"],
                                    "reason": rec.get("reason", ""), "attempts": rec.get("attempts", 0)}
        if progress is not None:
            progress(f"{oid}: toppled or fell when the scene was released together; grounded again on its "
                     f"supporters as they rest ({rec['settle_remedy']}), {'kept' if closer else 'not closer'}")
        if closer:
            poses[oid] = new
            kept.append(oid)
            _kept(masses, bases, oid, rec, obj)
            cert = objects[oid].get("certificate")
            if cert is not None:
                cert["remedy"] = f"{cert['remedy']}+reground"
                cert["touching"] = rec.get("touching", cert["touching"])
    if not kept:
        return poses
    return _joint_settle(_as_grounded(scene.with_poses(poses), attached, masses, bases), proxies, sim, cache_dir, fp,
                         params.settle_params, objects, coms, {o: np.asarray(scene.get(o).pose, float) for o in order})


def _joint_check(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, cache_dir: Path, fp: FaithfulParams,
                 objects: dict[str, dict]) -> None:
    """Release the grounded scene as a whole (the pybullet drift protocol, ``fp.joint_frames`` frames, no offset).

    Adds ``joint_drift`` (m, deg) and ``joint_stable`` (within ``joint_tol`` / ``joint_tol_deg``) to each
    object's certificate: sequential settling tests each object against a frozen context only.
    """
    from phiscene.metrics.drift import drift_bullet
    from phiscene.metrics.physical import PhysicalParams

    drift = drift_bullet(scene, proxies, PhysicalParams(upward_offset=0.0, frames=fp.joint_frames), sim, cache_dir)
    for oid, d in drift["objects"].items():
        cert = objects[oid].get("certificate")
        if cert is not None:
            cert["joint_drift"] = [_round(d["drift_trans"]), _round(d["drift_rot"], 6)]
            cert["joint_stable"] = bool(d["drift_trans"] <= fp.joint_tol and d["drift_rot"] <= fp.joint_tol_deg)
