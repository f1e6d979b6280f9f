"""The ``ray`` remedy's trade-off: a suite grounded with ``faithful.ray`` off and on, from the same inputs.

Closing a gap along the camera ray (a depth error) instead of straight down keeps an object where the photo shows
it and moves it farther in 3D. With ground truth (the embedded suites) the pose error against it says which is
closer to the scene; without it (real scenes) the displacement from the input says how much farther it moves.

Usage::

    python benchmarks/ray.py OUT [--results results] [--suite clutter] [--method phi_scene] [-j 2]

Reads ``<results>/scenes/<suite>/<scene>/{initial,reference}``, ``<results>/topology/<backend>/<suite>/<scene>.json``
and ``<results>/proxies/<suite>/<scene>.npz`` (a finished workflow run), grounds every scene with the method's
settings and ``ray`` off and on into ``OUT/{off,on}/<scene>/``, and prints per scene and as means over scenes:
pose error against ground truth (centre distance m, rotation deg, ADD-S m) when the suite has it, the displacement
(m) and rotation change (deg) from the input, and the pybullet drift (m, deg).
"""

from __future__ import annotations

import argparse
import logging
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from phiscene.config import method_assembly


def ground(task: tuple) -> tuple[str, str, float]:
    """Ground one scene (``task``: results, suite, scene, backend, assembly, sim, out, cache); returns its time."""
    import time

    from phiscene.pipeline import run_ground

    results, suite, scene, backend, assembly, sim, out, cache, label = task
    logging.disable(logging.INFO)
    base = results / "scenes" / suite / scene
    camera = base / "reference" / "camera.json"
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    run_ground(base / "initial" / "scene.json", results / "topology" / backend / suite / f"{scene}.json",
               results / "proxies" / suite / f"{scene}.npz", out / "scene.json", out / "assembly.json", assembly, sim,
               cache, progress=lambda m: None, camera_path=camera if camera.is_file() else None)
    return scene, label, time.perf_counter() - t0


def measure(results: Path, suite: str, scene: str, grounded: Path, sim: dict, cache: Path) -> dict:
    """Pose error against ground truth (when there is one), displacement from the input, pybullet drift."""
    from phiscene.metrics.drift import drift_bullet
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.metrics.pose import pose_metrics
    from phiscene.proxies import read_proxies
    from phiscene.scene import load_scene
    from phiscene.sim.settings import SimSettings

    base = results / "scenes" / suite / scene
    gt = load_scene(base / "gt" / "scene.json") if (base / "gt" / "scene.json").is_file() else None
    out = load_scene(grounded / "scene.json")
    m = pose_metrics(out, load_scene(base / "initial" / "scene.json"), gt)
    d = drift_bullet(out, read_proxies(results / "proxies" / suite / f"{scene}.npz"), PhysicalParams(),
                     SimSettings.from_dict(sim), cache)
    return {**{k: v for k, v in m.items() if isinstance(v, float)}, "drift_trans": d["drift_trans"],
            "drift_rot": d["drift_rot"]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="output folder (off/ and on/ per scene)")
    ap.add_argument("--results", type=Path, default=Path("results"))
    ap.add_argument("--suite", default="clutter")
    ap.add_argument("--method", default="phi_scene")
    ap.add_argument("--config", type=Path, default=Path("config/config.yaml"))
    ap.add_argument("-j", "--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    cfg = yaml.safe_load(a.config.read_text())
    scenes_dir = a.results / "scenes" / a.suite
    if not scenes_dir.is_dir():
        sys.exit(f"ray: no scenes of suite {a.suite!r} under {scenes_dir} (run the workflow first)")
    scenes = sorted(p.name for p in scenes_dir.iterdir() if (p / "initial" / "scene.json").is_file())
    backend = cfg["methods"][a.method]["topology"]
    cache = Path(cfg.get("cache_dir", "results/cache"))
    tasks = []
    for label, on in (("off", False), ("on", True)):
        assembly = method_assembly(cfg, a.method)
        assembly.setdefault("faithful", {})["ray"] = on
        tasks += [(a.results, a.suite, s, backend, assembly, cfg["sim"], a.out / label / s, cache, label)
                  for s in scenes]
    with ProcessPoolExecutor(a.jobs) as ex:
        for scene, label, seconds in ex.map(ground, tasks):
            print(f"grounded {scene} ray {label} in {seconds:.1f} s", flush=True)
    keys = ("gt_translation_mean", "gt_rotation_mean", "gt_adds_mean", "displacement_mean", "displacement_max",
            "rotation_mean", "drift_trans", "drift_rot")
    rows = {label: [] for label in ("off", "on")}
    for s in scenes:
        line = [f"{s[:24]:24s}"]
        for label in ("off", "on"):
            m = measure(a.results, a.suite, s, a.out / label / s, cfg["sim"], cache)
            rows[label].append(m)
            line.append(f"{label}: " + " ".join(f"{m[k]:.4f}" for k in keys if k in m))
        print(" | ".join(line), flush=True)
    print("columns: " + ", ".join(k for k in keys if k in rows["off"][0]))
    for label in ("off", "on"):
        print(f"mean ray {label}: " + ", ".join(f"{k} {np.mean([r[k] for r in rows[label]]):.4f}"
                                                for k in keys if k in rows[label][0]))


if __name__ == "__main__":
    main()
