"""How far the camera may tilt: the up estimate of real scenes turned by more pitch and roll.

A scene turned as a whole (objects and camera) is the same scene, so a levelling that depends only on the scene
gives the same up direction, turned with it. For each REST3D ``sam3d`` scene (README "Real scenes"), this estimates
up (:func:`phiscene.levelling.estimate_up`, the frame's up axis as the prior, as the import does), then turns the
whole scene about the camera's x axis (pitch) and about its viewing axis (roll) by each of ``TURNS`` degrees,
estimates again, and reports the angle between that estimate and the first one turned the same way, with the total
tilt the turned scene has (the angle between the first estimate, turned, and the prior). Then, per band of total
tilt, how many turned scenes are off by more than 3 degrees. Nothing is written.

    python benchmarks/levelling_tilts.py [ROOT] [SCENE ...]   # ROOT defaults to data/REST3D, scenes to all of them
"""

from __future__ import annotations

import sys

from scipy.spatial.transform import Rotation

from phiscene.io.placed import source_to_z_up
from phiscene.io.rest3d import read_rest3d, scene_ids
from phiscene.levelling import LevelParams, angle_deg, estimate_up
from phiscene.transforms import make_pose

#: Extra pitch and roll (deg) each scene is turned by.
TURNS = (-40, -30, -20, -10, 10, 20, 30, 40)
#: Bands of total tilt (deg) of the summary.
BANDS = ((0, 20), (20, 30), (30, 35), (35, 40), (40, 50), (50, 90))
#: An estimate farther than this (deg) from the turned first one is counted off.
OFF_DEG = 3.0


def scene_turns(root: str, scene: str, params: LevelParams) -> list[tuple[str, float, float]]:
    """``(turn, total tilt, error)`` (deg) of one scene for every turn of :data:`TURNS` about both axes."""
    data = read_rest3d(root, scene, "sam3d")
    A = make_pose(source_to_z_up("y"))  # z up: the camera looks along +y, its x axis is x
    meshes = {o.id: o.mesh.copy().apply_transform(A) for o in data.objects}
    up0 = estimate_up(meshes, [0.0, 0.0, 1.0], params).up
    out = []
    for axis, name in (("x", "pitch"), ("y", "roll")):
        for deg in TURNS:
            R = Rotation.from_euler(axis, deg, degrees=True).as_matrix()
            truth = R @ up0
            T = make_pose(R)
            turned = {k: m.copy().apply_transform(T) for k, m in meshes.items()}
            up = estimate_up(turned, [0.0, 0.0, 1.0], params).up
            out.append((f"{name}{deg:+d}", angle_deg(truth, [0.0, 0.0, 1.0]), angle_deg(up, truth)))
    return out


def main(argv: list[str]) -> None:
    root = argv[0] if argv else "data/REST3D"
    scenes = argv[1:] or scene_ids(root)
    params = LevelParams()
    rows = []
    for scene in scenes:
        turns = scene_turns(root, scene, params)
        rows += turns
        print(f"{scene[:24]:24s} " + " ".join(f"{t}:{tilt:.0f}/{err:.1f}" for t, tilt, err in turns), flush=True)
    print(f"turn: total tilt / error (deg); off: error > {OFF_DEG:g} deg")
    for lo, hi in BANDS:
        band = [err for _, tilt, err in rows if lo <= tilt < hi]
        print(f"total tilt {lo:2d}-{hi:2d} deg: {len(band):3d} turned scenes, {sum(e > OFF_DEG for e in band):3d} off")


if __name__ == "__main__":
    from phiscene.errors import PhisceneError

    try:
        main(sys.argv[1:])
    except PhisceneError as exc:  # the data absent or broken: one line naming the path
        sys.exit(f"levelling_tilts: {exc}")
