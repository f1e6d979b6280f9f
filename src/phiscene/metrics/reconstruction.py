"""Reconstruction metrics against ground truth (paper supplement "3D-Front Benchmark Metrics").

Five numbers per scene, as in the paper's 3D-Front table and MIDI-3D's
evaluation (``midi/systems/system_midi.py::compute_metrics``):

* scene chamfer distance (squared nearest-neighbour distances, both directions,
  summed) and scene F-score (plain distances, threshold ``tau``) after the
  predicted scene is aligned to the ground truth;
* object chamfer distance and F-score, averaged over objects, after each
  predicted and GT object is normalised on its own, per axis, into
  ``[-0.95, 0.95]^3`` and the prediction is rigidly aligned by ICP;
* mean IoU of per-object axis-aligned bounding boxes.

Two scene alignments are reported:

``paper`` (keys without suffix)
    Centroid matching, uniform rescale by the median ratio of sorted scene
    extents, then rigid point-to-point ICP (paper Eq. S1-S2).
``icp`` (keys ending in ``_icp``)
    Rigid ICP only, from the identity: what MIDI-3D's released code does.

Protocol choices where the paper is silent, and how MIDI-3D differs:

* Sampling. The paper samples N = 20480 points per *scene*; we sample them
  area-weighted over the union of all objects' world meshes. MIDI instead
  samples 20480 points per *object* and concatenates them, so that its scene
  cloud weights every object equally whatever its size. Objects get
  ``object_points`` samples each (paper and MIDI: 20480). Prediction and GT
  draw from the same seed, so identical geometry gives identical samples and
  exactly zero distance.
* Centroids and extents of the ``paper`` alignment are taken from the scene
  samples (area-weighted surface centroid, sample bounding box), not from mesh
  vertices, so they do not depend on tessellation.
* ICP uses every nearest neighbour as a correspondence (no distance cut-off)
  unless ``icp_threshold`` is set, as MIDI's ICP does.
* Object normalisation is MIDI's per-axis min/max map (see
  :func:`normalize_to_unit_box`); it is anisotropic and rotation-sensitive, as
  the paper's supplement remarks.
* Bounding-box IoU. The paper computes it after its scene alignment; MIDI
  computes it on the raw, unaligned predicted objects. ``bbox_iou`` is the
  paper's (the value the reconstruction table reports) and ``bbox_iou_raw`` is
  MIDI's. Boxes are the exact AABBs of the world meshes (MIDI uses the AABBs
  of its surface samples, which are slightly smaller).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phiscene.errors import InputError
from phiscene.params import Params
from phiscene.scene import Scene

#: The protocol's 1e-8 in ``F = 2PR / (P + R + 1e-8)`` and ``IoU = V_cap / (V_cup + 1e-8)``.
PROTOCOL_EPS = 1e-8


@dataclass(frozen=True)
class ReconParams(Params):
    """Parameters of the reconstruction metrics.

    Attributes
    ----------
    points
        Surface samples per scene (paper: 20480).
    object_points
        Surface samples per object for the object-level metrics (paper and MIDI: 20480).
    tau
        F-score distance threshold, in the units of the compared clouds (paper: 0.1).
    icp_iterations
        Maximum ICP iterations (MIDI: 50).
    icp_threshold
        ICP correspondence cut-off distance; ``None`` pairs every point with its
        nearest neighbour, as MIDI does.
    icp_tolerance
        ICP stops when both the relative change of inlier fraction and of inlier
        RMSE fall below this (open3d's convergence criteria).
    bound
        Half-size of the cube objects are normalised into (paper: 0.95).
    seed
        Seed of the surface sampling (scene: ``seed``; k-th GT object: ``seed + 1 + k``).
    """

    _label = "reconstruction metric parameters"

    points: int = 20480
    object_points: int = 20480
    tau: float = 0.1
    icp_iterations: int = 50
    icp_threshold: float | None = None
    icp_tolerance: float = 1e-6
    bound: float = 0.95
    seed: int = 0

    def __post_init__(self):
        checks = {"points": self.points >= 1, "object_points": self.object_points >= 1, "tau": self.tau > 0,
                  "icp_iterations": self.icp_iterations >= 1, "icp_tolerance": self.icp_tolerance >= 0,
                  "bound": self.bound > 0, "seed": self.seed >= 0,
                  "icp_threshold": self.icp_threshold is None or self.icp_threshold > 0}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError("invalid reconstruction parameters: "
                             + ", ".join(f"{k}={getattr(self, k)!r}" for k in bad))


# --------------------------------------------------------------------------- point-set primitives


def _as_points(points, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name} must be a non-empty (n, 3) array, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} contains NaN or inf")
    return p


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance from each point of ``a`` to its nearest point of ``b`` (k-d tree).

    The query runs on as many threads as the job's budget (``OMP_NUM_THREADS``, set by
    :func:`phiscene.runner.set_threads`; every core where it is unset).

    Parameters
    ----------
    a : (n, 3) float
    b : (m, 3) float

    Returns
    -------
    (n,) float
    """
    from scipy.spatial import cKDTree

    a, b = _as_points(a, "a"), _as_points(b, "b")
    from phiscene.runner import thread_budget

    d, _ = cKDTree(b).query(a, k=1, workers=thread_budget())
    return np.asarray(d, dtype=float)


def _cd_from(d_ab: np.ndarray, d_ba: np.ndarray) -> float:
    return float(np.mean(d_ab**2) + np.mean(d_ba**2))


def _fscore_from(d_ab: np.ndarray, d_ba: np.ndarray, tau: float) -> float:
    precision = float(np.mean(d_ab < tau))
    recall = float(np.mean(d_ba < tau))
    return 2.0 * precision * recall / (precision + recall + PROTOCOL_EPS)


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Bidirectional squared chamfer distance (paper Eq. S3).

    ``mean_a min_b |a - b|^2 + mean_b min_a |b - a|^2``.

    Parameters
    ----------
    a : (n, 3) float
    b : (m, 3) float
    """
    return _cd_from(nearest_distances(a, b), nearest_distances(b, a))


def fscore(a: np.ndarray, b: np.ndarray, tau: float = 0.1) -> float:
    """F-score at threshold ``tau`` on plain distances (paper Eq. S4).

    Precision is the fraction of ``a`` closer than ``tau`` (strictly) to ``b``,
    recall the fraction of ``b`` closer than ``tau`` to ``a``;
    ``F = 2PR / (P + R + 1e-8)``.

    Parameters
    ----------
    a : (n, 3) float
        Predicted points.
    b : (m, 3) float
        Ground-truth points.
    tau
        Distance threshold, > 0.
    """
    return _fscore_from(nearest_distances(a, b), nearest_distances(b, a), tau)


def chamfer_and_fscore(a: np.ndarray, b: np.ndarray, tau: float = 0.1) -> tuple[float, float]:
    """:func:`chamfer_distance` and :func:`fscore` from one pair of nearest-neighbour queries.

    Parameters
    ----------
    a : (n, 3) float
        Predicted points.
    b : (m, 3) float
        Ground-truth points.
    tau
        F-score threshold.

    Returns
    -------
    cd, fscore : float
    """
    d_ab, d_ba = nearest_distances(a, b), nearest_distances(b, a)
    return _cd_from(d_ab, d_ba), _fscore_from(d_ab, d_ba, tau)


def normalize_to_unit_box(points: np.ndarray, bound: float = 0.95) -> np.ndarray:
    """Map a point set per axis onto ``[-bound, bound]`` (MIDI's object normalisation).

    Each axis is shifted and scaled independently so that its minimum goes to
    ``-bound`` and its maximum to ``+bound``: ``2 bound (p - min) / (max - min) - bound``.
    This is anisotropic (aspect ratios are not kept) and depends on the
    object's orientation. An axis with zero range keeps scale 1, as in MIDI, so
    it maps to ``-bound``.

    Parameters
    ----------
    points : (n, 3) float
    bound
        Half-size of the target cube, > 0.

    Returns
    -------
    (n, 3) float
    """
    p = _as_points(points, "points")
    lo, hi = p.min(axis=0), p.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    unit = (p - lo) / span  # exactly 0 at the minimum and 1 at the maximum
    return bound * (2.0 * unit - 1.0)


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 affine transform to points.

    Parameters
    ----------
    transform : (4, 4) float
    points : (n, 3) float

    Returns
    -------
    (n, 3) float
    """
    t = np.asarray(transform, dtype=float)
    return np.asarray(points, dtype=float) @ t[:3, :3].T + t[:3, 3]


def icp(source: np.ndarray, target: np.ndarray, init: np.ndarray | None = None, max_iterations: int = 50,
        threshold: float | None = None, tolerance: float = 1e-6) -> np.ndarray:
    """Rigid point-to-point ICP of ``source`` onto ``target`` (open3d).

    Parameters
    ----------
    source : (n, 3) float
    target : (m, 3) float
    init : (4, 4) float, optional
        Initial transform (identity when omitted).
    max_iterations
        Iteration cap.
    threshold
        Correspondence cut-off distance; ``None`` uses every nearest neighbour.
    tolerance
        Relative change of inlier fraction and RMSE below which ICP stops.

    Returns
    -------
    transform : (4, 4) float
        Rigid transform mapping ``source`` onto ``target`` (includes ``init``).
    """
    from phiscene.o3d import open3d
    o3d = open3d()

    reg = o3d.pipelines.registration
    src, tgt = _as_points(source, "source"), _as_points(target, "target")
    init = np.eye(4) if init is None else np.asarray(init, dtype=float)
    if init.shape != (4, 4):
        raise ValueError(f"init must be a (4, 4) matrix, got shape {init.shape}")
    result = reg.registration_icp(
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src)),
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt)),
        float(np.inf if threshold is None else threshold), init,
        reg.TransformationEstimationPointToPoint(with_scaling=False),
        reg.ICPConvergenceCriteria(relative_fitness=tolerance, relative_rmse=tolerance,
                                   max_iteration=int(max_iterations)),
    )
    return np.array(result.transformation, dtype=float)


def bbox_iou(aabb_a: np.ndarray, aabb_b: np.ndarray) -> float:
    """IoU of two axis-aligned 3D boxes, ``V_cap / (V_cup + 1e-8)`` (paper's definition).

    Parameters
    ----------
    aabb_a, aabb_b : (2, 3) float
        Rows are the min and max corners.
    """
    a, b = np.asarray(aabb_a, dtype=float), np.asarray(aabb_b, dtype=float)
    for name, box in (("aabb_a", a), ("aabb_b", b)):
        if box.shape != (2, 3) or np.any(box[1] < box[0]):
            raise ValueError(f"{name} must be a (2, 3) [min, max] box with min <= max, got {box.tolist()}")
    inter = float(np.prod(np.clip(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]), 0.0, None)))
    union = float(np.prod(a[1] - a[0]) + np.prod(b[1] - b[0]) - inter)
    return inter / (union + PROTOCOL_EPS)


def aabb(points: np.ndarray) -> np.ndarray:
    """Axis-aligned bounding box of points.

    Parameters
    ----------
    points : (n, 3) float

    Returns
    -------
    (2, 3) float
        Min and max corners.
    """
    p = _as_points(points, "points")
    return np.stack([p.min(axis=0), p.max(axis=0)])


# --------------------------------------------------------------------------- scene alignment


def similarity_prealign(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Centroid matching and uniform rescale of ``source`` onto ``target`` (paper Eq. S1).

    ``v' = e_rel (v - c_src) + c_tgt`` with ``e_rel = median(sort(e_tgt) / sort(e_src))``,
    ``c`` the point centroids and ``e`` the bounding-box extents. Sorting the
    extents makes the scale independent of which axis is which.

    Parameters
    ----------
    source : (n, 3) float
    target : (m, 3) float

    Returns
    -------
    transform : (4, 4) float
        Similarity (uniform scale, no rotation) mapping ``source`` onto ``target``.
    """
    src, tgt = _as_points(source, "source"), _as_points(target, "target")
    e_src = np.sort(np.ptp(src, axis=0))
    e_tgt = np.sort(np.ptp(tgt, axis=0))
    if np.any(e_src <= 0):
        raise ValueError(f"source points have a zero extent {e_src.tolist()}: cannot rescale")
    scale = float(np.median(e_tgt / e_src))
    t = np.eye(4)
    t[:3, :3] *= scale
    t[:3, 3] = tgt.mean(axis=0) - scale * src.mean(axis=0)
    return t


def align_paper(source: np.ndarray, target: np.ndarray, params: ReconParams) -> np.ndarray:
    """The paper's scene alignment: :func:`similarity_prealign` followed by rigid ICP.

    Parameters
    ----------
    source : (n, 3) float
        Predicted scene points.
    target : (m, 3) float
        GT scene points.

    Returns
    -------
    transform : (4, 4) float
        Similarity mapping ``source`` onto ``target``.
    """
    pre = similarity_prealign(source, target)
    rigid = icp(apply_transform(pre, source), target, None, params.icp_iterations, params.icp_threshold,
                params.icp_tolerance)
    return rigid @ pre


def align_icp(source: np.ndarray, target: np.ndarray, params: ReconParams) -> np.ndarray:
    """MIDI's scene alignment: rigid ICP from the identity.

    Parameters
    ----------
    source : (n, 3) float
    target : (m, 3) float

    Returns
    -------
    transform : (4, 4) float
    """
    return icp(source, target, None, params.icp_iterations, params.icp_threshold, params.icp_tolerance)


# --------------------------------------------------------------------------- scenes


def _scene_points(meshes: list, count: int, seed: int) -> np.ndarray:
    import trimesh

    from phiscene.meshes import sample_surface

    return sample_surface(trimesh.util.concatenate(meshes), count, seed)


def _object_metrics(pred_pts: np.ndarray, gt_pts: np.ndarray, params: ReconParams) -> tuple[float, float]:
    p = normalize_to_unit_box(pred_pts, params.bound)
    g = normalize_to_unit_box(gt_pts, params.bound)
    p = apply_transform(icp(p, g, None, params.icp_iterations, params.icp_threshold, params.icp_tolerance), p)
    return chamfer_and_fscore(p, g, params.tau)


def reconstruction_metrics(pred: Scene, gt: Scene, params: ReconParams | None = None) -> dict:
    """Scene, object and bounding-box metrics of a predicted scene against its ground truth.

    Objects are matched by id. Scene-level metrics use every object of each
    scene (so missing or extra objects cost); object-level metrics and IoUs
    average over the matched objects.

    Parameters
    ----------
    pred
        The predicted scene.
    gt
        The ground-truth scene.
    params
        Sampling, threshold and ICP settings (defaults: the paper's).

    Returns
    -------
    dict
        ``scene_cd``, ``scene_fscore``
            After the paper's alignment (centroid + median-extent scale + ICP).
        ``scene_cd_icp``, ``scene_fscore_icp``
            After ICP only (MIDI's released code).
        ``scene_scale``
            The paper alignment's total uniform scale (1 = no rescale needed).
        ``object_cd``, ``object_fscore``
            Means over matched objects after per-object normalisation + ICP.
        ``bbox_iou``
            Mean AABB IoU after the paper's alignment (the table's value).
        ``bbox_iou_raw``
            Mean AABB IoU without alignment (MIDI's).
        ``n_objects``, ``n_missing``, ``n_extra``
            Matched objects, GT objects absent from ``pred``, ``pred`` objects absent from GT.
        ``objects``
            Per matched id: ``cd``, ``fscore``, ``bbox_iou``, ``bbox_iou_raw``.

    Raises
    ------
    InputError
        When the scenes share no object id.
    """
    params = params or ReconParams()
    pred_ids = set(pred.ids)
    matched = [i for i in gt.ids if i in pred_ids]
    if not matched:
        raise InputError(pred.source, "objects", f"no object id in common with the ground truth "
                         f"({gt.source}); predicted ids: {sorted(pred_ids)}, GT ids: {gt.ids}")

    pred_meshes = {o.id: o.world_mesh() for o in pred.objects}
    gt_meshes = {o.id: o.world_mesh() for o in gt.objects}

    pred_scene = _scene_points(list(pred_meshes.values()), params.points, params.seed)
    gt_scene = _scene_points(list(gt_meshes.values()), params.points, params.seed)
    t_paper = align_paper(pred_scene, gt_scene, params)
    t_icp = align_icp(pred_scene, gt_scene, params)
    aligned_paper = apply_transform(t_paper, pred_scene)
    aligned_icp = apply_transform(t_icp, pred_scene)

    from phiscene.meshes import sample_surface

    per_object = {}
    for k, oid in enumerate(gt.ids):
        if oid not in pred_ids:
            continue
        seed = params.seed + 1 + k
        cd, f = _object_metrics(sample_surface(pred_meshes[oid], params.object_points, seed),
                                sample_surface(gt_meshes[oid], params.object_points, seed), params)
        pred_vertices = np.asarray(pred_meshes[oid].vertices)
        gt_box = aabb(np.asarray(gt_meshes[oid].vertices))
        per_object[oid] = {
            "cd": cd, "fscore": f,
            "bbox_iou": bbox_iou(aabb(apply_transform(t_paper, pred_vertices)), gt_box),
            "bbox_iou_raw": bbox_iou(aabb(pred_vertices), gt_box),
        }

    def mean(key: str) -> float:
        return float(np.mean([v[key] for v in per_object.values()]))

    scene_cd, scene_f = chamfer_and_fscore(aligned_paper, gt_scene, params.tau)
    scene_cd_icp, scene_f_icp = chamfer_and_fscore(aligned_icp, gt_scene, params.tau)
    return {
        "scene_cd": scene_cd,
        "scene_fscore": scene_f,
        "scene_cd_icp": scene_cd_icp,
        "scene_fscore_icp": scene_f_icp,
        "scene_scale": float(np.cbrt(np.linalg.det(t_paper[:3, :3]))),
        "object_cd": mean("cd"),
        "object_fscore": mean("fscore"),
        "bbox_iou": mean("bbox_iou"),
        "bbox_iou_raw": mean("bbox_iou_raw"),
        "n_objects": len(matched),
        "n_missing": len(gt.ids) - len(matched),
        "n_extra": len(pred_ids - set(gt.ids)),
        "objects": per_object,
    }


def reconstruction_metrics_file(pred_path: str | Path, gt_path: str | Path, out_path: str | Path,
                                params: dict | None = None) -> dict:
    """Load two ``scene.json`` files, compute :func:`reconstruction_metrics`, write them as JSON.

    Parameters
    ----------
    pred_path, gt_path
        Predicted and ground-truth scene files.
    out_path
        Output JSON (written atomically).
    params
        Mapping for :meth:`ReconParams.from_dict`.

    Returns
    -------
    dict
        The metrics written.
    """
    from phiscene.atomic import write_json
    from phiscene.scene import load_scene

    result = reconstruction_metrics(load_scene(pred_path), load_scene(gt_path), ReconParams.from_dict(params))
    write_json(out_path, result)
    return result
