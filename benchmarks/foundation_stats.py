"""Statistics of a built suite's initial scenes against the real SAM 3D Objects figures the `foundation`
degradation model reproduces (config/README.md, `benchmark.degrade.foundation`).

Usage::

    python benchmarks/foundation_stats.py results/scenes/clutter [--cache results/cache] [--csv out.csv]

Per object of every scene: penetration and gap to the nearest neighbour (the physical metric's contact
validity, ground included), the translation and rotation error against ground truth (object centres; rotation
angle) of the model's own draw (the camera-frame scene with the drawn tilt undone) and of the levelled input the
methods receive (adding the levelling's residual), the scale factor, faces and watertightness of the initial
mesh (as loaded, and closed once its vertices are merged) and how hollow it is (the share of its solid in sealed
cavities of a double wall, :func:`phiscene.solid.cavity_share`); per scene: the drawn gravity tilt and the
levelling's residual, and the 2 s pybullet release drift of the initial scene (the physical metric's protocol,
convex-hull proxies). Prints target vs measured.

A suite without ground truth (the real scenes: ``results/scenes/real``) gets the statistics that need none
(contacts, drift, meshes); ``--hollow-blind`` measures contacts with the raw meshes' winding numbers, as before
:mod:`phiscene.solid` (a hollow mesh's cavity outside it), to show what the hollow shells hid.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import trimesh

from phiscene.metrics.drift import drift_bullet
from phiscene.metrics.physical import PhysicalParams, contact_validity
from phiscene.metrics.pose import object_centre
from phiscene.proxies import ProxyParams, scene_proxies
from phiscene.scene import load_scene
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, invert, rotation_angle

#: The real figures (issue "A benchmark that looks like real foundation-model output").
TARGETS = {
    "penetration mean (mm)": "3.5", "penetration max (mm)": "18", "share penetrating > 1 mm": "0.5",
    "gap to nearest, mean (cm)": "4.3", "release drift 2 s (m)": "0.60", "release drift 2 s (deg)": "66.5",
    "translation error median (cm)": "5.2", "translation error p90 (cm)": "15.6", "translation error max (cm)": "43",
    "rotation error median (deg)": "3.6", "rotation error p90 (deg)": "11", "rotation error max (deg)": "29",
    "translation error, levelled input, median (cm)": "(5.2 + levelling)",
    "translation error, levelled input, p90 (cm)": "(15.6 + levelling)",
    "rotation error, levelled input, median (deg)": "(3.6 + levelling)",
    "rotation error, levelled input, p90 (deg)": "(11 + levelling)",
    "scale factor min": "0.88", "scale factor max": "1.06", "gravity tilt median (deg)": "14.7",
    "gravity tilt min (deg)": "2.5", "gravity tilt max (deg)": "22", "faces per mesh, median": "~30000",
    "watertight meshes": "0 (files split vertices at texture seams)", "closed once vertices merged (share)": "0.85",
    "cavity share of the solid, mean": "0.19", "meshes with cavity share >= 0.2": "0.33",
}


def scene_rows(folder: Path, cache: Path, physical: PhysicalParams, sim: SimSettings) -> tuple[list, dict]:
    """Per-object rows and the per-scene record of one built scene folder."""
    from phiscene.solid import cavity_share

    gt = load_scene(folder / "gt" / "scene.json") if (folder / "gt" / "scene.json").exists() else None
    initial = load_scene(folder / "initial" / "scene.json")
    tilted = folder / "initial" / "camera_frame.json"
    untilted = None  # the per-object errors alone: the camera-frame scene with the drawn tilt undone exactly
    if tilted.exists():
        cam = load_scene(tilted)
        undo = invert(np.asarray(cam.meta["tilt_transform"], dtype=float))
        untilted = cam.with_poses({o.id: undo @ o.pose for o in cam.objects})
    static = contact_validity(initial, physical)["objects"]
    proxies = scene_proxies(initial, ProxyParams(backend="convex"), cache)
    drift = drift_bullet(initial, proxies, physical, sim, cache)
    rows = []
    for o in initial.objects:
        w = static[o.id]["w"]
        mesh = o.mesh()
        row = {"scene": folder.name, "id": o.id, "pen_m": static[o.id]["pen_depth"],
               "gap_m": max(w, 0.0) if w is not None else np.nan,
               "faces": len(mesh.faces), "watertight": bool(mesh.is_watertight),
               "closed": bool(trimesh.Trimesh(mesh.vertices, mesh.faces, process=True).is_watertight),
               "cavity": cavity_share(mesh),
               "drift_m": drift["objects"][o.id]["drift_trans"], "drift_deg": drift["objects"][o.id]["drift_rot"]}
        if gt is not None:
            g = gt.get(o.id)
            R0, _, _ = decompose(g.pose)
            R1, _, s1 = decompose(o.pose)
            model = untilted.get(o.id) if untilted is not None else o
            row.update({"model_translation_m": float(np.linalg.norm(object_centre(model) - object_centre(g))),
                        "model_rotation_deg": math.degrees(rotation_angle(R0, decompose(model.pose)[0])),
                        "translation_m": float(np.linalg.norm(object_centre(o) - object_centre(g))),
                        "rotation_deg": math.degrees(rotation_angle(R0, R1)),
                        "scale": float(o.meta.get("degrade", {}).get("scale", s1 / decompose(g.pose)[2]))})
        rows.append(row)
    frame = initial.meta.get("frame", {})
    return rows, {"scene": folder.name, "tilt_deg": frame.get("tilt_deg", np.nan),
                  "residual_deg": frame.get("residual_deg", np.nan),
                  "drift_m": drift["drift_trans"], "drift_deg": drift["drift_rot"]}


def summary(objects: pd.DataFrame, scenes: pd.DataFrame) -> dict:
    """The measured value of every :data:`TARGETS` entry."""
    nan = pd.Series([np.nan])
    t, r = (objects.get("model_translation_m", nan) * 100, objects.get("model_rotation_deg", nan))
    tl, rl = objects.get("translation_m", nan) * 100, objects.get("rotation_deg", nan)
    scale = objects.get("scale", nan)
    return {
        "penetration mean (mm)": objects["pen_m"].mean() * 1000, "penetration max (mm)": objects["pen_m"].max() * 1000,
        "share penetrating > 1 mm": (objects["pen_m"] > 1e-3).mean(),
        "gap to nearest, mean (cm)": objects["gap_m"].mean() * 100,
        "release drift 2 s (m)": scenes["drift_m"].mean(), "release drift 2 s (deg)": scenes["drift_deg"].mean(),
        "translation error median (cm)": t.median(), "translation error p90 (cm)": t.quantile(0.9),
        "translation error max (cm)": t.max(), "rotation error median (deg)": r.median(),
        "rotation error p90 (deg)": r.quantile(0.9), "rotation error max (deg)": r.max(),
        "translation error, levelled input, median (cm)": tl.median(),
        "translation error, levelled input, p90 (cm)": tl.quantile(0.9),
        "rotation error, levelled input, median (deg)": rl.median(),
        "rotation error, levelled input, p90 (deg)": rl.quantile(0.9),
        "scale factor min": scale.min(), "scale factor max": scale.max(),
        "gravity tilt median (deg)": scenes["tilt_deg"].median(), "gravity tilt min (deg)": scenes["tilt_deg"].min(),
        "gravity tilt max (deg)": scenes["tilt_deg"].max(), "faces per mesh, median": objects["faces"].median(),
        "watertight meshes": int(objects["watertight"].sum()),
        "closed once vertices merged (share)": objects["closed"].mean(),
        "cavity share of the solid, mean": objects["cavity"].mean(),
        "meshes with cavity share >= 0.2": (objects["cavity"] >= 0.2).mean(),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("suite_dir", type=Path, help="results/scenes/<suite>")
    ap.add_argument("--cache", type=Path, default=Path("results/cache"))
    ap.add_argument("--csv", type=Path, help="write the per-object rows here")
    ap.add_argument("--hollow-blind", action="store_true",
                    help="contacts with the raw meshes' winding numbers (a hollow mesh's cavity counts as outside)")
    args = ap.parse_args(argv)
    if args.hollow_blind:
        import phiscene.solid

        phiscene.solid.outer_shell = lambda mesh, params=None: mesh
    folders = sorted(p for p in args.suite_dir.iterdir() if (p / "initial" / "scene.json").exists())
    if not folders:
        print(f"{args.suite_dir}: no built scenes (…/initial/scene.json)", file=sys.stderr)
        return 2
    objs, scenes = [], []
    for f in folders:
        rows, rec = scene_rows(f, args.cache, PhysicalParams(), SimSettings())
        objs += rows
        scenes.append(rec)
        print(f"{f.name}: {len(rows)} objects, tilt {rec['tilt_deg']:.1f} deg (residual {rec['residual_deg']:.2f}),"
              f" drift {rec['drift_m']:.3f} m / {rec['drift_deg']:.1f} deg", file=sys.stderr)
    objects, per_scene = pd.DataFrame(objs), pd.DataFrame(scenes)
    if args.csv:
        objects.to_csv(args.csv, index=False)
    measured = summary(objects, per_scene)
    table = pd.DataFrame({"target (real SAM 3D)": TARGETS, "measured": {k: f"{v:.3g}" for k, v in measured.items()}})
    print(f"{len(folders)} scenes, {len(objects)} objects, levelling residual median "
          f"{per_scene['residual_deg'].median():.2f} deg (max {per_scene['residual_deg'].max():.2f})")
    print(table.to_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
