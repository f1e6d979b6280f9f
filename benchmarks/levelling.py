"""Levelling of real SAM 3D Objects scenes against REST3D's (needs the REST3D page assets; README "Real scenes").

For each scene: the tilt our estimate corrects (:func:`phiscene.levelling.estimate_up` through
:func:`phiscene.io.placed.level_objects`), REST3D's tilt (the Kabsch rotation between the object centres of
``sam3d/`` and ``ours/``, :func:`phiscene.io.rest3d.reference_up`), the angle between the two up directions, and an
independent plausibility check: the area-weighted mean angle between each object's dominant upward planar region
(table tops, seats, plates) and each up direction (a level scene has level tables).

REST3D's rotation is itself an estimate: the Kabsch rotation of object centres mixes the frame change with the
motion REST3D's own simulation gave each object (fruit rolling off, a chair tipping). A second reference,
``icp``, reads the frame change off each object's own mesh instead: each ``sam3d`` mesh is registered onto its
``ours`` counterpart by ICP (:func:`phiscene.metrics.reconstruction.icp`, started from the Kabsch rotation), each
registration gives an up direction, and their robust mean (weights: ICP fitness over the angle to the current
mean) is the up REST3D's frame implies for most objects; ``spread`` is the median angle of the per-object ups to it.
A third check, ``walls``: the area-weighted mean angle from vertical of the wall objects that are thin panels
(a description naming a wall object, :func:`phiscene.topology.words.names_wall_object`, and a minimum-volume box
whose smallest extent is at most ``thin_ratio`` of its largest): posters and paintings hang nearly vertical.

    python benchmarks/levelling.py [ROOT] [SCENE ...]      # ROOT defaults to data/REST3D, scenes to all of them
"""

from __future__ import annotations

import sys
import time

import numpy as np

from phiscene.io.placed import PlacedParams, level_objects, source_to_z_up
from phiscene.io.rest3d import read_rest3d, reference_up, scene_ids
from phiscene.levelling import angle_deg

#: Surface samples per mesh for the per-object ICP reference, and its correspondence cut-off (share of the diagonal).
ICP_SAMPLES = 4000
ICP_REACH = 0.05


def icp_reference_up(root: str, scene: str) -> tuple[np.ndarray, float]:
    """REST3D's up (3,) in the ``sam3d`` source frame from per-object ICP (module docstring), and the spread (deg)."""
    import trimesh
    from scipy.spatial import cKDTree

    from phiscene.io.rest3d import reference_levelling
    from phiscene.metrics.reconstruction import icp

    K = reference_levelling(root, scene)
    a = {o.id: o.mesh for o in read_rest3d(root, scene, "sam3d").objects}
    b = {o.id: o.mesh for o in read_rest3d(root, scene, "ours").objects}
    ups, weights = [], []
    for oid in sorted(set(a) & set(b)):
        pa, _ = trimesh.sample.sample_surface(a[oid], ICP_SAMPLES, seed=0)
        pb, _ = trimesh.sample.sample_surface(b[oid], ICP_SAMPLES, seed=1)
        init = np.eye(4)
        init[:3, :3] = K
        init[:3, 3] = pb.mean(axis=0) - K @ pa.mean(axis=0)
        reach = ICP_REACH * float(np.linalg.norm(a[oid].extents))
        T = icp(pa, pb, init, 100, reach)
        gap, _ = cKDTree(pb).query(pa @ T[:3, :3].T + T[:3, 3])
        fitness = float(np.mean(gap < reach))  # share registered
        ups.append(T[:3, :3].T @ np.array([0.0, 1.0, 0.0]))
        weights.append(max(fitness, 1e-3))
    ups, weights = np.array(ups), np.array(weights)
    up = ups.mean(axis=0) / np.linalg.norm(ups.mean(axis=0))
    for _ in range(20):
        w = weights / np.maximum([angle_deg(u, up) for u in ups], 0.1)
        up = (ups * w[:, None]).sum(axis=0)
        up /= np.linalg.norm(up)
    return up, float(np.median([angle_deg(u, up) for u in ups]))


def plane_tilt(votes: dict, up: np.ndarray) -> float:
    """Area-weighted mean angle (deg) between the plane votes and ``up`` (NaN without plane votes)."""
    planes = [v for v in votes.values() if v["kind"] == "plane"]
    if not planes:
        return float("nan")
    w = np.array([v["area"] for v in planes])
    return float((w * np.array([angle_deg(v["up"], up) for v in planes])).sum() / w.sum())


def wall_tilt(objects, up: np.ndarray, thin_ratio: float = 0.15) -> float:
    """Area-weighted mean angle (deg) from vertical (``up``, (3,) in the objects' frame) of the thin wall panels
    among ``objects`` (:class:`phiscene.io.placed.PlacedObject`); NaN when there is none."""
    from phiscene.meshes import oriented_box
    from phiscene.topology.words import names_wall_object

    tilts, weights = [], []
    for o in objects:
        if not names_wall_object(o.description):
            continue
        box = oriented_box(o.mesh)
        extents = np.asarray(box.primitive.extents, dtype=float)
        k = int(np.argmin(extents))
        if extents[k] > thin_ratio * extents.max():
            continue
        axis = np.asarray(box.primitive.transform, dtype=float)[:3, k]
        tilts.append(float(np.degrees(np.arcsin(min(1.0, abs(axis @ up) / np.linalg.norm(axis))))))
        weights.append(float(np.prod(np.sort(extents)[1:])))
    return float(np.average(tilts, weights=weights)) if tilts else float("nan")


def main(argv: list[str]) -> None:
    root = argv[0] if argv else "data/REST3D"
    scenes = argv[1:] or scene_ids(root)
    print(f"{'scene':40s} {'ours':>6s} {'rest3d':>6s} {'between':>7s} {'icp':>5s} {'spread':>6s} {'ours|icp':>8s} "
          f"{'planes|ours':>11s} {'planes|rest3d':>13s} {'walls|ours':>10s} {'walls|rest3d':>12s} {'s':>5s}")
    for scene in scenes:
        t0 = time.perf_counter()
        data = read_rest3d(root, scene, "sam3d")
        lev = level_objects(data.objects, PlacedParams(), data.camera)
        ours = lev.transform[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # source (y-up) frame
        ref = reference_up(root, scene)
        ref_icp, spread = icp_reference_up(root, scene)
        A = source_to_z_up("y")  # the votes are recorded in the z-up source frame
        print(f"{scene:40s} {lev.rotation_deg:6.2f} {angle_deg(ref, [0.0, 1.0, 0.0]):6.2f} {angle_deg(ours, ref):7.2f} "
              f"{angle_deg(ref_icp, ref):5.2f} {spread:6.2f} {angle_deg(ours, ref_icp):8.2f} "
              f"{plane_tilt(lev.estimate.votes, A @ ours):11.2f} {plane_tilt(lev.estimate.votes, A @ ref):13.2f} "
              f"{wall_tilt(data.objects, ours):10.2f} {wall_tilt(data.objects, ref):12.2f} "
              f"{time.perf_counter() - t0:5.1f}")


if __name__ == "__main__":
    from phiscene.errors import PhisceneError

    try:
        main(sys.argv[1:])
    except PhisceneError as exc:  # the data absent or broken: one line naming the path
        sys.exit(f"levelling: {exc}")
