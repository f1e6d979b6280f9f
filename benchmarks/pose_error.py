"""Per-object pose error of a grounded method against ground truth, next to its input's, with the remedy its
assembly log records: where a method loses (or gains) alignment, object by object.

Usage::

    python benchmarks/pose_error.py phi_scene --suite clutter [--results results] [--top 20] [--csv out.csv]

Reads ``results/scenes/<suite>/<scene>/{initial,gt}/scene.json`` and
``results/methods/<method>/<suite>/<scene>/{scene,assembly}.json`` of every scene the method has. Per free object:
centre distance to GT (m) and rotation angle to GT (deg) of the input and of the result, the settling remedy,
the joint-settling motion and the supporters it lost. Prints the objects that got worse the most, then the means
over objects and over scenes (the tables' convention: mean of the per-scene means, with
:func:`phiscene.metrics.pose.pose_metrics`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from phiscene.metrics.pose import object_centre, pose_metrics
from phiscene.scene import load_scene
from phiscene.transforms import decompose, rotation_angle


def object_rows(results: Path, method: str, suite: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-object and per-scene frames of ``method`` on ``suite`` (see the module docstring)."""
    objects, scenes = [], []
    root = results / "methods" / method / suite
    if not root.is_dir():
        sys.exit(f"pose_error: no results of method {method!r} on suite {suite!r} under {root}")
    for d in sorted(p for p in root.iterdir() if (p / "scene.json").is_file()):
        base = results / "scenes" / suite / d.name
        gt, ini, out = load_scene(base / "gt" / "scene.json"), load_scene(base / "initial" / "scene.json"), \
            load_scene(d / "scene.json")
        log = json.loads((d / "assembly.json").read_text())["objects"] if (d / "assembly.json").is_file() else {}
        for o in ini.free_ids:
            g = gt.get(o)
            rg = decompose(np.asarray(g.pose, float))[0]
            rec = log.get(o, {})
            cert = rec.get("certificate") or {}
            objects.append({
                "scene": d.name, "object": o, "description": g.description,
                "input_error_m": float(np.linalg.norm(object_centre(ini.get(o)) - object_centre(g))),
                "result_error_m": float(np.linalg.norm(object_centre(out.get(o)) - object_centre(g))),
                "input_rot_deg": math.degrees(rotation_angle(decompose(np.asarray(ini.get(o).pose, float))[0], rg)),
                "result_rot_deg": math.degrees(rotation_angle(decompose(np.asarray(out.get(o).pose, float))[0], rg)),
                "remedy": rec.get("settle_remedy"), "joint_settle": rec.get("joint_settle"),
                "lost": ",".join(cert.get("lost", []))})
        pm = pose_metrics(out, ini, gt)
        pi = pose_metrics(ini, ini, gt)
        scenes.append({"scene": d.name, **{f"input_{k}": pi[k] for k in ("gt_translation_mean", "gt_adds_mean")},
                       **{k: pm[k] for k in ("displacement_mean", "gt_translation_mean", "gt_rotation_mean",
                                             "gt_adds_mean")}})
    return pd.DataFrame(objects), pd.DataFrame(scenes)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("method")
    ap.add_argument("--suite", default="clutter")
    ap.add_argument("--results", type=Path, default=Path("results"))
    ap.add_argument("--top", type=int, default=20, help="objects listed (largest loss of alignment first)")
    ap.add_argument("--csv", type=Path, help="write the per-object rows here")
    a = ap.parse_args(argv)
    obj, sc = object_rows(a.results, a.method, a.suite)
    if obj.empty:
        sys.exit(f"pose_error: no scenes of {a.method!r} on {a.suite!r}")
    obj["worse_m"] = obj["result_error_m"] - obj["input_error_m"]
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(obj.sort_values("worse_m", ascending=False).head(a.top).round(3).to_string(index=False))
    print(f"\n{len(obj)} objects in {len(sc)} scenes; mean over objects: error {obj.input_error_m.mean():.4f} m "
          f"(input) -> {obj.result_error_m.mean():.4f} m, rotation {obj.input_rot_deg.mean():.2f} -> "
          f"{obj.result_rot_deg.mean():.2f} deg; worse by > 2 cm: {(obj.worse_m > 0.02).mean():.2f}, "
          f"better by > 2 cm: {(obj.worse_m < -0.02).mean():.2f}; over 1 m from GT: "
          f"{int((obj.result_error_m > 1).sum())}")
    print("mean of per-scene means:", sc.drop(columns="scene").mean().round(4).to_dict())
    print("remedies:", obj.remedy.value_counts().to_dict())
    if a.csv:
        obj.to_csv(a.csv, index=False)


if __name__ == "__main__":
    main()
