"""Faithfulness of a grounded scene to its input, and pose error against ground truth.

Per scene, over the objects the input does not mark attached (objects a method's own topology decides are
attached count, with the motion the method gives them, so that every method is averaged over the same objects):

* displacement: distance (m) between each object's centre (its local
  bounding-box centre under its pose) in the scene and in the input;
* rotation change: angle (deg) of the relative rotation (objects whose mesh differs from the input's, as in an
  imported peer result: the rotation of a rigid ICP of their surface samples onto the input's);
* with ground truth: translation and rotation error against it, and ADD-S
  (mean over seeded surface samples of the GT mesh of the distance from each
  GT-posed sample to the nearest predicted-posed sample; a KD-tree).

For a method whose output lives in another frame (``align=True``), the best
rigid motion of the object centres onto the input's (Kabsch, via
:meth:`scipy.spatial.transform.Rotation.align_vectors` on centred points) is
applied first, to positions and rotations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phiscene.params import Params
from phiscene.scene import Scene
from phiscene.transforms import decompose, rotation_angle, transform_points


@dataclass(frozen=True)
class PoseParams(Params):
    """Settings of the pose metrics (``metrics.pose`` in config).

    Attributes
    ----------
    samples
        Surface samples per object for ADD-S.
    seed
        Their seed.
    """

    _label = "pose metric parameters"

    samples: int = 2048
    seed: int = 0

    def check(self) -> None:
        """At least one sample (``ValueError``)."""
        if self.samples < 1:
            raise ValueError(f"pose metric 'samples' must be >= 1, got {self.samples}")


def object_centre(obj) -> np.ndarray:
    """World position (3,) of the centre of ``obj``'s local bounding box."""
    lo, hi = np.asarray(obj.mesh().bounds, dtype=float)
    return transform_points(np.asarray(obj.pose, dtype=float), ((lo + hi) / 2)[None])[0]


def rigid_alignment(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (3, 3) and translation (3,) minimising ``sum |R src_i + t - dst_i|^2`` (points (n, 3)).

    Fewer than 3 points: translation only (the rotation is not determined).
    """
    from scipy.spatial.transform import Rotation

    src, dst = np.asarray(src, dtype=float), np.asarray(dst, dtype=float)
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    if len(src) < 3:
        return np.eye(3), cd - cs
    rot, _ = Rotation.align_vectors(dst - cd, src - cs)
    R = rot.as_matrix()
    return R, cd - R @ cs


def _adds(obj, ref, n: int, seed: int) -> float:
    """ADD-S (m) of ``obj``'s pose against ``ref``'s (same mesh assumed: ``ref``'s is sampled)."""
    import trimesh
    from scipy.spatial import cKDTree

    mesh = ref.mesh()
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    a = transform_points(np.asarray(ref.pose, dtype=float), pts)
    b = transform_points(np.asarray(obj.pose, dtype=float), pts)
    d, _ = cKDTree(b).query(a)
    return float(d.mean())


def pose_metrics(scene: Scene, initial: Scene, gt: Scene | None = None, align: bool = False,
                 samples: int = 2048, seed: int = 0) -> dict:
    """Displacement and rotation change of ``scene`` from ``initial``; pose error against ``gt``.

    Parameters
    ----------
    scene
        The result (same object ids as ``initial``; extra or missing ids are skipped).
    initial
        The input scene.
    gt
        Ground truth (optional).
    align
        First move ``scene`` by the best rigid motion of its object centres onto ``initial``'s (and onto
        ``gt``'s for the GT errors).
    samples, seed
        Surface samples per object for ADD-S and their seed.

    Returns
    -------
    dict
        ``objects`` (count), ``displacement_mean``/``_max`` (m), ``rotation_mean``/``_max`` (deg), and with
        ``gt``: ``gt_translation_mean``/``_max`` (m), ``gt_rotation_mean``/``_max`` (deg),
        ``gt_adds_mean``/``_max`` (m). NaN where no object is shared.
    """
    ids = [o for o in initial.free_ids if o in set(scene.ids)]
    out = {"objects": len(ids)}
    out.update(_compare(scene, initial, ids, align, "displacement", "rotation"))
    if gt is not None:
        gids = [o for o in ids if o in set(gt.ids)]
        out.update(_compare(scene, gt, gids, align, "gt_translation", "gt_rotation", adds=(samples, seed)))
    return out


def _compare(scene: Scene, ref: Scene, ids: list[str], align: bool, tkey: str, rkey: str,
             adds: tuple[int, int] | None = None) -> dict:
    nan = float("nan")
    keys = [tkey, rkey] + (["gt_adds"] if adds else [])
    if not ids:
        return {f"{k}_{s}": nan for k in keys for s in ("mean", "max")}
    c = np.array([object_centre(scene.get(o)) for o in ids])
    c0 = np.array([object_centre(ref.get(o)) for o in ids])
    G = np.eye(4)
    if align:
        R, t = rigid_alignment(c, c0)
        G[:3, :3], G[:3, 3] = R, t
        c = c @ R.T + t
    trans = np.linalg.norm(c - c0, axis=1)
    rot = np.array([_rotation_change(scene.get(o), ref.get(o), G) for o in ids])
    vals = {tkey: trans, rkey: rot}
    if adds:
        moved = {o: _moved(scene.get(o), G) for o in ids}
        vals["gt_adds"] = np.array([_adds(moved[o], ref.get(o), *adds) for o in ids])
    return {f"{k}_{s}": float(getattr(np, s)(v)) for k, v in vals.items() for s in ("mean", "max")}


def _rotation_change(obj, ref, G: np.ndarray, samples: int = 2048, seed: int = 0) -> float:
    """Rotation (deg) between an object and its reference after the alignment ``G`` (4, 4).

    The same mesh in both: the relative rotation of the poses. Different meshes (a method that brings its own,
    e.g. an imported peer result): the rotation of a rigid ICP (open3d) of seeded surface samples of the aligned
    object onto the reference, started with their centres matched.
    """
    R0 = decompose(np.asarray(ref.pose, dtype=float))[0]
    R1 = G[:3, :3] @ decompose(np.asarray(obj.pose, dtype=float))[0]
    if obj.mesh_path == ref.mesh_path:
        return math.degrees(rotation_angle(R1, R0))
    from phiscene.meshes import sample_surface
    from phiscene.metrics.reconstruction import icp

    a = transform_points(G @ np.asarray(obj.pose, dtype=float), sample_surface(obj.mesh(), samples, seed))
    b = transform_points(np.asarray(ref.pose, dtype=float), sample_surface(ref.mesh(), samples, seed + 1))
    init = np.eye(4)
    init[:3, 3] = b.mean(axis=0) - a.mean(axis=0)
    T = icp(a, b, init, max_iterations=50)
    return math.degrees(rotation_angle(T[:3, :3], np.eye(3)))


def _moved(obj, G: np.ndarray):
    from dataclasses import replace

    return replace(obj, pose=G @ np.asarray(obj.pose, dtype=float))
