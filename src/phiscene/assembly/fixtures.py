"""Objects fixed to a wall or the ceiling (attached objects) in faithful grounding: made flush with what holds
them, lifted out of the floor, and moved clear of each other.

An attached object is never settled or dropped: it is placed first, static, and the other objects are grounded
against it (:func:`phiscene.assembly.assemble.ground_scene`). Its pose is the input's with two corrections,
each small and each only where the input is plainly wrong:

1. :func:`flush_fixture`: flush with, upright on and touching a wall or ceiling of ``Scene.structure`` that was
   given (:func:`~phiscene.assembly.resting.flush_attached`), then lifted out of the floor when its mesh reaches
   at most :data:`~phiscene.assembly.resting.ATTACH_REACH` below it;
2. :func:`clear_fixture` (``FaithfulParams.fixtures``): moved the shortest way clear of the attached objects
   placed before it (:func:`~phiscene.assembly.penetration.fixture_clearance`), never into the wall or ceiling
   holding it, nor into the floor. A reconstruction puts them through each other (a curtain through the window
   it hangs in front of, two posters through each other), and a fixed object is held by its wall, not by its
   neighbours, so nothing else would ever separate them. The shortest move keeps the one that is mostly in
   front in front: out from the other by the depth of the overlap, or sideways along the wall where that is
   shorter.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phiscene.assembly import resting
from phiscene.assembly.penetration import (
    PenetrationParams,
    SdfBody,
    fixture_clearance,
    overlaps_deeper,
    sdf_body,
)
from phiscene.assembly.record import rounded
from phiscene.proxies import Proxy
from phiscene.scene import Scene
from phiscene.transforms import transform_points


def shape_points(proxy: Proxy | None, mesh) -> np.ndarray:
    """The vertices (n, 3), local, of an object's collision shape: its convex pieces', else its mesh's."""
    return np.vstack(proxy.hulls) if proxy is not None and proxy.hulls else np.asarray(mesh.vertices)


def flush_fixture(scene: Scene, obj, proxy: Proxy | None, holder: str, max_angle_deg: float, cache_dir: Path,
                  rec: dict) -> np.ndarray:
    """The pose (4, 4) of an attached object made flush with the wall or ceiling holding it
    (:func:`~phiscene.assembly.resting.flush_attached`; its input pose when the holder is not a plane of
    ``scene.structure``, the ground standing for an unknown wall, or is an estimated one, which is where the
    objects it comes from are), then lifted out of the floor when its mesh
    reaches at most ``ATTACH_REACH`` below it (a floor-length curtain a depth error pushed through the floor;
    lifting it slides it along its wall). Fills ``rec`` (``flush_angle`` deg, ``attach_shift`` m,
    ``attach_lift`` m)."""
    pose = np.asarray(obj.pose, dtype=float)
    plane = holder_plane(scene, holder)
    out = pose if plane is None or plane.estimated else _flushed_on(plane, obj, proxy, pose, max_angle_deg,
                                                                    cache_dir, rec)
    below = scene.ground_height - float(transform_points(out, np.asarray(obj.mesh().vertices))[:, 2].min())
    lift = below if 0.0 < below <= resting.ATTACH_REACH else 0.0
    if lift:
        out = out.copy()
        out[2, 3] += lift
    rec["attach_lift"] = rounded(lift)
    return out


def _flushed_on(plane, obj, proxy: Proxy | None, pose: np.ndarray, max_angle_deg: float, cache_dir: Path,
                rec: dict) -> np.ndarray:
    """``pose`` made flush with ``plane`` (:func:`~phiscene.assembly.resting.flush_attached`); fills ``rec``."""
    import trimesh

    hull = trimesh.convex.convex_hull(shape_points(proxy, obj.mesh()))
    normals = resting.cached_resting_normals(hull.vertices, cache_dir)
    out, angle, shift = resting.flush_attached(pose, normals, np.asarray(hull.center_mass), hull.vertices,
                                               np.asarray(plane.normal, dtype=float), plane.offset,
                                               plane.kind == "wall", max_angle_deg)
    rec.update(flush_angle=rounded(angle), attach_shift=rounded(shift))
    return out


def holder_plane(scene: Scene, holder: str):
    """The wall or ceiling of ``scene.structure`` called ``holder`` (:class:`~phiscene.scene.Plane`); ``None`` for
    any other holder (the ground standing for an unknown wall)."""
    return next((q for q in scene.structure if q.id == holder), None)


def outward(scene: Scene, holder: str) -> np.ndarray | None:
    """The unit normal (3,), into the room, of the wall or ceiling ``holder`` (:func:`holder_plane`); ``None`` for
    any other holder."""
    plane = holder_plane(scene, holder)
    if plane is None:
        return None
    n = np.asarray(plane.normal, dtype=float)
    return n / np.linalg.norm(n)


def clear_fixture(scene: Scene, oid: str, pose: np.ndarray, holder: str, fixed: list[SdfBody],
                  pp: PenetrationParams, tol: float, cache_dir: Path, rec: dict) -> np.ndarray:
    """``pose`` (4, 4) of the attached object ``oid`` moved clear of the attached objects ``fixed`` placed before
    it, where it overlaps them deeper than ``tol`` (m): :func:`~phiscene.assembly.penetration.fixture_clearance`,
    never into the wall or ceiling ``holder`` (:func:`outward`) nor the floor.

    Fills ``rec["fixture_clear"]``: the translation (3,) m; ``None`` when none was needed; ``"none found"`` when
    no move within ``pp.search_reach`` clears (the pose is then left as it is).
    """
    rec["fixture_clear"] = None
    if not fixed:
        return pose
    active = sdf_body(oid, scene.get(oid).mesh(), pose, pp.n_active, pp, cache_dir)
    if not overlaps_deeper(active, fixed, tol, pp.ground_extreme_points):
        return pose
    move = fixture_clearance(active, fixed, scene.ground_height, pp, outward(scene, holder))
    if move is None:
        rec["fixture_clear"] = "none found"
        return pose
    out = np.asarray(pose, dtype=float).copy()
    out[:3, 3] += move
    rec["fixture_clear"] = [rounded(v) for v in move]
    return out


def summary(rec: dict, moved: float, turned: float) -> str:
    """The progress line's account of an attached object: ``kept in place``, or how far (``moved`` m, ``turned``
    rad) and why, from its record ``rec`` (``flush_angle``, ``attach_lift``, ``fixture_clear``)."""
    steps = (("made flush", rec.get("flush_angle")), ("lifted out of the floor", rec.get("attach_lift")),
             ("clear of the fixed objects before it", isinstance(rec.get("fixture_clear"), list)))
    why = [w for w, done in steps if done]
    if not why:
        return "kept in place"
    return f"moved {moved:.3f} m, turned {np.degrees(turned):.1f} deg ({', '.join(why)})"
