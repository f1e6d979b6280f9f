"""One place for the numeric tolerances and physical defaults phiscene uses.

Values that a user may want to change live in ``config/config.yaml``; these
are the internal ones (validation thresholds, numerical guards).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    """Numerical tolerances.

    Attributes
    ----------
    pose_orthogonality
        Max abs deviation of ``R^T R`` from identity for a valid pose rotation.
    min_scale, max_scale
        Accepted range of a pose's uniform scale.
    min_volume
        Smallest accepted mesh volume (m^3) for mass properties; smaller is degenerate.
    winding_inside
        Generalised winding number above which a point is inside a mesh.
    max_coordinate
        Largest accepted absolute world coordinate (m); farther is refused as a unit error.
    """

    pose_orthogonality: float = 1e-5
    min_scale: float = 1e-3
    max_scale: float = 1e3
    min_volume: float = 1e-9
    winding_inside: float = 0.5
    max_coordinate: float = 1e3


TOL = Tolerances()

#: Gravity along -z, m/s^2.
GRAVITY = 9.81
