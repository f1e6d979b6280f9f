"""Ground truth by simulation: settle a templated scene, verify it is at rest, read its support graph.

Every object is a dynamic pybullet body (convex proxies from
:func:`phiscene.proxies.proxy_for_mesh`, mass properties from
:func:`phiscene.inertia.rigid_props`) above a ground box whose top is ``z = 0``.
The scene is simulated until every body is still (or a time cap), then
rebuilt from those rest poses and released again: the scene is accepted only
if no object drifts by more than the thresholds. Support edges come from the
load-bearing contacts at rest (total contact force, normal + friction,
averaged over the last frames): B supports A when it lifts a fraction of A's
weight, or when it pushes A sideways and A falls once B is removed (leaning).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.inertia import rigid_props
from phiscene.params import Params
from phiscene.proxies import Proxy, ProxyParams, proxy_for_mesh
from phiscene.scene import Scene
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import decompose, rotation_angle

#: Categories whose support is reported as ``contains``.
CONTAINERS = ("tray", "crate", "bowl", "basket")


@dataclass(frozen=True)
class GTParams(Params):
    """Settling, verification and support-graph parameters.

    Attributes
    ----------
    settle_seconds
        Cap on the settling simulation (s).
    rest_frames
        Consecutive frames every body must be still to stop settling early.
    rest_speed, rest_angular_speed
        Stillness thresholds: linear (m/s) and angular (rad/s) speed of every body.
    verify_seconds
        Length of the second release from the rest poses (s).
    verify_rounds
        Releases tried: after a failed one, settling resumes from where the objects got to.
    max_drift_m, max_drift_deg
        Largest accepted translation (m) and rotation (deg) of any object during verification.
    max_shift_m, max_turn_deg
        Largest accepted distance (m) and rotation (deg) between an object's template placement
        and its rest pose.
    support_fraction
        Contact forces below this fraction of the supported object's weight are ignored.
    removal_seconds, removal_move_m
        Sideways support test: the object must move more than ``removal_move_m`` (m) within
        ``removal_seconds`` (s) once the supporter is removed (see :func:`support_edges`).
    average_frames
        Frames at the end of verification over which contact forces are averaged.
    lean_angle_deg
        A load-bearing force tilted more than this from the vertical is a ``leans_on`` relation
        (ground contacts are always ``supports``).
    """

    _label = "ground-truth parameters"

    settle_seconds: float = 4.0
    rest_frames: int = 30
    rest_speed: float = 1e-3
    rest_angular_speed: float = 5e-3
    verify_seconds: float = 2.0
    verify_rounds: int = 3
    max_drift_m: float = 1e-3
    max_drift_deg: float = 0.5
    max_shift_m: float = 0.05
    max_turn_deg: float = 25.0
    support_fraction: float = 0.05
    removal_seconds: float = 0.25
    removal_move_m: float = 0.002
    average_frames: int = 10
    lean_angle_deg: float = 30.0


@dataclass
class GroundTruth:
    """Result of :func:`ground_truth`.

    Attributes
    ----------
    scene
        The scene at its rest poses.
    edges
        Support edges ``{"from", "to", "relation", "confidence", "reason"}`` (``ground`` included).
    drift_m, drift_deg
        Per-object drift during verification.
    settle_frames
        Frames simulated until rest.
    problem
        Why the scene is rejected, or ``None`` when it is accepted.
    """

    scene: Scene
    edges: list[dict]
    drift_m: dict[str, float]
    drift_deg: dict[str, float]
    settle_frames: int
    problem: str | None = None
    supporters: dict[str, set[str]] = field(default_factory=dict)


@contextlib.contextmanager
def scene_world(scene: Scene, settings: SimSettings, proxies: dict[str, Proxy],
                cache_dir: str | Path) -> Iterator[tuple[BulletWorld, dict[str, float]]]:
    """A pybullet world with the ground and every object of ``scene`` as a dynamic body.

    Walls and ceiling (``scene.structure``) are static planes named by their ids; attached objects
    are static bodies (never moved).

    Yields
    ------
    world
        The open :class:`BulletWorld`.
    masses
        Mass (kg) of each free object, by id (attached objects have none).
    """
    with BulletWorld(settings, cache_dir) as world:
        world.add_ground(scene.ground_height)
        world.add_structure(scene.structure)
        masses = {}
        for o in scene.objects:
            hulls = proxies[o.id].hulls
            if o.attached is not None:  # fixed to a wall (or the ground): a static collider, no mass
                world.add_body(o.id, hulls, o.pose, None)
                continue
            props = rigid_props(o.mesh(), hulls, settings.density, decompose(o.pose)[2], o.com)
            world.add_body(o.id, hulls, o.pose, props)
            masses[o.id] = props.mass
        yield world, masses


def _poses(scene: Scene, world: BulletWorld) -> dict[str, np.ndarray]:
    """Every object's pose (4, 4) in ``world``; attached objects keep their scene pose exactly (no round trip)."""
    return {o.id: np.array(o.pose, dtype=float) if o.attached is not None else world.pose(o.id)
            for o in scene.objects}


def _still(world: BulletWorld, ids: list[str], params: GTParams) -> bool:
    for name in ids:
        lin, ang = world.velocity(name)
        if np.linalg.norm(lin) > params.rest_speed or np.linalg.norm(ang) > params.rest_angular_speed:
            return False
    return True


def settle(scene: Scene, settings: SimSettings, proxies: dict[str, Proxy], cache_dir: str | Path,
           params: GTParams) -> tuple[dict[str, np.ndarray], int]:
    """Simulate every object under gravity until all are still for ``rest_frames`` frames (or the cap).

    Returns
    -------
    poses
        Rest pose (4, 4) of each object, by id.
    frames
        Frames simulated.
    """
    cap = int(round(params.settle_seconds / settings.frame_dt))
    with scene_world(scene, settings, proxies, cache_dir) as (world, _):
        still = 0
        frame = 0
        while frame < cap and still < params.rest_frames:
            world.step_frames(1)
            frame += 1
            still = still + 1 if _still(world, scene.ids, params) else 0
        return _poses(scene, world), frame


@dataclass
class Release:
    """What :func:`release` measures.

    Attributes
    ----------
    drift_m, drift_deg
        Translation (m) and rotation (deg) of each object from its start pose.
    forces
        Total contact force (3,) (normal + friction) on A from B, averaged over the last
        ``average_frames`` frames, by (A, B); each touching pair once.
    normal_forces
        The normal part alone, on A from B, for both orders (A, B) and (B, A).
    masses
        Mass of each object (kg).
    end
        Pose (4, 4) of each object at the end.
    """

    drift_m: dict[str, float]
    drift_deg: dict[str, float]
    forces: dict[tuple[str, str], np.ndarray]
    normal_forces: dict[tuple[str, str], np.ndarray]
    masses: dict[str, float]
    end: dict[str, np.ndarray]


def release(scene: Scene, settings: SimSettings, proxies: dict[str, Proxy], cache_dir: str | Path,
            params: GTParams) -> Release:
    """Release the scene from its poses for ``verify_seconds``; measure drift and the contact forces at the end."""
    frames = int(round(params.verify_seconds / settings.frame_dt))
    n_avg = max(1, min(params.average_frames, frames))
    with scene_world(scene, settings, proxies, cache_dir) as (world, masses):
        world.step_frames(frames - n_avg)
        total: dict[tuple[str, str], np.ndarray] = {}
        normal: dict[tuple[str, str], np.ndarray] = {}
        for _ in range(n_avg):
            world.step_frames(1)
            for key, f in world.contact_forces().items():
                total[key] = total.get(key, 0.0) + f / n_avg
            for o in scene.objects:
                for c in world.contacts(o.id):
                    key = (o.id, c["other"])
                    normal[key] = normal.get(key, 0.0) + c["normal"] * c["force"] / n_avg
        objects = set(scene.ids)
        for (a, b), f in list(normal.items()):  # contacts with ground and walls are only listed from the object's side
            if b not in objects:
                normal[(b, a)] = -f
        end = _poses(scene, world)
    drift_m, drift_deg = {}, {}
    for o in scene.objects:
        R0, t0, _ = decompose(o.pose)
        R1, t1, _ = decompose(end[o.id])
        drift_m[o.id] = float(np.linalg.norm(t1 - t0))
        drift_deg[o.id] = float(np.degrees(rotation_angle(R0, R1)))
    return Release(drift_m, drift_deg, total, normal, masses, end)


def forces_on(forces: dict[tuple[str, str], np.ndarray]) -> dict[tuple[str, str], np.ndarray]:
    """Both directions of every pair force: ``{(a, b): force on a from b}`` with ``f(b, a) = -f(a, b)``."""
    on: dict[tuple[str, str], np.ndarray] = {}
    for (a, b), f in forces.items():
        on[(a, b)] = on.get((a, b), 0.0) + f
        on[(b, a)] = on.get((b, a), 0.0) - f
    return on


def moves_without(scene: Scene, removed: str, settings: SimSettings, proxies: dict[str, Proxy],
                  cache_dir: str | Path, params: GTParams) -> dict[str, float]:
    """How far (m) each remaining object moves in ``removal_seconds`` once ``removed`` is taken away."""
    kept = Scene([o for o in scene.objects if o.id != removed], scene.ground_height,
                 structure=[p for p in scene.structure if p.id != removed])
    with scene_world(kept, settings, proxies, cache_dir) as (world, _):
        world.step_frames(max(1, int(round(params.removal_seconds / settings.frame_dt))))
        return {o.id: float(np.linalg.norm(world.pose(o.id)[:3, 3] - o.pose[:3, 3])) for o in kept.objects}


#: Relation of an object fixed to a wall (or the ground): the edge ``holder -> object``.
ATTACHED = "attached"


def support_edges(scene: Scene, measured: Release, settings: SimSettings, proxies: dict[str, Proxy],
                  cache_dir: str | Path, params: GTParams) -> list[dict]:
    """Support edges of a scene at rest.

    B supports A when, at rest, B pushes on A (force not pointing down by more than
    ``support_fraction`` of A's weight) and either

    * lifts A: the force's up component exceeds ``support_fraction`` of A's weight, or
    * holds A up sideways: its force exceeds that fraction and A moves more than
      ``removal_move_m`` within ``removal_seconds`` once B is removed (a board leaning
      on a vertical wall gets no lift from it).

    The relation is ``contains`` for a container (:data:`CONTAINERS`), ``leans_on`` when the contact normals
    (normal forces summed) are tilted more than ``lean_angle_deg`` from the vertical or the
    support is sideways, else ``supports``; the ground only ever ``supports``, a wall or ceiling
    plane (``scene.structure``, named by its id) only ever ``leans_on``. An attached object
    (:attr:`~phiscene.scene.SceneObject.attached`) gets exactly one edge, ``attached`` from what holds it.

    Parameters
    ----------
    scene
        The scene at rest.
    measured
        Forces and masses from :func:`release` (pair keys may name ``ground``).
    settings, proxies, cache_dir, params
        For the removal simulations and the thresholds.

    Returns
    -------
    Edges ``{"from": b, "to": a, "relation", "confidence": 1.0, "reason"}`` sorted by (to, from).
    """
    categories = {o.id: o.meta.get("category", "") for o in scene.objects}
    planes = {p.id for p in scene.structure}
    masses = measured.masses
    on = forces_on(measured.forces)
    removal: dict[str, dict[str, float]] = {}
    edges = []
    for (a, b), f in sorted(on.items(), key=lambda kv: kv[0]):
        if a == "ground" or a not in masses:
            continue
        weight = masses[a] * GRAVITY
        limit = params.support_fraction * weight
        if f[2] < -limit or np.linalg.norm(f) <= limit:
            continue
        tilt = float(np.degrees(np.arctan2(np.linalg.norm(f[:2]), f[2])))
        fn = measured.normal_forces.get((a, b), np.zeros(3))
        normal_tilt = float(np.degrees(np.arctan2(np.linalg.norm(fn[:2]), fn[2])))
        if f[2] > limit:
            lean = b != "ground" and normal_tilt > params.lean_angle_deg
            reason = (f"lifts {100 * f[2] / weight:.0f}% of the weight at rest; contact normal {normal_tilt:.0f} deg "
                      f"from vertical")
        elif b != "ground":
            if b not in removal:
                removal[b] = moves_without(scene, b, settings, proxies, cache_dir, params)
            if removal[b][a] <= params.removal_move_m:
                continue
            lean = True
            reason = (f"pushes with {100 * np.linalg.norm(f) / weight:.0f}% of the weight, {tilt:.0f} deg from "
                      f"vertical; without it the object moves {1000 * removal[b][a]:.0f} mm in "
                      f"{params.removal_seconds:g} s")
        else:
            continue
        relation = "contains" if categories.get(b) in CONTAINERS else "leans_on" if lean or b in planes \
            else "supports"
        edges.append({"from": b, "to": a, "relation": relation, "confidence": 1.0, "reason": reason})
    for o in scene.objects:
        if o.attached is not None:
            edges.append({"from": o.attached, "to": o.id, "relation": ATTACHED, "confidence": 1.0,
                          "reason": f"fixed to {o.attached}"})
    edges.sort(key=lambda e: (e["to"], e["from"]))
    return edges


def _drift_problem(drift_m: dict[str, float], drift_deg: dict[str, float], params: GTParams) -> str | None:
    worst = max(drift_m, key=lambda i: drift_m[i] / params.max_drift_m + drift_deg[i] / params.max_drift_deg)
    if drift_m[worst] >= params.max_drift_m or drift_deg[worst] >= params.max_drift_deg:
        return (f"not at rest: {worst} drifts {1000 * drift_m[worst]:.2f} mm / {drift_deg[worst]:.2f} deg when "
                f"released again (limits {1000 * params.max_drift_m:g} mm / {params.max_drift_deg:g} deg)")
    return None


def ground_truth(scene: Scene, settings: SimSettings, proxy_params: ProxyParams, cache_dir: str | Path,
                 params: GTParams, intended: dict[str, set[str]] | None = None) -> GroundTruth:
    """Settle ``scene``, verify it is at rest and derive its support edges.

    Parameters
    ----------
    scene
        Objects at their template placements (meshes on disk; ground height 0).
    settings, proxy_params, cache_dir
        Simulation settings, proxy parameters and the proxy/hull cache folder.
    params
        Thresholds.
    intended
        Optional intended supporters of each object (ids or ``ground``); a scene where an object
        lost one of them or newly touches the ground with load (it fell off), or where any object
        moved or turned more than ``max_shift_m`` / ``max_turn_deg`` while settling, is rejected.

    Returns
    -------
    :class:`GroundTruth` whose ``problem`` is ``None`` when the scene is accepted.
    """
    proxies = {o.id: proxy_for_mesh(o.mesh_path, proxy_params, cache_dir) for o in scene.objects}
    rest, frames = settle(scene, settings, proxies, cache_dir, params)
    rested = scene.with_poses(rest)
    for _ in range(params.verify_rounds):  # a slow creep left by settling: settle on from where it got to
        measured = release(rested, settings, proxies, cache_dir, params)
        if _drift_problem(measured.drift_m, measured.drift_deg, params) is None:
            break
        rest, more = settle(scene.with_poses(measured.end), settings, proxies, cache_dir, params)
        rested = scene.with_poses(rest)
        frames += int(round(params.verify_seconds / settings.frame_dt)) + more
    edges = support_edges(rested, measured, settings, proxies, cache_dir, params)
    supporters: dict[str, set[str]] = {i: set() for i in scene.ids}
    for e in edges:
        supporters[e["to"]].add(e["from"])
    gt = GroundTruth(rested, edges, measured.drift_m, measured.drift_deg, frames, supporters=supporters)
    gt.problem = _drift_problem(measured.drift_m, measured.drift_deg, params)
    if gt.problem:
        return gt
    for o in scene.objects:
        (R0, t0, _), (R1, t1, _) = decompose(o.pose), decompose(rest[o.id])
        shift, turn = float(np.linalg.norm(t1 - t0)), float(np.degrees(rotation_angle(R0, R1)))
        if shift > params.max_shift_m or turn > params.max_turn_deg:
            gt.problem = (f"{o.id} moved {100 * shift:.1f} cm / turned {turn:.0f} deg while settling "
                          f"(limits {100 * params.max_shift_m:g} cm / {params.max_turn_deg:g} deg)")
            return gt
        if intended is None or o.id not in intended:
            continue
        lost = sorted(intended[o.id] - supporters[o.id])
        fell = "ground" in supporters[o.id] and "ground" not in intended[o.id]
        if lost or fell:
            gt.problem = (f"{o.id} should rest on {', '.join(sorted(intended[o.id]))} but rests on "
                          f"{', '.join(sorted(supporters[o.id])) or 'nothing'}")
            return gt
    return gt
