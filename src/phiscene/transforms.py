"""Pose conventions.

A pose is a 4x4 row-major matrix ``T`` that maps object-local homogeneous
points to world points, ``p_world = T @ p_local``. Its upper-left block is
``s * R`` with ``R`` a proper rotation and ``s > 0`` an optional uniform scale.
Quaternions at library boundaries are ``(w, x, y, z)``; pybullet uses
``(x, y, z, w)`` and the conversion helpers say so in their names.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from phiscene.tolerances import TOL

#: Pose (4, 4) taking phiscene's z-up world to the y-up world of glTF, three.js, 3D-FRONT and SAM 3D Objects'
#: GLB files: -90 degrees about x, (x, y, z) -> (x, z, -y). The one home of this convention (export, viewer,
#: importers); read-only.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
Z_UP_TO_Y_UP.setflags(write=False)
#: Its inverse, y-up to z-up: (x, y, z) -> (x, -z, y); read-only.
Y_UP_TO_Z_UP = np.ascontiguousarray(Z_UP_TO_Y_UP.T)
Y_UP_TO_Z_UP.setflags(write=False)


def make_pose(rotation: np.ndarray | None = None, translation=(0.0, 0.0, 0.0), scale: float = 1.0) -> np.ndarray:
    """Compose a pose from a rotation, a translation and a uniform scale.

    Parameters
    ----------
    rotation : (3, 3) float, optional
        Proper rotation matrix (identity when omitted).
    translation : (3,) float
    scale : float
        Uniform scale, > 0.

    Returns
    -------
    pose : (4, 4) float
    """
    pose = np.eye(4)
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    pose[:3, :3] = scale * R
    pose[:3, 3] = np.asarray(translation, dtype=float)
    return pose


def decompose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Split a pose into rotation, translation and uniform scale.

    Parameters
    ----------
    pose : (4, 4) float

    Returns
    -------
    rotation : (3, 3) float
    translation : (3,) float
    scale : float
    """
    pose = np.asarray(pose, dtype=float)
    A = pose[:3, :3]
    det = float(np.linalg.det(A))
    scale = float(np.cbrt(det)) if det > 0 else float("nan")
    return A / scale, pose[:3, 3].copy(), scale


def rigidity_error(pose: np.ndarray) -> str | None:
    """Explain why ``pose`` is not a rigid (similarity) transform, or return ``None``.

    Parameters
    ----------
    pose : (4, 4) float
    """
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        return f"expected a 4x4 matrix, got shape {pose.shape}"
    if not np.all(np.isfinite(pose)):
        return "contains NaN or inf"
    if not np.allclose(pose[3], [0, 0, 0, 1], atol=TOL.pose_orthogonality):
        return f"last row must be [0, 0, 0, 1], got {pose[3].tolist()}"
    det = np.linalg.det(pose[:3, :3])
    if det <= 0:
        return f"rotation block has determinant {det:.3g} (reflection or degenerate)"
    R, _, s = decompose(pose)
    dev = float(np.abs(R.T @ R - np.eye(3)).max())
    if dev > TOL.pose_orthogonality:
        return f"not a rotation times a uniform scale (deviation {dev:.3g}); shear or non-uniform scale"
    if not (TOL.min_scale <= s <= TOL.max_scale):
        return f"uniform scale {s:.3g} outside [{TOL.min_scale}, {TOL.max_scale}]"
    return None


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a pose to points.

    Parameters
    ----------
    pose : (4, 4) float
    points : (n, 3) float

    Returns
    -------
    (n, 3) float
    """
    points = np.asarray(points, dtype=float)
    return points @ pose[:3, :3].T + pose[:3, 3]


def invert(pose: np.ndarray) -> np.ndarray:
    """Inverse of a similarity pose, (4, 4) -> (4, 4)."""
    R, t, s = decompose(pose)
    inv = np.eye(4)
    inv[:3, :3] = R.T / s
    inv[:3, 3] = -(R.T @ t) / s
    return inv


def quat_wxyz_to_matrix(q) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` -> (3, 3) rotation matrix."""
    w, x, y, z = np.asarray(q, dtype=float)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def matrix_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix -> unit quaternion ``(w, x, y, z)`` with ``w >= 0``."""
    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = np.array([w, x, y, z])
    return q if w >= 0 else -q


def quat_xyzw_to_matrix(q) -> np.ndarray:
    """pybullet quaternion ``(x, y, z, w)`` -> (3, 3) rotation matrix."""
    return Rotation.from_quat(np.asarray(q, dtype=float)).as_matrix()


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix -> pybullet quaternion ``(x, y, z, w)``."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle in radians of the relative rotation ``Ra^T Rb``.

    Parameters
    ----------
    Ra, Rb : (3, 3) float
    """
    c = (np.trace(np.asarray(Ra).T @ np.asarray(Rb)) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def random_rotation(rng: np.random.Generator, max_angle: float) -> np.ndarray:
    """A rotation about a uniformly random axis by an angle uniform in ``[-max_angle, max_angle]``.

    Returns
    -------
    (3, 3) float
    """
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(-max_angle, max_angle)
    return Rotation.from_rotvec(axis * angle).as_matrix()


def rotation_z(angle: float) -> np.ndarray:
    """Rotation about the world z axis (up), (3, 3)."""
    return Rotation.from_euler("z", angle).as_matrix()


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
