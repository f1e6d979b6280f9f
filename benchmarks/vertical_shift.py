"""Would a floor placed where the grounded objects' vertical motions balance be closer to the input, and to the truth?

Grounding closes every object's vertical gap to what holds it: an object a depth error put too high comes down, one
sunk into its supporter comes up. The scene's floor is set at import (the resting bottoms of the objects that
stand on it, :func:`phiscene.levelling.floor_height`), before anything is known of the objects above them. Had the
floor been ``delta`` higher, every object would end ``delta`` higher (to first order: walls and attached objects
aside), and the ``delta`` that moves the free objects least is minus the median of their vertical motion. This
script measures, per scene of a grounded suite, that ``delta`` and what the grounded scene moved rigidly by it
gives: the mean displacement from the input and, where the suite has ground truth, the mean object-centre error
against it (:func:`phiscene.metrics.pose.pose_metrics`, the tables' own measures), next to the median vertical
error against ground truth (the shift that would be right). Nothing is grounded again.

    python benchmarks/vertical_shift.py [RESULTS] [--suite clutter ...] [--method phi_scene]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from phiscene.metrics.pose import object_centre, pose_metrics
from phiscene.scene import Scene, load_scene
from phiscene.transforms import make_pose


def lifted(scene: Scene, ids: list[str], delta: float) -> Scene:
    """``scene`` with the objects ``ids`` moved up by ``delta`` (m)."""
    lift = make_pose(translation=[0.0, 0.0, delta])
    return scene.with_poses({i: lift @ np.asarray(scene.get(i).pose) for i in ids})


def median_rise(scene: Scene, ref: Scene, ids: list[str]) -> float:
    """Median over ``ids`` of the height (m) of each object's centre in ``scene`` above its centre in ``ref``."""
    return float(np.median([object_centre(scene.get(i))[2] - object_centre(ref.get(i))[2] for i in ids]))


def scene_row(results: Path, suite: str, method: str, name: str) -> dict:
    """One scene's balancing shift and what it does (module docstring)."""
    base = results / "scenes" / suite / name
    initial = load_scene(base / "initial/scene.json")
    grounded = load_scene(results / "methods" / method / suite / name / "scene.json")
    gt_path = base / "gt/scene.json"
    gt = load_scene(gt_path) if gt_path.is_file() else None
    ids = [i for i in initial.free_ids if i in set(grounded.ids)]
    delta = -median_rise(grounded, initial, ids)
    now, shifted = pose_metrics(grounded, initial, gt), pose_metrics(lifted(grounded, ids, delta), initial, gt)
    row = {"scene": name, "objects": len(ids), "delta": delta,
           "disp": now["displacement_mean"], "disp_shifted": shifted["displacement_mean"]}
    if gt is not None:
        row |= {"gt_delta": -median_rise(grounded, gt, [i for i in ids if i in set(gt.ids)]),
                "gt": now["gt_translation_mean"], "gt_shifted": shifted["gt_translation_mean"]}
    return row


def row_text(label: str, r: dict, gt: bool) -> str:
    """One printed row (cm) of :func:`scene_row`'s figures."""
    text = f"  {label[:28]:28s} {100 * r['delta']:6.2f} | {100 * r['disp']:6.2f} -> {100 * r['disp_shifted']:6.2f}"
    if gt:
        text += f" | {100 * r['gt_delta']:6.2f} | {100 * r['gt']:6.2f} -> {100 * r['gt_shifted']:6.2f}"
    return text


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="?", default="results")
    ap.add_argument("--suite", nargs="+", default=["clutter"])
    ap.add_argument("--method", default="phi_scene")
    args = ap.parse_args(argv)
    results = Path(args.results)
    for suite in args.suite:
        folder = results / "methods" / args.method / suite
        if not folder.is_dir():
            raise SystemExit(f"{folder}: no grounded scenes (run the suite's tables first)")
        rows = [scene_row(results, suite, args.method, d.name) for d in sorted(folder.iterdir())
                if (d / "scene.json").is_file()]
        gt = "gt" in rows[0]
        print(f"{suite} ({args.method}, {len(rows)} scenes), cm: balancing shift | displacement from the input now "
              f"-> shifted" + (" | GT vertical offset | GT error now -> shifted" if gt else ""))
        for r in rows:
            print(row_text(r["scene"], r, gt))
        mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k not in ("scene", "objects")}
        line = row_text("mean", mean, gt)
        if gt:
            corr = np.corrcoef([r["delta"] for r in rows], [r["gt_delta"] for r in rows])[0, 1]
            line += f"   (correlation of the two shifts {corr:.2f})"
        print(line)


if __name__ == "__main__":
    main()
