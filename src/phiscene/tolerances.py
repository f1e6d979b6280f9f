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
        Largest accepted absolute world coordinate (m) of an object's pose and of its
        world bounding box; farther is refused as a unit error (the simulators' ground
        box spans 100 m x 100 m around the origin, see ``phiscene.sim.bullet``).
    max_object_size
        Largest accepted extent (m) of one object's world bounding box; larger is
        refused as a unit error (e.g. a scene written in millimetres).
    max_below_ground
        Deepest accepted position (m) of an object's top below the ground plane;
        an object buried deeper is refused (a sign or unit error, beyond what
        grounding can lift).
    sdf_aabb_pad
        Padding of a mesh's bounding box, as a fraction of its diagonal, inside which
        signed distance evaluates the winding number (points outside are outside).
    footprint_resolution
        Footprint areas (m^2) are compared in units of this when ordering objects, so equal
        objects tie exactly and fall back to id order.
    com_bounds_pad
        How far (m, local frame) a declared centre of mass (``com`` in ``scene.json``) may lie outside
        its mesh's bounding box (rounding); farther is refused.
    base_bounds_share
        How far a completed base (``base`` in ``scene.json``) may reach beyond its mesh's bounding box, as a
        share of the mesh's largest extent: it completes the bottom flat (:func:`phiscene.assembly.faithful.
        flat_base`), within a thin band under it; farther is refused.
    """

    pose_orthogonality: float = 1e-5
    min_scale: float = 1e-3
    max_scale: float = 1e3
    min_volume: float = 1e-9
    winding_inside: float = 0.5
    max_coordinate: float = 50.0
    max_object_size: float = 50.0
    max_below_ground: float = 1.0
    sdf_aabb_pad: float = 1e-6
    footprint_resolution: float = 1e-6
    com_bounds_pad: float = 1e-6
    base_bounds_share: float = 0.25


TOL = Tolerances()

#: Gravity along -z, m/s^2.
GRAVITY = 9.81

#: The drift protocol's lift (m) of every free object before it is released (``PhysicalParams.upward_offset``, paper
#: supplement), and the lift of faithful grounding's last release (``FaithfulParams.joint_drop``) that judges its
#: certificates by the same release.
DRIFT_LIFT = 0.002
