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
import copy
import functools
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.assembly import beneath, certify, fixtures, guarded, resting, starts
from phiscene.assembly.faithful import BELOW, FaithfulParams
from phiscene.assembly.penetration import (
    PenetrationParams,
    SdfBody,
    resolve_penetration,
    sdf_body,
    upward_clearance,
)
from phiscene.assembly.record import LOG_FORMAT, rounded
from phiscene.assembly.settle import (
    SettleParams,
    beyond,
    settle_object,
    window_motion,
)
from phiscene.errors import InputError
from phiscene.meshes import sample_surface
from phiscene.params import Params
from phiscene.proxies import Proxy, check_proxies, with_base, with_bases
from phiscene.scene import Scene, as_written
from phiscene.sim.settings import SimSettings
from phiscene.topology.attached import STRUCTURE
from phiscene.transforms import decompose, transform_points, turned_about

log = logging.getLogger(__name__)


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
        (:func:`~phiscene.assembly.starts.ray_corrected`; skipped without it).
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
        with ``ray`` and ``eye``; ``stand_ins``, what stood in for itself while it was placed, :func:`_stand_ins`;
        an attached object's ``attach_lift`` and, with ``fixtures``, ``fixture_clear``,
        :func:`~phiscene.assembly.fixtures.clear_fixture`) and a
        ``certificate`` per object (:func:`~phiscene.assembly.certify.certificate`), and the summary lists the
        lost supporters, the remedies, the objects not stable in the final release (``joint_unstable``) and
        those that end a gross failure from their input (``gross``: id -> what happened,
        :func:`~phiscene.assembly.certify.gross_failures`; also logged as a warning and a progress line).
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
    stand_ins = _stand_ins(graph, order, attached) if params.faithful.enabled and params.settle else {}
    structure = {o for o, why in (graph.meta.get("attached", {}) if graph is not None else {}).items()
                 if why == STRUCTURE and o in attached}
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
                # the room's own meshes (a wall, the floor) are where the room is: never turned, lifted or cleared
                adjust = params.faithful.enabled and oid not in structure
                if adjust and params.faithful.flush:
                    pose = fixtures.flush_fixture(scene, obj, proxies.get(oid), attached[oid],
                                                  params.faithful.max_flush_angle, cache_dir, rec)
                if adjust and params.faithful.fixtures and params.penetration:
                    pose = fixtures.clear_fixture(scene, oid, pose, attached[oid],
                                                  [b for b in placed if b.id in attached], pp,
                                                  params.faithful.contact_tol, cache_dir, rec)
                _fix(world if params.settle else None, oid, obj.mesh(), proxies.get(oid), pose, sim, rec,
                     masses.get(oid))
                total, turned = window_motion(initial, pose)
                rec.update(displacement=rounded(total), rotation_change=rounded(turned))
                poses[oid] = pose
                if params.penetration:
                    placed.append(sdf_body(oid, obj.mesh(), pose, pp.n_context, pp, cache_dir))
                objects[oid] = rec
                if progress is not None:
                    progress(f"[{index + 1}/{len(order)}] {oid}: attached to {attached[oid]}, "
                             f"{fixtures.summary(rec, total, turned)}")
                continue

            fp = params.faithful
            info = None
            # what it leans on that comes later (a support cycle broken: two planks leaning on each other) stands in
            # for itself at its input pose, static, until this object is placed
            stand = [q for q in stand_ins.get(oid, []) if q not in poses]
            for q in stand:
                _add_static(world, q, scene.get(q).mesh(), proxies[q], np.asarray(scene.get(q).pose, dtype=float),
                            sim, masses.get(q))
            context = placed + [sdf_body(q, scene.get(q).mesh(), np.asarray(scene.get(q).pose, dtype=float),
                                         pp.n_context, pp, cache_dir) for q in stand if params.penetration]
            if stand:
                rec["stand_ins"] = stand
            if fp.enabled:
                t0 = time.perf_counter()
                pose, info = _faithful_start(scene, oid, proxies.get(oid), graph, poses, world_meshes, surfaces,
                                             attached, fp, pp.seed, cache_dir, rec, eye)
                info.update(visible=None if shares is None else (lambda o=oid: shares().get(o)), input=initial)
                rec["seconds"]["flush"] = time.perf_counter() - t0

            t0 = time.perf_counter()
            if params.penetration:
                if info is not None:
                    pose = _resolve_faithful(scene, oid, pose, context, poses, world_meshes, pp, fp, cache_dir, rec,
                                             info)
                else:
                    pose = _resolve(oid, obj.mesh(), pose, context, scene.ground_height, pp, cache_dir, rec,
                                    scene.structure)
            else:
                rec.update(sdf_iterations=0, sdf_initial_loss=None, sdf_final_loss=None,
                           sdf_translation=[0.0, 0.0, 0.0], sdf_context=[], sdf_grid_error=None)
            rec["seconds"]["sdf"] = time.perf_counter() - t0

            t0 = time.perf_counter()
            if params.settle and info is not None:
                pose = guarded.settle_faithful(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params,
                                               fp, info, rec, masses.get(oid))
                _kept(masses, bases, oid, rec, obj)
                if rec["settle_remedy"] in guarded.KEPT_REMEDIES:  # static where it was put from now on, as if attached
                    attached[oid] = "ground"
                    if rec["settle_remedy"] == "hidden":
                        log.warning("%s: no start held it and %.0f %% of it is visible in the photo: kept where "
                                    "it was put, static", oid, 100 * rec["visible_share"])
                    else:
                        log.warning("%s: no start held it and the fallback carried it across the scene: kept "
                                    "where it was put, static, not settled", oid)
            elif params.settle:
                pose = _settle(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params, rec,
                               masses.get(oid))
            else:
                rec.update(settle_frames=0, settled=None, settle_remedy=None, residual_translation=None,
                           residual_rotation=None, settle_translation=0.0, settle_rotation=0.0)
            rec["seconds"]["settle"] = time.perf_counter() - t0
            for q in stand:
                world.remove_body(q)

            t0 = time.perf_counter()
            poses[oid] = pose
            if params.penetration:
                placed.append(sdf_body(oid, obj.mesh(), pose, pp.n_context, pp, cache_dir))
            rec["seconds"]["context"] = time.perf_counter() - t0
            total, turned = window_motion(initial, pose)
            rec.update(displacement=rounded(total), rotation_change=rounded(turned))
            if info is not None:
                com = info["com"]
                moved = float(np.linalg.norm(resting.com_world(pose, com) - resting.com_world(initial, com)))
                coms[oid] = com
                rec["certificate"] = certify.certificate(
                    rec["settled"], rec["settle_remedy"] or "none", info["below"], info["leaning"],
                    rec.get("touching", []),
                    moved, np.degrees(turned), info["flush_angle"], rec.get("reason", ""))
            rec["seconds"] = {k: rounded(v, 6) for k, v in rec["seconds"].items()}
            objects[oid] = rec
            if progress is not None:
                progress(_progress_line(index, len(order), oid, rec))
    if params.faithful.enabled and params.settle and params.faithful.joint_settle_frames > 0:
        poses = _joint_stage(scene, order, proxies, params, sim, cache_dir, graph, attached, poses, objects, coms,
                             masses, bases, progress, eye)
    if params.faithful.enabled and params.settle and params.faithful.joint_frames > 0:
        _joint_check(_as_grounded(scene.with_poses(poses), attached, masses, bases), proxies, sim, cache_dir,
                     params.faithful, objects)
    unsettled = [o for o, r in objects.items() if r["settled"] is False]
    summary = {"objects": len(order), "settled": sum(r["settled"] is True for r in objects.values()),
               "unsettled": unsettled,
               "sdf_iterations": int(sum(r["sdf_iterations"] for r in objects.values())),
               "settle_frames": int(sum(r["settle_frames"] for r in objects.values())),
               "seconds": rounded(time.perf_counter() - t_start, 6)}
    certs = {o: r["certificate"] for o, r in objects.items() if "certificate" in r}
    if certs:
        summary["supporters_lost"] = {o: c["lost"] for o, c in certs.items() if c["lost"]}
        summary["remedies"] = {o: c["remedy"] for o, c in certs.items() if c["remedy"] != "none"}
        summary["joint_unstable"] = [o for o, c in certs.items() if c.get("joint_stable") is False]
        summary["gross"] = certify.gross_failures(certs, params.faithful)
        summary["hidden"] = sorted(o for o, r in objects.items() if r.get("settle_remedy") == "hidden")
        summary["held"] = sorted(o for o, r in objects.items() if r.get("settle_remedy") == "held")
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


def _stand_ins(graph, order: list[str], attached: dict[str, str]) -> dict[str, list[str]]:
    """Object id -> the free objects it leans on that come after it in ``order``: the sources of ``leans_on`` edges
    the support graph dropped to break a cycle (two planks leaning on each other, books leaning together).

    Placed alone, the first of such a pair has nothing to lean on and falls; with the other standing in at its input
    pose (static, in the settling world and in the SDF context) it rests leaning on it, and the other then leans on
    it where it rests. The joint settling releases both together."""
    if graph is None:
        return {}
    at = {o: i for i, o in enumerate(order)}
    out: dict[str, list[str]] = {}
    for e in graph.dropped_edges:
        if e.relation == "leans_on" and e.source in at and e.target in at and at[e.source] > at[e.target] \
                and e.source not in attached and e.target not in attached:
            out.setdefault(e.target, []).append(e.source)
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
        before = np.asarray(scene.get(carrier).pose, float)
        if fp.carry_sideways == "off_support" and beneath.over_support(
                pose, info["com"], info["points"], _placed_mesh(scene, carrier, poses, world_meshes),
                fp.carry_margin):
            pose = starts.carried_vertically(pose, info["com"], before, poses[carrier])
            rec["carried_vertically"] = True
        else:
            pose = starts.carried(pose, info["com"], before, poses[carrier])
        rec["carried_by"] = carrier
    if fp.ray and eye is not None and info["below"] and not info["leaning"]:
        pose, shift = starts.ray_corrected(pose, info["points"], info["com"], info["below_world"], scene.ground_height,
                                           eye, fp)
        rec["ray_shift"] = rounded(shift)
    if fp.flush and info["flushable"]:
        turned, info["flush_angle"] = resting.flush_pose(pose, info["normals"], info["com"], info["up"],
                                                         fp.max_flush_angle)
        info["flush_rotation"] = decompose(turned)[0] @ decompose(pose)[0].T  # world frame, about the centre of mass
        pose = turned
    rec["flush_angle"] = rounded(info["flush_angle"])
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
    rec.update(sdf_planar=planar, sdf_iterations=info["iterations"], sdf_initial_loss=rounded(info["initial_loss"]),
               sdf_final_loss=rounded(info["final_loss"]), sdf_searched=info["searched"],
               sdf_translation=[rounded(v) for v in x], sdf_rotation=[rounded(v) for v in info["rotation"]],
               sdf_context=info["context"],
               sdf_grid_error=rounded(active.scale * active.grid.error.get("max_abs", float("nan"))))
    out = turned_about(pose, np.asarray(info["rotation"]), np.asarray(info["pivot"]))
    out[:3, 3] += x
    return out


def _resolve_faithful(scene: Scene, oid: str, pose: np.ndarray, placed: list[SdfBody],
                      poses: dict[str, np.ndarray], world_meshes: dict[str, object], pp: PenetrationParams,
                      fp: FaithfulParams, cache_dir: Path, rec: dict, info: dict) -> np.ndarray:
    """The faithful variant's SDF stage: :func:`_resolve`, horizontally only for an object on the floor alone
    (:func:`_on_the_floor`), moved up and out instead where that is much shorter (:func:`upward_clearance`: straight
    up or up and sideways, then lowered onto what lies there), at most ``max_shift``, and
    leaves it resting on placed objects (within ``eps + contact_tol`` plus the largest grid error of the placed
    objects it may rest on: their grids set where the lift stops; ``FaithfulParams.floor_lift``: ``info["below"]``
    becomes those objects,
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
    lift = upward_clearance(active, placed, scene.ground_height, pp, scene.structure,
                            min(fp.floor_lift * pushed, fp.max_shift, pp.search_reach))
    if lift is None:
        return out
    lifted = pose.copy()
    lifted[:3, 3] += lift
    near = {q: _placed_mesh(scene, q, poses, world_meshes) for q in rec["sdf_context"] if q in poses}
    bottom = np.vstack([info["points"], sample_surface(mesh, beneath.RESTING_SAMPLES, pp.seed)])
    # the lift ends clear by eps in the placed objects' grids, which may read a thin board thicker than its mesh
    # by up to their error (a floor shelf's boards: 3.9 cm): resting within that too
    slack = max([b.scale * b.grid.error.get("max_abs", 0.0) for b in placed if b.id in near] + [0.0])
    holders = beneath.resting_on(transform_points(lifted, bottom), resting.com_world(lifted, info["com"]), near,
                                 scene.ground_height, pp.eps + fp.contact_tol + slack)
    if not holders:
        return out
    rec["sdf_lifted"] = {"onto": holders, "planar_translation": [rounded(v) for v in out[:3, 3] - pose[:3, 3]]}
    rec.update(sdf_planar=False, sdf_final_loss=0.0, sdf_translation=[rounded(v) for v in lift],
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
               residual_translation=rounded(result.residual_translation, 12),
               residual_rotation=rounded(result.residual_rotation, 12),
               settle_translation=rounded(moved), settle_rotation=rounded(turned))
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
        elif rec["settle_remedy"] == "held":
            state = "NOT settled: the fallback carried it across the scene, kept static"
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
        # what it leans on in a support cycle the graph broke (:func:`_stand_ins`): still leaning, never flushed
        cycle = [e for e in graph.dropped_edges if e.target == oid and e.relation == "leans_on"]
    else:
        edges, cycle = [], []
    parents = [e.source for e in edges] or ["ground"]
    leaning = any(e.relation == "leans_on" for e in edges + cycle)
    below = [e.source for e in edges if e.relation in BELOW] or (["ground"] if not edges else [])
    mesh = obj.mesh()
    points = fixtures.shape_points(proxy, mesh)
    hull = trimesh.convex.convex_hull(points)
    com = np.asarray(hull.center_mass, dtype=float)
    parents_world = {}
    for p in below:
        if p == "ground":
            parents_world[p] = None
        elif p in poses:
            parents_world[p] = _placed_mesh(scene, p, poses, world_meshes)
    world_mesh = hull.copy().apply_transform(np.asarray(obj.pose, dtype=float))
    up = resting.support_normal(world_mesh, parents_world)
    flushable = not leaning and bool(below)
    normals = resting.cached_resting_normals(hull.vertices, cache_dir) if flushable else np.zeros((0, 3))
    leaning_ids = [e.source for e in edges + cycle if e.relation == "leans_on"]
    return {"parents": parents, "below": below, "leaning": leaning_ids, "up": up, "normals": normals, "com": com,
            "flushable": flushable, "given_base": obj.base is not None, "flush_angle": 0.0,
            "flush_rotation": np.eye(3),
            "diag": _diagonal(obj),
            "placed": list(poses), "input": np.asarray(obj.pose, dtype=float),
            "walls": [q for q in scene.structure if q.kind == "wall"], "cache_dir": cache_dir,
            "points": points, "below_world": parents_world}


def _diagonal(obj) -> float:
    """Bounding-box diagonal (m) of an object's mesh at its pose's scale."""
    return float(np.linalg.norm(obj.mesh().extents) * decompose(obj.pose)[2])


def _surfaces(scene: Scene, poses: dict[str, np.ndarray], names: list[str], seed: int,
              cache: dict[str, np.ndarray]) -> np.ndarray:
    """Upward surface samples (k, 3) of the placed objects ``names`` at their grounded poses (cached per id)."""
    for q in names:
        if q not in cache:
            cache[q] = starts.upward_samples(scene.get(q).mesh().copy().apply_transform(poses[q]), starts.ONTO_SAMPLES,
                                             seed)
    parts = [cache[q] for q in names]
    return np.vstack(parts) if parts else np.zeros((0, 3))


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


#: :func:`_joint_settle`: how many more times the scene is released for ``joint_settle_frames`` when, at the cap, an
#: object still moves farther over the settling window than ``joint_tol`` / ``joint_tol_deg``: a table tipping over
#: under the load placed on it, cut off half-way (its rest is what the regrounding starts from), where an object
#: that only rocks in place moves less than a millimetre.
JOINT_EXTENSIONS = 2


def _still_falling(entry: dict, fp: FaithfulParams) -> bool:
    """Whether an object of a joint simulation's log (:func:`~phiscene.baselines.joint_sim.joint_sim`) moved farther
    over its last settling window than ``joint_tol`` / ``joint_tol_deg``; a window not yet full counts as moving."""
    moved, turned = entry["residual_translation"], entry["residual_rotation"]
    return moved is None or turned is None or beyond((moved, turned), fp.joint_tol, fp.joint_tol_deg)


def _joint_settle(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, cache_dir: Path, fp: FaithfulParams,
                  sp: SettleParams, objects: dict[str, dict], coms: dict[str, np.ndarray],
                  inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Release the sequentially grounded scene as a whole until every object is at rest; the poses it ends at.

    Sequential settling tests each object against a frozen context: a supporter is never tested under the load
    of what was placed on it later (a book that tips under the box put on its edge). One joint simulation
    (:func:`~phiscene.baselines.joint_sim.joint_sim`, attached objects static) ends that: objects that were
    at rest do not move, the others find the rest their neighbours allow. Cut off at ``joint_settle_frames`` with
    an object still moving farther over the settling window than ``joint_tol`` / ``joint_tol_deg`` (falling, not
    rocking in place), the scene is released on, up to :data:`JOINT_EXTENSIONS` more times. Each moved object's
    record gets ``joint_settle`` ([m, deg]) and its displacement and rotation change from ``inputs`` (id -> input
    pose (4, 4)) are updated, certificate included (its centre-of-mass displacement with ``coms``: id -> (3,)
    local).
    """
    from phiscene.baselines.joint_sim import JointSimParams, joint_sim

    params = JointSimParams(window=sp.window, eps_pos=sp.eps_pos, eps_rot=sp.eps_rot,
                            max_frames=fp.joint_settle_frames)
    settled, log_ = joint_sim(scene, proxies, sim, params, cache_dir)
    frames = log_["frames"]
    for _ in range(JOINT_EXTENSIONS):
        # at the cap with something still falling (not rocking in place): released on until it lies where it falls
        if log_["all_settled"] or not any(_still_falling(o, fp) for o in log_["objects"].values()):
            break
        settled, log_ = joint_sim(settled, proxies, sim, params, cache_dir)
        frames += log_["frames"]
    poses = {o.id: np.asarray(o.pose, dtype=float) for o in settled.objects}
    for oid in log_["objects"]:
        rec = objects[oid]
        settle_motion = window_motion(np.asarray(scene.get(oid).pose, dtype=float), poses[oid])
        rec["joint_settle"] = [rounded(settle_motion[0]), rounded(np.degrees(settle_motion[1]), 6)]
        _record_motion(rec, inputs[oid], poses[oid], coms.get(oid))
        cert = rec.get("certificate")
        if cert is not None and beyond(settle_motion, fp.joint_tol, fp.joint_tol_deg):
            cert["remedy"] = f"{cert['remedy']}+joint"
    log.info("joint settling: %d frames, %s", frames,
             "all at rest" if log_["all_settled"] else f"not at rest: {', '.join(log_['unsettled'])}")
    return poses


#: :func:`_joint_stage`: how many times joint settling is redone with the objects it threw across the scene held
#: where sequential grounding put them (each time may throw others that were pushed by them).
JOINT_HOLDS = 2


def _joint_stage(scene: Scene, order: list[str], proxies: dict[str, Proxy], params: "AssemblyParams",
                 sim: SimSettings, cache_dir: Path, graph, attached: dict[str, str], poses: dict[str, np.ndarray],
                 objects: dict[str, dict], coms: dict[str, np.ndarray], masses: dict[str, np.ndarray],
                 bases: dict[str, np.ndarray], progress: Callable[[str], None] | None,
                 eye: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Joint settling (:func:`_joint_settle`) and the regrounding of what it brought down
    (:func:`_reground_collapsed`, with ``reground``); the poses (id -> (4, 4)) the scene ends at.

    With ``hold_far`` (remedy ``held``), an object that ends farther than its bound
    (:func:`~phiscene.assembly.guarded.far_bound`) from where sequential grounding put it was thrown across the
    scene by the release (pushed out of what it was put through: a reconstruction's chairs in its table): the
    stage is redone from the sequential poses, ``poses``, with it held static there (attached to the ground,
    its record's ``settled`` false, ``settle_remedy`` and the certificate's remedy ``held``, ``joint_held``: how
    far it was thrown, m), up to :data:`JOINT_HOLDS` times. Records, declared centres of mass and bases are
    those of sequential grounding again each time. ``attached`` and the records are updated in place.
    """
    fp = params.faithful
    inputs = {o: np.asarray(scene.get(o).pose, float) for o in order}
    sequential, saved = dict(poses), copy.deepcopy((objects, masses, bases, attached))
    for attempt in range(JOINT_HOLDS + 1):
        out = _joint_settle(_as_grounded(scene.with_poses(sequential), attached, masses, bases), proxies, sim,
                            cache_dir, fp, params.settle_params, objects, coms, inputs)
        if fp.reground:
            out = _reground_collapsed(scene, order, proxies, params, sim, cache_dir, graph, attached, out,
                                      objects, coms, masses, bases, progress, eye)
        thrown = _thrown(scene, inputs, sequential, out, coms, attached, fp) if fp.hold_far > 0 else {}
        if not thrown or attempt == JOINT_HOLDS:
            return out
        # again from the sequential rest, the thrown objects held there
        for oid, distance in thrown.items():
            saved[3][oid] = "ground"
            saved[0][oid].update(settled=False, settle_remedy="held", joint_held=rounded(distance))
            cert = saved[0][oid].get("certificate")
            if cert is not None:
                cert.update(settled=False, remedy="held")
        _restore((objects, masses, bases, attached), saved)
        if progress is not None:
            progress("thrown across the scene when it was released together, held where it was grounded: "
                     + ", ".join(f"{o} ({d:.2f} m)" for o, d in thrown.items()))
        log.warning("joint settling threw %s across the scene: held where grounded, settled again",
                    ", ".join(thrown))
    return out


def _thrown(scene: Scene, inputs: dict[str, np.ndarray], sequential: dict[str, np.ndarray],
            poses: dict[str, np.ndarray], coms: dict[str, np.ndarray], attached: dict[str, str],
            fp: FaithfulParams) -> dict[str, float]:
    """The free objects the joint stage threw across the scene, each with how far (m): their centre of mass ends
    farther than their remedy-``held`` bound (:func:`~phiscene.assembly.guarded.far_bound` of the bounding-box
    diagonal) from where ``sequential`` put it, and farther from ``inputs`` than it was there (a regrounded object
    brought back near its input is not thrown). Poses id -> (4, 4); ``coms``: id -> (3,) local."""
    out = {}
    for oid in poses:
        if oid in attached or oid not in coms:
            continue
        diag = _diagonal(scene.get(oid))
        at = {k: resting.com_world(p[oid], coms[oid]) for k, p in (("end", poses), ("seq", sequential),
                                                                  ("input", inputs))}
        moved = float(np.linalg.norm(at["end"] - at["seq"]))
        if (moved > guarded.far_bound(diag, fp)
                and np.linalg.norm(at["end"] - at["input"]) > np.linalg.norm(at["seq"] - at["input"])):
            out[oid] = moved
    return out


def _record_motion(rec: dict, initial: np.ndarray, pose: np.ndarray, com: np.ndarray | None) -> None:
    """Set an object's record's ``displacement`` and ``rotation_change`` from ``initial`` to ``pose`` ((4, 4)), and
    its certificate's (centre-of-mass displacement with ``com``, (3,) local; deg), when it has one."""
    total, turned = window_motion(initial, pose)
    rec.update(displacement=rounded(total), rotation_change=rounded(turned))
    cert = rec.get("certificate")
    if cert is not None:
        cert["displacement"] = rounded(float(np.linalg.norm(resting.com_world(pose, com)
                                                            - resting.com_world(initial, com))))
        cert["rotation_change"] = rounded(np.degrees(turned), 6)


def _restore(stores: tuple[dict, ...], saved: tuple[dict, ...]) -> None:
    """Put a deep copy of each of ``saved`` back into the dict of ``stores`` at its place, in place (the records,
    declared centres of mass, bases and attachments of a grounding undone)."""
    for store, before in zip(stores, copy.deepcopy(saved)):
        store.clear()
        store.update(before)


def _collapsed(rec: dict, fp: FaithfulParams) -> bool:
    """Whether joint settling undid an object's placement: it turned past ``max_stable_angle`` (toppled) or moved
    farther than ``reground_move`` (fell) when the whole scene was released."""
    moved = rec.get("joint_settle")
    return moved is not None and (moved[1] > fp.max_stable_angle or moved[0] > fp.reground_move)


def _sunk(scene: Scene, poses: dict[str, np.ndarray], proxies: dict[str, Proxy], bases: dict[str, np.ndarray],
          ids: list[str], depth: float) -> set[str]:
    """The objects of ``ids`` whose collision shape (proxies with their completed base, at ``poses``) reaches
    deeper than ``depth`` (m) below the ground: pushed through the floor by a joint release of objects that
    overlap (a reconstruction's chairs through its tables), which no later stage undoes and which drops every
    object of the drift tests with it (their ground is the scene's lowest point, :func:`~phiscene.scene.
    ground_below`)."""
    out = set()
    for oid in ids:
        hulls = with_base(proxies[oid], bases.get(oid)).hulls
        lowest = min(float(transform_points(poses[oid], np.asarray(h, dtype=float))[:, 2].min()) for h in hulls)
        if lowest < scene.ground_height - depth:
            out.add(oid)
    return out


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

    An object the first joint settling left through the floor (:func:`_sunk`, deeper than ``contact_tol``) counts as
    collapsed too.

    That last joint settling may bring the scene down instead (:func:`_collapsed` or through the floor: the vase put
    back on a dish in a Gen3DSR reconstruction, released with it, tips the dish over and what stands on it). Then
    the regrounded poses are undone: every record and the declared centres of mass and bases are those of the first
    joint settling's rest again, and each regrounded object's ``reground`` gets ``kept`` false and ``undone`` (the
    ids that collapsed). Not when that rest has an object through the floor that the last one has lifted out
    (Digital Cousins' classroom: a chair pushed 27 cm into the floor dropped every object of the drift test with
    it), nor when only objects that had collapsed before collapse again and they end nearer their input in all
    (their summed displacement): the last rest is then the better of two (a SceneGen room whose first release threw
    two objects 3.5 m).

    Returns
    -------
    The poses (id -> (4, 4)) after the final joint settling (``poses`` when nothing was kept; the first joint
    settling's when the final one collapsed).
    """
    from phiscene.sim.bullet import BulletWorld

    fp, pp = params.faithful, params.penetration_params
    free = [o for o in order if o not in attached]
    sunk = _sunk(scene, poses, proxies, bases, free, fp.contact_tol)
    collapsed = [o for o in free if _collapsed(objects[o], fp) or o in sunk]
    if not collapsed:
        return poses
    kept = []
    # the first joint settling's rest, to go back to if releasing the regrounded scene brings it down
    before, saved = dict(poses), copy.deepcopy((objects, masses, bases, attached))
    for oid in collapsed:
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
            new = guarded.settle_faithful(world, oid, obj.mesh(), proxies[oid], pose, sim, params.settle_params, fp,
                                          info, rec, obj.com)
        closer = (certify.closeness(initial, new, info["com"], info["diag"])
                  < certify.closeness(initial, poses[oid], info["com"], info["diag"]))
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
            if rec["settle_remedy"] in guarded.KEPT_REMEDIES:  # kept where it was put, static: as if attached
                attached[oid] = "ground"  # no joint settling moves it now: its record is final here
                objects[oid].update(settled=rec["settled"], settle_remedy=rec["settle_remedy"])
                _record_motion(objects[oid], initial, new, coms.get(oid))
                if cert is not None:
                    cert["settled"] = rec["settled"]
            if cert is not None:
                cert["remedy"] = f"{cert['remedy']}+reground"
                cert["touching"] = rec.get("touching", cert["touching"])
    if not kept:
        return poses
    settled = _joint_settle(_as_grounded(scene.with_poses(poses), attached, masses, bases), proxies, sim, cache_dir,
                            fp, params.settle_params, objects, coms,
                            {o: np.asarray(scene.get(o).pose, float) for o in order})
    sunk_after = _sunk(scene, settled, proxies, bases, free, fp.contact_tol)
    fallen = [o for o in free if o not in attached and (_collapsed(objects[o], fp) or o in sunk_after)]
    if not fallen or sunk - sunk_after:
        return settled

    def far(records: dict[str, dict]) -> float:
        return sum(float(records[o].get("displacement", 0.0)) for o in collapsed)

    if set(fallen) <= set(collapsed) and far(objects) <= far(saved[0]):
        # nothing broke that had held before, and what fell again lies nearer its input than where it first fell
        return settled
    # released together, the scene with the regrounded objects collapsed (a vase put back on a dish tips the dish
    # over, and what stands on it): the regrounded poses are undone, the first joint settling's rest is kept
    attempts = {oid: rec["reground"] for oid, rec in objects.items() if "reground" in rec}
    _restore((objects, masses, bases, attached), saved)
    for oid, attempt in attempts.items():
        objects[oid]["reground"] = {**attempt, "kept": False, "undone": fallen} if oid in kept else attempt
    if progress is not None:
        progress(f"released together, the scene with {', '.join(kept)} grounded again collapsed ({', '.join(fallen)}):"
                 f" kept as the scene came to rest before")
    return before


def _joint_check(scene: Scene, proxies: dict[str, Proxy], sim: SimSettings, cache_dir: Path, fp: FaithfulParams,
                 objects: dict[str, dict]) -> None:
    """Release the grounded scene as a whole (the pybullet drift protocol, ``fp.joint_frames`` frames, every free
    object lifted by ``fp.joint_drop`` first), as it will be written (:func:`~phiscene.scene.as_written`).

    Adds ``joint_drift`` (m, deg) and ``joint_stable`` (within ``joint_tol`` / ``joint_tol_deg``) to each
    object's certificate: sequential settling tests each object against a frozen context only.
    """
    from phiscene.metrics.drift import drift_bullet
    from phiscene.metrics.physical import PhysicalParams

    # the scene as written: a rest on the edge of stability goes either way on the file's rounding
    drift = drift_bullet(as_written(scene), proxies, PhysicalParams(upward_offset=fp.joint_drop,
                                                                     frames=fp.joint_frames), sim, cache_dir)
    for oid, d in drift["objects"].items():
        cert = objects[oid].get("certificate")
        if cert is not None:
            cert["joint_drift"] = [rounded(d["drift_trans"]), rounded(d["drift_rot"], 6)]
            cert["joint_stable"] = bool(d["drift_trans"] <= fp.joint_tol and d["drift_rot"] <= fp.joint_tol_deg)
