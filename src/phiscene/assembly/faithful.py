"""Faithful grounding: the stable pose closest to the input, kept on the supporters the graph names.

The paper's loop (translation-only SDF, free settling, freeze) lets the simulator
take an object wherever it goes: a slightly tilted block slides off its parent,
a fruit rolls off the table. The faithful variant adds three things around the
same SDF and settling stages (:func:`phiscene.assembly.assemble.ground_scene`):

1. **Flush correction** before the SDF stage. The stable resting poses of the
   object's convex hull (:func:`trimesh.poses.compute_stable_poses`) each rest
   on one hull facet; the facet whose world normal under the input rotation is
   closest to ``-n`` (``n``: the supporters' surface normal under the object's
   footprint, :func:`support_normal`) is made to face exactly ``-n`` by the
   smallest rotation, about the object's centre of mass, if that rotation is at
   most ``max_flush_angle``. Small orientation errors are corrected, large
   ones (a plank leaning on purpose) are left alone. Objects with a
   ``leans_on`` parent are never flushed.
2. **Carried and lowered**. An object supported from below first moves
   with its supporter (``carry``: the supporter's change of pose is applied
   to it), then is lowered straight down onto its supporters (no free fall).
3. **Guarded settling**. After the paper's settling the result is rejected
   when the centre of mass moved (horizontally) farther than the bound (``max_slide`` or
   ``max_slide_frac`` of the object's bounding-box diagonal, the smaller),
   turned more than ``max_turn``, or lost contact with a supporter the graph
   names. A rejected object is restarted from its nearest stable resting
   pose within ``max_stable_angle`` (``stable``, accepted only if it settles
   within the bounds); else the settled result of either that kept its
   supporters and rolled at most ``max_roll`` (``rolled``); else reset to its corrected pose and settled again
   with high damping and rolling friction (``damped``); if that is rejected
   too it is frozen at its corrected pose lowered onto its supporters
   (``held``), whose static equilibrium is then tested with one settling
   window at normal settings (the certificate's ``settled``).
4. **A certificate** per object in the assembly log (:func:`certificate`), with the result of releasing
   the whole grounded scene at once (``joint_stable``; sequential settling only tests an object against a
   frozen context).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phiscene.params import Params
from phiscene.transforms import decompose, make_pose, rotation_angle, transform_points

#: Relations whose parent carries the object from below (its surface normal matters for flushing).
BELOW = ("supports", "contains")


@dataclass(frozen=True)
class FaithfulParams(Params):
    """Settings of the faithful grounding (off = the paper's loop exactly).

    Attributes
    ----------
    enabled
        Run flush correction, guarded settling and the retry remedies.
    flush
        Rotate each object onto its nearest stable resting facet, flush with its supporters.
    max_flush_angle
        Largest flush rotation applied (deg); larger tilts are taken as intended.
    max_slide
        Largest centre-of-mass displacement accepted from settling (m).
    max_slide_frac
        Same bound as a fraction of the object's bounding-box diagonal (the smaller bound applies).
    max_turn
        Largest rotation accepted from settling (deg).
    carry
        Move each object with its (first placed) supporter from below: the supporter's change of pose from
        its input is applied to the object's input pose first.
    joint_frames
        After the loop the whole scene is released for this many frames (0 = no check); each certificate gets
        ``joint_drift`` and ``joint_stable``.
    joint_tol, joint_tol_deg
        ``joint_stable``: the object moved at most this far (m) and turned at most this much (deg).
    max_stable_angle
        Remedy ``stable``: a rejected object is restarted from its nearest stable resting pose when that is
        within this angle (deg) of its pose.
    max_roll
        Remedy ``rolled``: when both fail, the settled result (of either) that kept its supporters and whose
        centre of mass moved at most this far horizontally (m) is taken, the closest to the input.
    contact_tol
        A supporter counts as kept when the object is within this distance of it at rest (m).
    retry_damping
        Linear and angular damping of the ``damped`` retry (Bullet units, in [0, 1)).
    retry_rolling_friction
        Rolling and spinning friction of the ``damped`` retry.
    """

    _label = "faithful parameters"

    enabled: bool = False
    flush: bool = True
    max_flush_angle: float = 20.0
    max_slide: float = 0.03
    max_slide_frac: float = 0.25
    max_turn: float = 10.0
    carry: bool = True
    joint_frames: int = 120
    joint_tol: float = 0.005
    joint_tol_deg: float = 1.0
    max_stable_angle: float = 45.0
    max_roll: float = 0.1
    contact_tol: float = 0.004
    retry_damping: float = 0.9
    retry_rolling_friction: float = 0.1

    def check(self) -> None:
        """Reject negative bounds and ``retry_damping`` outside [0, 1) (``ValueError``)."""
        for key in ("max_flush_angle", "max_stable_angle", "max_roll", "joint_frames", "joint_tol", "joint_tol_deg",
                    "max_slide", "max_slide_frac", "max_turn", "contact_tol", "retry_rolling_friction"):
            if getattr(self, key) < 0:
                raise ValueError(f"faithful parameter {key!r} must be >= 0, got {getattr(self, key)}")
        if not 0.0 <= self.retry_damping < 1.0:
            raise ValueError(f"faithful retry_damping must be in [0, 1), got {self.retry_damping}")


def support_normal(mesh_world, parents_world: dict[str, object]) -> np.ndarray:
    """Unit surface normal (3,) of the supporters under an object's footprint.

    Parameters
    ----------
    mesh_world
        The object's mesh in world coordinates (trimesh).
    parents_world
        Supporters carrying it from below: ``"ground"`` maps to ``None`` (normal +z), others to their
        world-frame mesh.

    Returns
    -------
    The area-weighted mean of the upward-facing supporter face normals closest to the object's lowest
    points (within 10% of its height of its lowest point), or +z when none face up.
    """
    import trimesh

    up = np.array([0.0, 0.0, 1.0])
    objects = {k: m for k, m in parents_world.items() if m is not None}
    if not objects:
        return up
    v = np.asarray(mesh_world.convex_hull.vertices)
    zmin, zmax = v[:, 2].min(), v[:, 2].max()
    low = v[v[:, 2] <= zmin + 0.1 * max(zmax - zmin, 1e-6)]
    acc = np.zeros(3)
    if "ground" in parents_world:
        acc += up * len(low)
    for m in objects.values():
        _, dist, tri = trimesh.proximity.closest_point(m, low)
        n = m.face_normals[tri]
        near = dist <= max(0.02, 2 * float(np.min(dist)))
        w = (n[:, 2] > 0.5) & near
        acc += (n[w] * m.area_faces[tri][w, None] / max(float(m.area_faces[tri][w].mean()), 1e-12)
                if w.any() else np.zeros((0, 3))).sum(axis=0)
    norm = np.linalg.norm(acc)
    return acc / norm if norm > 1e-9 else up


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit vector ``a`` to unit vector ``b``."""
    from scipy.spatial.transform import Rotation

    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        return Rotation.from_rotvec(perp / np.linalg.norm(perp) * math.pi).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def resting_normals(hull_points: np.ndarray) -> np.ndarray:
    """Outward normals (k, 3), local frame, of the facets the object's convex hull can rest on.

    Parameters
    ----------
    hull_points : (n, 3) float
        Points whose convex hull is the object's collision shape (local, unscaled).
    """
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(hull_points, dtype=float))
    transforms, _ = trimesh.poses.compute_stable_poses(hull, center_mass=hull.center_mass, n_samples=1,
                                                        threshold=0.0)
    # Each transform rests the hull on z = 0: its resting facet's normal maps to -z.
    return np.array([T[:3, :3].T @ np.array([0.0, 0.0, -1.0]) for T in transforms]).reshape(-1, 3)


def flush_pose(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, up: np.ndarray,
               max_angle_deg: float) -> tuple[np.ndarray, float]:
    """The pose rotated so its nearest resting facet faces ``-up``, about its centre of mass.

    Parameters
    ----------
    pose : (4, 4) float
        Input pose (uniform scale allowed).
    normals_local : (k, 3) float
        Resting facet normals (:func:`resting_normals`).
    com_local : (3,) float
        Centre of mass, local frame (the rotation's fixed point).
    up : (3,) float
        Unit supporter normal.
    max_angle_deg
        Rotations larger than this are not applied.

    Returns
    -------
    pose : (4, 4) float
        The flushed pose (``pose`` itself when none is within ``max_angle_deg``).
    angle
        The rotation applied (deg; 0 when none).
    """
    if len(normals_local) == 0:
        return pose, 0.0
    R, t, s = decompose(pose)
    world = normals_local @ R.T
    cos = world @ -up
    k = int(np.argmax(cos))
    angle = math.degrees(math.acos(float(np.clip(cos[k], -1.0, 1.0))))
    if angle > max_angle_deg or angle < 1e-9:
        return pose, 0.0
    Q = _rotation_between(world[k] / np.linalg.norm(world[k]), -up)
    c = transform_points(pose, np.asarray(com_local, dtype=float)[None])[0]
    R2 = Q @ R
    t2 = c - Q @ (c - t)
    return make_pose(R2, t2, s), angle


def com_world(pose: np.ndarray, com_local: np.ndarray) -> np.ndarray:
    """World position (3,) of a local point (the centre of mass) under ``pose``."""
    return transform_points(pose, np.asarray(com_local, dtype=float)[None])[0]


def within_bounds(before: np.ndarray, after: np.ndarray, com_local: np.ndarray, diag: float,
                  fp: FaithfulParams) -> tuple[bool, float, float]:
    """Whether settling from ``before`` to ``after`` (poses (4, 4)) stayed within the slide/turn bounds.

    Returns
    -------
    ok, moved (m, horizontal centre-of-mass displacement), turned (deg)
    """
    step = com_world(after, com_local) - com_world(before, com_local)
    moved = float(np.linalg.norm(step[:2]))  # sliding/rolling; the vertical drop onto the supporter is free
    turned = math.degrees(rotation_angle(decompose(before)[0], decompose(after)[0]))
    bound = min(fp.max_slide, fp.max_slide_frac * diag)
    return moved <= bound and turned <= fp.max_turn, moved, turned


def lost_supporters(below: list[str], leaning: list[str], touching: list[str]) -> list[str]:
    """Supporters the object lost at rest: all of ``below`` when it touches none of them, plus untouched ``leaning``.

    An object carried from below needs one of its carriers (the graph may name a table that ``contains`` a
    jug standing on a plate); each object it leans on must still be touched.
    """
    lost = [] if not below or any(p in touching for p in below) else list(below)
    return lost + [p for p in leaning if p not in touching]


def certificate(settled: bool | None, remedy: str, below: list[str], leaning: list[str], touching: list[str],
                displacement: float, rotation_change_deg: float, flush_angle: float,
                reason: str = "") -> dict:
    """Per-object certificate for the assembly log.

    Parameters
    ----------
    settled
        Whether the final pose met the settling criterion.
    remedy
        What produced the final pose: ``none``, ``extra_frames``, ``damping`` (the paper's remedies),
        ``stable``, ``rolled``, ``damped`` (faithful retries), ``held`` (frozen at the corrected pose), ``attached``.
    below, leaning
        The graph's supporters of the object from below (``supports``, ``contains``) and those it leans on.
    touching
        Objects (``ground`` included) within ``contact_tol`` of it at rest.
    displacement, rotation_change_deg
        Centre-of-mass displacement (m) and rotation change (deg) from the input pose.
    flush_angle
        Flush rotation applied (deg).
    reason
        Why a remedy beyond the paper's was needed.
    """
    lost = lost_supporters(below, leaning, touching)
    return {"settled": settled, "remedy": remedy, "supporters": list(below) + list(leaning),
            "touching": sorted(touching),
            "supporters_kept": not lost, "lost": lost, "displacement": round(float(displacement), 9),
            "rotation_change": round(float(rotation_change_deg), 6), "flush_angle": round(float(flush_angle), 6),
            "reason": reason}
