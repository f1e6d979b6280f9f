"""Per-stage seconds of the phi-Scene method (topology + SDF + settling) on one core.

1. Every scene of a suite already built under results/ (default ``contact``: run
   ``snakemake -j2 results/tables/phys.csv`` first; ``--suite clutter``: ``results/tables/phys_clutter.csv``),
   warm caches, timed in-process (imports, SDF grids and hull files warmed by a first run). ``total_s`` is the
   grounding job's work (``phiscene.pipeline.run_ground``: read, ground, write) without its process start;
   ``topology_s``, the geometric backend's inference, is a job of its own in the workflow.
2. One 10-object scene built into a temporary folder: warm-cache timings, and
   cold CoACD proxy seconds per object (empty cache).

Usage::

    python benchmarks/method_speed.py [--results results] [--suite contact] [--objects 10] [--method phi_scene]

It prints the machine's reference seconds first (``benchmarks/machine.py``): compare timings of different days
only beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from phiscene import topology  # noqa: E402
from phiscene.assembly.assemble import AssemblyParams, ground_scene  # noqa: E402
from phiscene.config import method_assembly  # noqa: E402
from phiscene.proxies import ProxyParams, proxy_for_mesh, scene_proxies  # noqa: E402
from phiscene.runner import set_threads  # noqa: E402
from phiscene.scene import load_scene  # noqa: E402
from phiscene.sim.settings import SimSettings  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def time_scene(scene_path: Path, cfg: dict, cache: Path, method: str = "phi_scene") -> dict:
    """Topology, SDF and settling seconds of one scene grounded by ``method`` (proxies and grids warmed first)."""
    scene = load_scene(scene_path)
    proxies = scene_proxies(scene, ProxyParams.from_dict(cfg["proxies"]), cache)
    params, sim = AssemblyParams.from_dict(method_assembly(cfg, method)), SimSettings.from_dict(cfg["sim"])
    graph = topology.infer(scene, "geometric", cfg["topology"].get("geometric", {}))
    ground_scene(scene, graph.order, proxies, params, sim, cache, graph=graph)  # warm: SDF grids, hull files, imports
    t0 = time.perf_counter()
    graph = topology.infer(scene, "geometric", cfg["topology"].get("geometric", {}))
    t_topo = time.perf_counter() - t0
    _, rec = ground_scene(scene, graph.order, proxies, params, sim, cache, graph=graph)
    return {"topology_s": t_topo, "total_s": t_topo + rec["summary"]["seconds"], **_stages(rec)}


def _stages(record: dict) -> dict:
    """Objects, summed SDF and settling seconds and unsettled objects of an assembly record."""
    objs = list(record["objects"].values())
    return {"objects": len(objs), "sdf_s": sum(o["seconds"].get("sdf", 0.0) for o in objs),
            "settle_s": sum(o["seconds"].get("settle", 0.0) for o in objs),
            "unsettled": len(record["summary"]["unsettled"])}


def time_suite_scene(results: Path, suite: str, scene: str, cfg: dict, method: str = "phi_scene") -> dict:
    """Seconds of the workflow's grounding job of one built scene (``phiscene.pipeline.run_ground`` on the
    method's topology, the proxies and the camera under ``results``), run twice in this process and timed the
    second time.

    ``topology_s`` times the geometric backend's inference, which the workflow runs as a job of its own."""
    from phiscene.pipeline import run_ground

    base = results / "scenes" / suite / scene
    backend = cfg["methods"][method].get("topology", "geometric")
    topo = results / "topology" / backend / suite / f"{scene}.json"
    camera = base / "reference" / "camera.json"
    args = (base / "initial" / "scene.json", topo, results / "proxies" / suite / f"{scene}.npz")
    with tempfile.TemporaryDirectory() as tmp:
        out = [Path(tmp) / "scene.json", Path(tmp) / "assembly.json"]
        kw = {"progress": lambda s: None, "camera_path": camera if camera.exists() else None}
        run_ground(*args, *out, method_assembly(cfg, method), cfg["sim"], results / "cache", **kw)  # warm
        t0 = time.perf_counter()
        run_ground(*args, *out, method_assembly(cfg, method), cfg["sim"], results / "cache", **kw)
        total = time.perf_counter() - t0
        rec = json.loads(out[1].read_text())
    scene_obj = load_scene(base / "initial" / "scene.json")
    t0 = time.perf_counter()
    topology.infer(scene_obj, "geometric", cfg["topology"].get("geometric", {}))
    t_topo = time.perf_counter() - t0
    return {"topology_s": t_topo, "total_s": total, **_stages(rec)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default=str(ROOT / "results"))
    ap.add_argument("--suite", default="contact", help="a suite whose scenes are built under --results")
    ap.add_argument("--objects", type=int, default=10)
    ap.add_argument("--method", default="phi_scene", help="a phi_scene-kind method of config.yaml")
    args = ap.parse_args()
    set_threads(1)
    from machine import describe, reference_seconds  # benchmarks/machine.py, beside this script

    print(describe(reference_seconds()), flush=True)
    cfg = yaml.safe_load((ROOT / "config/config.yaml").read_text())
    results = Path(args.results)
    cache = results / "cache"
    scenes = sorted((results / "scenes" / args.suite).glob("*/initial/scene.json"))
    rows = [time_suite_scene(results, args.suite, p.parents[1].name, cfg, args.method) for p in scenes]
    if rows:
        keys = ["objects", "topology_s", "sdf_s", "settle_s", "total_s"]
        mean = {k: float(np.mean([r[k] for r in rows])) for k in keys}
        print(f"{args.method}: {args.suite} suite, {len(rows)} scenes, warm caches, 1 thread: mean per scene "
              + ", ".join(f"{k} {v:.2f}" for k, v in mean.items())
              + f"; max total {max(r['total_s'] for r in rows):.2f} s; unsettled objects "
              f"{sum(r['unsettled'] for r in rows)}")
        ten = [r["total_s"] for r in rows if r["objects"] >= 10]
        if ten:
            print(f"  scenes of 10 objects or more: {len(ten)}, mean total {np.mean(ten):.2f} s, "
                  f"max {max(ten):.2f} s (target <= 3 s)")
    from phiscene.bench.build import build_scene

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        params = {**cfg["benchmark"], "n_objects": [args.objects, args.objects], "templates": ["tabletop"],
                  "sim": cfg["sim"], "proxies": cfg["proxies"]}
        build_scene(tmp / "scene", "contact", 0, params, cache)
        scene_path = tmp / "scene/initial/scene.json"
        r = time_scene(scene_path, cfg, cache, args.method)
        print(f"{r['objects']}-object scene, warm caches, 1 thread: topology {r['topology_s']:.2f} s, "
              f"SDF {r['sdf_s']:.2f} s, settling {r['settle_s']:.2f} s, total {r['total_s']:.2f} s "
              f"(target <= 3 s); unsettled {r['unsettled']}")
        scene = load_scene(scene_path)
        cold = []
        for o in scene.objects:
            t0 = time.perf_counter()
            proxy_for_mesh(o.mesh_path, ProxyParams.from_dict(cfg["proxies"]), tmp / "cold-cache")
            cold.append(time.perf_counter() - t0)
        print(f"cold CoACD proxies: mean {np.mean(cold):.2f} s per object, max {max(cold):.2f} s "
              f"(target mean <= 3 s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
