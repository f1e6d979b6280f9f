"""The initial scene: ground truth degraded the way a 3D foundation model errs.

Each object's pose gets independent errors, all drawn from one seed:

* a horizontal translation error (normal per axis) and a smaller vertical one;
* a vertical offset drawn uniformly from a range that straddles zero, so some
  objects sink into their supports and some float above them;
* a rotation error about a uniformly random axis (normal angle);
* a uniform scale error (normal, relative), applied about the object's
  bounding-box centre (its local origin).

Normal draws are truncated at ``truncate`` standard deviations, so every error
is bounded. Meshes are untouched: the initial scene points to the GT meshes.

This is the ``clean`` model (``kind: clean``, the default). ``kind: foundation`` selects the realistic model
of :mod:`phiscene.bench.foundation` (reconstructed meshes, camera-ray depth errors with heavy tails, a tilted
camera frame levelled by estimate), with its magnitudes in ``foundation``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from phiscene.bench.foundation import FoundationParams
from phiscene.params import Params
from phiscene.scene import Scene
from phiscene.transforms import decompose, make_pose

#: Degradation models of the initial scene.
DEGRADE_KINDS = ("clean", "foundation")


@dataclass(frozen=True)
class DegradeParams(Params):
    """Magnitudes of the pose errors of the initial scene.

    Attributes
    ----------
    translation_xy_sigma
        Standard deviation (m) of the horizontal translation error, per axis. Default 1.5 cm.
    translation_z_sigma
        Standard deviation (m) of the vertical translation error on top of the offset. Default 0.5 cm.
    vertical_offset_min, vertical_offset_max
        Range (m) of the uniform vertical offset; negative sinks, positive floats.
        Default [-2 cm, +3 cm].
    rotation_sigma_deg
        Standard deviation (deg) of the rotation error angle. Default 4 deg.
    scale_sigma
        Standard deviation of the relative uniform scale error. Default 0.03 (3 %).
    truncate
        Normal draws are clipped at this many standard deviations. Default 3.
    kind
        ``clean`` (this module: pose errors of a few centimetres on the GT meshes) or ``foundation``
        (:mod:`phiscene.bench.foundation`); the ``clean`` magnitudes above apply to ``clean`` only.
    foundation
        Magnitudes of the ``foundation`` model.
    """

    _label = "degradation parameters"

    translation_xy_sigma: float = 0.015
    translation_z_sigma: float = 0.005
    vertical_offset_min: float = -0.02
    vertical_offset_max: float = 0.03
    rotation_sigma_deg: float = 4.0
    scale_sigma: float = 0.03
    truncate: float = 3.0
    kind: str = "clean"
    foundation: FoundationParams = field(default_factory=FoundationParams)

    def check(self) -> None:
        """Reject an empty vertical offset range, negative sigmas and scales that could reach 0 (``ValueError``)."""
        if self.vertical_offset_min > self.vertical_offset_max:
            raise ValueError("vertical_offset_min must not exceed vertical_offset_max")
        if min(self.translation_xy_sigma, self.translation_z_sigma, self.rotation_sigma_deg, self.scale_sigma) < 0:
            raise ValueError("degradation sigmas must be >= 0")
        if self.truncate * self.scale_sigma >= 1:
            raise ValueError("truncate * scale_sigma must be < 1 (scales must stay positive)")
        if self.kind not in DEGRADE_KINDS:
            raise ValueError(f"degradation kind must be one of {list(DEGRADE_KINDS)}, got {self.kind!r}")


def _normal(rng: np.random.Generator, sigma: float, truncate: float, size=None):
    return np.clip(rng.normal(0.0, 1.0, size=size), -truncate, truncate) * sigma


def degrade_pose(pose: np.ndarray, rng: np.random.Generator, params: DegradeParams) -> tuple[np.ndarray, dict]:
    """One degraded pose and the errors applied.

    Parameters
    ----------
    pose : (4, 4) float
        Ground-truth pose.
    rng
        Random generator (consumes a fixed number of draws).
    params
        Error magnitudes.

    Returns
    -------
    pose : (4, 4) float
        ``make_pose(R_err @ R, t + dt, s * scale)``.
    errors
        ``translation`` (3,) (m, vertical offset excluded), ``vertical_offset`` (m),
        ``rotation_deg``, ``rotation_axis`` (3,), ``scale`` (relative factor).
    """
    R, t, s = decompose(pose)
    dxy = _normal(rng, params.translation_xy_sigma, params.truncate, size=2)
    dz = float(_normal(rng, params.translation_z_sigma, params.truncate))
    offset = float(rng.uniform(params.vertical_offset_min, params.vertical_offset_max))
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = float(_normal(rng, np.radians(params.rotation_sigma_deg), params.truncate))
    scale = 1.0 + float(_normal(rng, params.scale_sigma, params.truncate))
    R_err = Rotation.from_rotvec(axis * angle).as_matrix()
    shift = np.array([dxy[0], dxy[1], dz + offset])
    out = make_pose(R_err @ R, t + shift, s * scale)
    errors = {"translation": [float(dxy[0]), float(dxy[1]), dz], "vertical_offset": offset,
              "rotation_deg": float(np.degrees(abs(angle))), "rotation_axis": (np.sign(angle or 1.0) * axis).tolist(),
              "scale": scale}
    return out, errors


def degrade_scene(scene: Scene, params: DegradeParams, seed) -> Scene:
    """The initial scene: every pose of ``scene`` degraded, errors recorded in ``meta["degrade"]``.

    Parameters
    ----------
    scene
        Ground truth.
    params
        Error magnitudes.
    seed
        Anything :func:`numpy.random.default_rng` accepts; objects draw in file order.

    Returns
    -------
    A new :class:`Scene` sharing the meshes, with ``meta["state"] = "initial"``.
    """
    rng = np.random.default_rng(seed)
    poses, errors = {}, {}
    for o in scene.objects:
        poses[o.id], errors[o.id] = degrade_pose(o.pose, rng, params)
    clean = {k: v for k, v in params.to_dict().items() if k not in ("kind", "foundation")}
    out = scene.with_poses(poses, meta={"state": "initial", "degrade": clean})
    for o in out.objects:
        o.meta = {**o.meta, "degrade": errors[o.id]}
    return out
