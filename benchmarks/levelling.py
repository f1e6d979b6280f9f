"""Levelling of real SAM 3D Objects scenes against REST3D's (needs the REST3D page assets; README "Real scenes").

For each scene: the tilt our estimate corrects (:func:`phiscene.levelling.estimate_up` through
:func:`phiscene.io.placed.level_objects`), REST3D's tilt (the Kabsch rotation between the object centres of
``sam3d/`` and ``ours/``, :func:`phiscene.io.rest3d.reference_up`), the angle between the two up directions, and an
independent plausibility check: the area-weighted mean angle between each object's dominant upward planar region
(table tops, seats, plates) and each up direction (a level scene has level tables).

    python benchmarks/levelling.py [ROOT] [SCENE ...]      # ROOT defaults to data/REST3D, scenes to all of them
"""

from __future__ import annotations

import sys
import time

import numpy as np

from phiscene.io.placed import PlacedParams, level_objects, source_to_z_up
from phiscene.io.rest3d import read_rest3d, reference_up, scene_ids
from phiscene.levelling import angle_deg


def plane_tilt(votes: dict, up: np.ndarray) -> float:
    """Area-weighted mean angle (deg) between the plane votes and ``up`` (NaN without plane votes)."""
    planes = [v for v in votes.values() if v["kind"] == "plane"]
    if not planes:
        return float("nan")
    w = np.array([v["weight"] for v in planes])
    return float((w * np.array([angle_deg(v["up"], up) for v in planes])).sum() / w.sum())


def main(argv: list[str]) -> None:
    root = argv[0] if argv else "data/REST3D"
    scenes = argv[1:] or scene_ids(root)
    print(f"{'scene':40s} {'ours':>6s} {'rest3d':>6s} {'between':>7s} {'planes|ours':>11s} {'planes|rest3d':>13s} "
          f"{'s':>5s}")
    for scene in scenes:
        t0 = time.perf_counter()
        data = read_rest3d(root, scene, "sam3d")
        lev = level_objects(data.objects, PlacedParams(), data.camera)
        ours = lev.transform[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # source (y-up) frame
        ref = reference_up(root, scene)
        A = source_to_z_up("y")  # the votes are recorded in the z-up source frame
        print(f"{scene:40s} {lev.rotation_deg:6.2f} {angle_deg(ref, [0.0, 1.0, 0.0]):6.2f} {angle_deg(ours, ref):7.2f} "
              f"{plane_tilt(lev.estimate.votes, A @ ours):11.2f} {plane_tilt(lev.estimate.votes, A @ ref):13.2f} "
              f"{time.perf_counter() - t0:5.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])
