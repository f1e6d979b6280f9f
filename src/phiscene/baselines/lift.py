"""Top-down lifting, then joint simulation (PAT3D-style baseline, paper Tab. 6 "lift + sim.").

1. **Single parent.** PAT3D keeps one parent per object, the first one its
   support relation lists. Our support graphs may give several; "first" is
   made deterministic as the parent of the highest confidence, ties broken by
   the order of the graph's edges (:func:`single_parent`). An object without a
   parent rests on the ground. Cycles, if the graph has any, are broken first
   exactly as the placement order does (:func:`phiscene.topology.order.break_cycles`).
2. **Lift.** Objects are visited in breadth-first order from the ground over
   the single-parent tree (parents before children). Each object is translated
   along +z so that its lowest world point lies ``gap`` above the top of its
   parent's world AABB (as already lifted), or ``gap`` above the ground plane
   for ground-parented objects. Only upward moves are made: an object already
   higher than that keeps its height (it falls in step 3). Rotation, scale and
   x, y are unchanged.
3. **Joint simulation** of all objects (:func:`~phiscene.baselines.joint_sim.joint_sim`).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.baselines.joint_sim import JointSimParams, joint_sim
from phiscene.params import Params
from phiscene.proxies import Proxy, check_proxies
from phiscene.scene import Scene
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import GROUND, SupportGraph, check_graph
from phiscene.topology.order import break_cycles

#: Format tag of the lift log.
LOG_FORMAT = "phiscene.lift_sim_log/1"


@dataclass(frozen=True)
class LiftParams(Params):
    """Parameters of the lift baseline.

    Attributes
    ----------
    gap
        Clearance (m) between a lifted object's lowest point and its parent's AABB top (or the ground).
    sim
        Joint simulation stopping rule, see :class:`~phiscene.baselines.joint_sim.JointSimParams`.
    """

    _label = "lift parameters"
    _coerce = {"gap": float}

    gap: float = 0.002
    sim: JointSimParams = field(default_factory=JointSimParams)

    def check(self) -> None:
        """Reject a negative or non-finite ``gap`` (``ValueError``)."""
        if not (np.isfinite(self.gap) and self.gap >= 0.0):
            raise ValueError(f"lift gap must be finite and >= 0, got {self.gap}")


def single_parent(graph: SupportGraph) -> dict[str, str]:
    """One parent per object: the most confident supporter, ties by edge order; ``ground`` if none.

    A wall or ceiling (a ``structure`` node) is never a parent: nothing is lifted above a wall, so an object
    leaning on one or fixed to one counts as resting on the ground unless an object supports it.

    Parameters
    ----------
    graph
        A support graph (any relation counts as support).

    Returns
    -------
    ``{object id: parent id or "ground"}`` for every object of the graph, in graph order.
    """
    best: dict[str, tuple[float, str]] = {}
    walls = set(graph.structure)
    for e in graph.edges:
        if e.source in walls:
            continue
        if e.target not in best or e.confidence > best[e.target][0]:
            best[e.target] = (e.confidence, e.source)
    return {oid: best[oid][1] if oid in best else GROUND for oid in graph.object_ids}


def depth_order(parents: dict[str, str]) -> list[tuple[str, int]]:
    """Breadth-first order from the ground over a single-parent forest.

    Parameters
    ----------
    parents
        ``{object id: parent id or "ground"}``; must be acyclic.

    Returns
    -------
    ``[(object id, depth)]``, depth 1 for ground-parented objects; children in ``parents`` order.

    Raises
    ------
    ValueError
        Objects not reachable from the ground (a cycle or an unknown parent).
    """
    children: dict[str, list[str]] = {}
    for oid, parent in parents.items():
        children.setdefault(parent, []).append(oid)
    out: list[tuple[str, int]] = []
    queue = deque([(GROUND, 0)])
    while queue:
        node, depth = queue.popleft()
        for c in children.get(node, []):
            out.append((c, depth + 1))
            queue.append((c, depth + 1))
    missing = sorted(set(parents) - {oid for oid, _ in out})
    if missing:
        raise ValueError(f"objects not reachable from the ground through single parents: {missing}")
    return out


def lift_scene(scene: Scene, parents: dict[str, str], gap: float) -> tuple[Scene, dict]:
    """Lift every object above its parent's world AABB top (or the ground), parents first.

    Parameters
    ----------
    scene
        The scene.
    parents
        ``{object id: parent id or "ground"}`` for every object of the scene.
    gap
        Clearance above the parent's top (m).

    Returns
    -------
    scene
        The lifted scene (only z translations differ).
    info
        Per object id: ``parent``, ``depth``, ``lift`` (m, >= 0), ``target`` (height its lowest point was
        asked to clear, m).
    """
    bounds = {o.id: np.asarray(o.world_mesh().bounds, dtype=float) for o in scene.objects}
    poses: dict[str, np.ndarray] = {}
    info: dict[str, dict] = {}
    for oid, depth in depth_order(parents):
        parent = parents[oid]
        target = (scene.ground_height if parent == GROUND else bounds[parent][1, 2]) + gap
        dz = max(0.0, float(target - bounds[oid][0, 2]))
        bounds[oid] = bounds[oid] + np.array([0.0, 0.0, dz])
        pose = np.array(scene.get(oid).pose, dtype=float)
        pose[2, 3] += dz
        poses[oid] = pose
        info[oid] = {"parent": parent, "depth": depth, "lift": dz, "target": float(target)}
    return scene.with_poses(poses), info


def lift_sim(scene: Scene, graph: SupportGraph, proxies: dict[str, Proxy], sim: SimSettings, params: LiftParams,
             cache_dir: str | Path) -> tuple[Scene, dict]:
    """PAT3D-style baseline: single parents, top-down lifting, joint simulation.

    Parameters
    ----------
    scene
        The initial scene.
    graph
        Its support graph (object set equal to the scene's).
    proxies
        Convex proxies by object id.
    sim
        Physical settings of the simulation.
    params
        Lift gap and simulation stopping rule.
    cache_dir
        Folder for pybullet's hull files.

    Returns
    -------
    scene
        The simulated scene.
    record
        JSON-ready log: ``format``, ``params``, ``dropped_edges`` (cycle breaking), ``objects`` (per id:
        ``parent``, ``depth``, ``lift``, ``target``), ``sim`` (the joint simulation log), ``seconds``.

    Raises
    ------
    InputError
        The graph's objects differ from the scene's, or an object has no proxy.
    """
    t0 = time.perf_counter()
    check_graph(graph, None, scene.ids)
    check_proxies(scene, proxies)
    kept, dropped = break_cycles(graph.edges)
    parents = single_parent(graph.with_edges(kept))
    lifted, info = lift_scene(scene, parents, params.gap)
    t_lift = time.perf_counter() - t0
    settled, sim_log = joint_sim(lifted, proxies, sim, params.sim, cache_dir)
    record = {"format": LOG_FORMAT, "params": params.to_dict(), "dropped_edges": [e.to_dict() for e in dropped],
              "objects": {oid: info[oid] for oid in scene.ids}, "sim": sim_log,
              "seconds": {"lift": t_lift, "total": time.perf_counter() - t0}}
    return settled, record
