"""Estimated walls against given ones, on a built suite whose walls are known (``clutter``).

Each initial scene with given walls is stripped of its walls and of its given attachments and passed to
:func:`phiscene.walls.estimate_walls` (with the camera of ``reference/camera.json``). Each estimated wall is
matched to the given wall nearest in normal: the angle between their normals and the offset difference (positive:
the estimate lies behind the given wall) are printed per scene, then summarised.

With ``--ground OUT`` every scene is also grounded three times with ``phi_scene``'s settings on the geometric graph
of its stripped scene (attachments inferred, as on real scenes): with no walls, with the estimated walls and with
the given ones. Printed per mode: the mean over the free objects of the input (the objects the tables count) of the
object-centre distance and the rotation angle to ground truth (:func:`phiscene.metrics.pose.pose_metrics`, weighted
by each scene's object count). Outputs go to ``OUT/<mode>/<scene>/``.

    python benchmarks/walls.py [RESULTS] [--suite clutter] [--config config/config.yaml] [--ground OUT] [-j 2]
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from phiscene.scene import Scene, load_scene, save_scene
from phiscene.walls import estimate_walls

MODES = ("none", "estimated", "given")


def stripped(scene: Scene) -> Scene:
    """``scene`` without walls and without given attachments."""
    return replace(scene, structure=[], objects=[replace(o, attached=None) for o in scene.objects])


def eye_of(scene_dir: Path) -> np.ndarray | None:
    """The camera centre of a built scene (``reference/camera.json``), if it has one."""
    from phiscene.render import camera_eye, read_camera

    path = scene_dir / "reference" / "camera.json"
    return camera_eye(read_camera(path)) if path.is_file() else None


def compare(scene_dir: Path) -> list[tuple[str, float, float]]:
    """(given wall id, angle deg, offset difference m) per estimated wall of one built scene."""
    scene = load_scene(scene_dir / "initial" / "scene.json")
    est = estimate_walls(stripped(scene), eye=eye_of(scene_dir))
    out = []
    for w in est.planes:
        angles = {g.id: float(np.degrees(np.arccos(np.clip(np.dot(g.normal, w.normal), -1.0, 1.0))))
                  for g in scene.structure}
        best = min(angles, key=angles.get)
        out.append((best, angles[best], w.offset - next(g.offset for g in scene.structure if g.id == best)))
    return out


def ground_one(job: tuple) -> tuple[str, str, dict]:
    """Ground one scene in one mode; returns (mode, scene, pose metrics against ground truth)."""
    from phiscene import topology
    from phiscene.config import method_assembly
    from phiscene.metrics.pose import pose_metrics
    from phiscene.pipeline import run_ground

    results, suite, scene_name, mode, out, cfg = job
    base = results / "scenes" / suite / scene_name
    initial = load_scene(base / "initial" / "scene.json")
    bare = stripped(initial)
    planes = {"none": [], "given": initial.structure,
              "estimated": estimate_walls(bare, eye=eye_of(base)).planes}[mode]
    work = out / mode / scene_name
    work.mkdir(parents=True, exist_ok=True)
    scene_path = save_scene(replace(bare, structure=planes), work / "initial.json")
    graph = topology.infer(load_scene(scene_path), "geometric", cfg["topology"]["geometric"],
                           attached=cfg["topology"]["attached"])
    topology.save(graph, work / "topology.json")
    camera = base / "reference" / "camera.json"
    run_ground(scene_path=scene_path, topology_path=work / "topology.json",
               proxies_path=results / "proxies" / suite / f"{scene_name}.npz", out_scene=work / "scene.json",
               out_log=work / "assembly.json", assembly=method_assembly(cfg, "phi_scene"), sim=cfg["sim"],
               cache_dir=Path(cfg["cache_dir"]), camera_path=camera if camera.is_file() else None)
    m = pose_metrics(load_scene(work / "scene.json"), initial, load_scene(base / "gt" / "scene.json"))
    return mode, scene_name, m


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="?", default="results")
    ap.add_argument("--suite", default="clutter")
    ap.add_argument("--config", default="config/config.yaml")
    ap.add_argument("--ground", metavar="OUT", help="also ground every scene with no, estimated and given walls")
    ap.add_argument("-j", "--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    results = Path(args.results)
    scenes = sorted(p.parent.parent for p in (results / "scenes" / args.suite).glob("*/initial/scene.json"))
    scenes = [d for d in scenes if load_scene(d / "initial" / "scene.json", check_meshes=False).structure]
    if not scenes:
        raise SystemExit(f"no built scenes with given walls under {results / 'scenes' / args.suite}")
    print(f"{'scene':12s} {'walls':>5s}  estimated -> given (angle deg, offset m)")
    found = {d.name: compare(d) for d in scenes}
    for name, walls in found.items():
        print(f"{name:12s} {len(walls):5d}  " + "; ".join(f"{g} {a:.1f} {o:+.3f}" for g, a, o in walls))
    rows = [r for walls in found.values() for r in walls]
    if rows:
        a, o = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
        print(f"{len(rows)} walls in {sum(map(bool, found.values()))} of {len(scenes)} scenes; angle "
              f"{a.min():.1f}-{a.max():.1f} (median {np.median(a):.1f}) deg; offset {o.min():+.3f} to {o.max():+.3f} "
              f"(median {np.median(o):+.3f}) m")
    if not args.ground:
        return
    cfg = yaml.safe_load(Path(args.config).read_text())
    jobs = [(results, args.suite, d.name, mode, Path(args.ground), cfg) for mode in MODES for d in scenes]
    sums = {mode: np.zeros(3) for mode in MODES}
    with ProcessPoolExecutor(args.jobs) as pool:
        for mode, name, m in pool.map(ground_one, jobs):
            n = m["objects"]
            sums[mode] += (n, n * m["gt_translation_mean"], n * m["gt_rotation_mean"])
            print(f"  {mode:9s} {name}: {m['gt_translation_mean']:.4f} m, {m['gt_rotation_mean']:.2f} deg", flush=True)
    for mode in MODES:
        n, t, r = sums[mode]
        print(f"{mode:9s} {int(n)} objects: {t / n:.4f} m, {r / n:.2f} deg from ground truth")


if __name__ == "__main__":
    main()
