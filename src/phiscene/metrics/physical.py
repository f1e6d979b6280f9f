"""Physical plausibility metrics (paper supplement, "Physical Plausibility Metrics").

Static contact validity
    Every object gets ``samples`` seeded surface samples on its world-frame mesh.
    For each object pair ``i != j`` the worst bidirectional signed distance is
    ``w_ij = min(min_n SDF(p_i,n, o_j), min_m SDF(p_j,m, o_i))`` (exact signed
    distance, :mod:`phiscene.sdf`); ``w_i = min_j w_ij``; the penetration depth
    is ``max(0, -w_i)`` and the floating distance ``max(0, w_i)``; the scene
    values are means over objects.

    Ground: the paper names object pairs only. With ``include_ground`` (the
    default) the ground plane ``z = scene.ground_height`` is one more
    surrounding object: the signed distance of a sample to the half-space below
    the plane is ``z - h``, so ``w_i,ground = min_n z_i,n - h`` (one direction:
    the plane has no samples). An object resting on the ground thus has
    ``w_i = 0`` instead of the gap to its nearest neighbour. Without it, an
    object with no other object has no ``w_i``: its floating distance is
    ``None`` (left out of the scene mean; a scene where no object has a
    neighbour reports 0) and its penetration depth 0.

    Pairs are visited in increasing order of the gap ``g_ij`` between their
    padded bounding boxes. A positive gap is a lower bound of ``w_ij`` (every
    sample then lies outside the other mesh's padded box, so it is outside
    that mesh and at least ``g_ij`` from its surface); a pair with
    ``g_ij > 0`` and ``g_ij >= max(w_i, w_j)`` (current values) cannot lower
    either and is skipped; pairs whose boxes touch or overlap are always
    evaluated. The result is identical to evaluating every pair, at a cost
    that grows with the number of nearby pairs rather than all pairs.

Post-simulation drift (pybullet)
    All objects are released together as dynamic compounds of their convex
    proxies (mass properties at ``SimSettings.density``) above a ground box
    whose top is the lowest world z of the free (not attached) objects' collision proxies
    (:func:`phiscene.scene.ground_below`), after lifting every
    object by ``upward_offset``; the world runs ``frames`` frames. Translation
    drift is the distance between the final centre of mass and the original
    one (the lifted one minus the offset); rotation drift is the relative
    rotation angle in degrees. Scene values are means over objects. The MuJoCo
    counterpart is :func:`phiscene.metrics.drift.drift_mujoco`.

Attached objects (:attr:`phiscene.scene.SceneObject.attached`: fixed to a wall, the ceiling or the ground) are
static colliders in both simulators, are not lifted, and are left out of the drift and floating means (their
per-object entries say ``attached``); they still count in the penetration depth. The room's own meshes among them
(a floor or wall mesh, :func:`phiscene.topology.words.names_structure`) are not measured against the ground plane
or against each other: a floor slab runs through the ground plane, a wall through the floor slab, and neither is an
overlap of two things (what else reaches into them still counts).

Units: metres and degrees.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from phiscene.errors import InputError
from phiscene.meshes import sample_surface
from phiscene.params import Params
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import DRIFT_LIFT

if TYPE_CHECKING:
    from phiscene.proxies import Proxy
    from phiscene.scene import Scene
    from phiscene.sdf import SignedDistance

#: Name of the ground in ``closest``.
GROUND = "ground"


@dataclass(frozen=True)
class PhysicalParams(Params):
    """Parameters of the physical metrics (config ``metrics.physical``).

    Attributes
    ----------
    samples
        Surface samples per object (paper: N = 2048).
    seed
        Seed of the surface sampling (each object's stream also depends on its id).
    include_ground
        Count the ground plane as a surrounding object in the static metric.
    upward_offset
        Lift (m) applied to every object before the drift simulation.
    frames
        Frames of ``SimSettings.frame_dt`` simulated for the drift (paper: 120).
    """

    _label = "physical metric parameters"

    samples: int = 2048
    seed: int = 0
    include_ground: bool = True
    upward_offset: float = DRIFT_LIFT
    frames: int = 120

    def __post_init__(self):
        if int(self.samples) < 1:
            raise ValueError(f"samples must be >= 1, got {self.samples}")
        if int(self.frames) < 0:
            raise ValueError(f"frames must be >= 0, got {self.frames}")
        if not (math.isfinite(self.upward_offset) and self.upward_offset >= 0.0):
            raise ValueError(f"upward_offset must be finite and >= 0, got {self.upward_offset}")


# -- static contact validity -----------------------------------------------------------------------------------------
def object_seed(seed: int, object_id: str) -> int:
    """Sampling seed of one object: depends on ``seed`` and the id only (not on the object order)."""
    return int(np.random.SeedSequence([int(seed), zlib.crc32(object_id.encode())]).generate_state(1)[0])


def box_gaps(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distances between axis-aligned boxes (0 where they touch or overlap).

    Parameters
    ----------
    lo, hi : (k, 3) float
        Box corners.

    Returns
    -------
    gaps : (k, k) float
    """
    sep = np.maximum(0.0, np.maximum(lo[None, :, :] - hi[:, None, :], lo[:, None, :] - hi[None, :, :]))
    return np.linalg.norm(sep, axis=2)


def worst_pair_distance(points_i: np.ndarray, sdf_i: "SignedDistance", points_j: np.ndarray,
                        sdf_j: "SignedDistance") -> float:
    """Worst bidirectional signed distance ``w_ij`` of two objects.

    Parameters
    ----------
    points_i, points_j : (n, 3) float
        World surface samples of each object.
    sdf_i, sdf_j
        Signed distance to each object's world mesh.
    """
    return float(min(sdf_j(points_i).min(), sdf_i(points_j).min()))


def contact_validity(scene: "Scene", params: PhysicalParams, prune: bool = True) -> dict:
    """Penetration depth and floating distance of every object and their scene means.

    Parameters
    ----------
    scene
        The scene (world poses, ground height).
    params
        Samples, seed and ``include_ground``.
    prune
        Skip pairs whose bounding-box gap shows they cannot change the result
        (identical output; ``False`` evaluates every pair, for checking).

    Returns
    -------
    ``{"pen_depth": m, "float_dist": m, "pairs_evaluated": int, "objects": {id: {"w": m | None,
    "closest": id | "ground" | None, "pen_depth": m, "float_dist": m | None}}}``
    """
    from phiscene.sdf import sign_box, signed_distance_for
    from phiscene.topology.attached import object_text
    from phiscene.topology.words import names_structure

    objs = scene.objects
    k = len(objs)
    meshes = [o.world_mesh() for o in objs]
    samples = [sample_surface(m, int(params.samples), object_seed(params.seed, o.id)) for m, o in zip(meshes, objs)]
    sdfs: dict[int, "SignedDistance"] = {}

    def sdf(i: int) -> "SignedDistance":
        if i not in sdfs:
            sdfs[i] = signed_distance_for(meshes[i])
        return sdfs[i]

    best = np.full(k, np.inf)
    closest: list[str | None] = [None] * k
    room = {i for i, o in enumerate(objs) if o.attached is not None and names_structure(object_text(o))}
    if params.include_ground:
        for i in range(k):
            if i not in room:  # the room's own meshes are the ground and walls (module notes)
                best[i] = float(samples[i][:, 2].min() - scene.ground_height)
                closest[i] = GROUND
    evaluated = 0
    if k > 1:
        boxes = np.array([sign_box(m) for m in meshes])  # (k, 2, 3)
        gaps = box_gaps(boxes[:, 0], boxes[:, 1])
        iu, ju = np.triu_indices(k, 1)
        order = np.lexsort((ju, iu, gaps[iu, ju]))
        for i, j in zip(iu[order], ju[order]):
            if i in room and j in room:
                continue
            g = gaps[i, j]
            if prune and g > 0.0 and g >= max(best[i], best[j]):
                if g >= best.max():
                    break  # gaps only grow from here and no w_i can drop below them
                continue
            w = worst_pair_distance(samples[i], sdf(i), samples[j], sdf(j))
            evaluated += 1
            for a, b in ((i, j), (j, i)):
                if w < best[a]:
                    best[a], closest[a] = w, objs[b].id
    per = {}
    for i, o in enumerate(objs):
        w = float(best[i]) if np.isfinite(best[i]) else None
        per[o.id] = {"w": w, "closest": closest[i], "pen_depth": max(0.0, -w) if w is not None else 0.0,
                     "float_dist": max(0.0, w) if w is not None and o.attached is None else None}
    floats = [v["float_dist"] for v in per.values() if v["float_dist"] is not None]
    return {"pen_depth": float(np.mean([v["pen_depth"] for v in per.values()])) if per else 0.0,
            "float_dist": float(np.mean(floats)) if floats else 0.0,
            "pairs_evaluated": evaluated, "objects": per}


# -- entry point -----------------------------------------------------------------------------------------------------
def physical_metrics(scene: "Scene", proxies: dict[str, "Proxy"], params: PhysicalParams, sim: SimSettings,
                     cache_dir: str | Path) -> dict:
    """Static contact validity and pybullet post-simulation drift of one scene.

    Returns
    -------
    JSON-ready dict: scene means ``pen_depth``, ``float_dist`` (m), ``drift_trans`` (m),
    ``drift_rot`` (degrees); ``objects``: per object id ``w``, ``closest``, ``pen_depth``,
    ``float_dist``, ``drift_trans``, ``drift_rot``; plus ``pairs_evaluated``,
    ``ground_below`` (height of the drift ground) and ``params``. Undefined values
    (see the module notes on ``include_ground``) are ``None``.
    """
    if not scene.objects:
        raise InputError(scene.source, "objects", "scene has no objects")
    from phiscene.metrics.drift import drift_bullet

    static = contact_validity(scene, params)
    drift = drift_bullet(scene, proxies, params, sim, cache_dir)
    objects = {oid: {**static["objects"][oid], **drift["objects"][oid]} for oid in scene.ids}
    return {"pen_depth": static["pen_depth"], "float_dist": static["float_dist"],
            "drift_trans": drift["drift_trans"], "drift_rot": drift["drift_rot"],
            "pairs_evaluated": static["pairs_evaluated"], "ground_below": drift["ground_below"],
            "params": params.to_dict(), "objects": objects}
