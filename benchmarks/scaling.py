"""Cost growth with scene size: per-stage wall time and peak memory for scenes of 5, 10, 20 and 40 objects.

Each scene is the contact suite's ``tabletop`` template with ``n_objects`` fixed
to the size (one or two objects resting on flat-topped ones, the rest standing on
the ground around them; :func:`phiscene.bench.build.build_scene`). Every stage
then runs in a fresh child process, one thread, through the same
:mod:`phiscene.pipeline` function the workflow calls:

``build``     the benchmark scene itself (ground-truth simulation, degradation, render; own cache, so
              the first build also makes the asset library; the reference view's visibility check
              is off: at 40 objects some objects are always occluded at 320x240)
``proxies``   CoACD/V-HACD/convex proxies of every object, cold cache (meshes repeat: the library has 48 assets)
``topology``  the ``geometric`` support graph
``ground``    phi-Scene grounding: SDF penetration resolution + settling, cold SDF-grid cache
              (``sdf_s``/``settle_s`` split it, from the assembly log)
``ground_warm`` the same again with the SDF grids cached: the solve and settling alone
``physical``  physical metrics: static contact validity + pybullet drift

Peak memory is the child's ``ru_maxrss`` (peak resident set, imports included);
``stage_mb`` is its growth during the stage alone. Modules are imported before
the clock starts (time and ``stage_mb`` leave out the interpreter's start-up).
``pairs_total`` is
``n (n - 1) / 2``; ``pairs_evaluated`` counts the pairs a stage actually
examined after bounding-box pruning (topology: AABB-near pairs handed to the
contact query, each direction once; ground: context bodies the SDF loss
evaluated; physical: pairs of the exact SDF evaluation). The 1-minute load
average before and after each stage is recorded: the machine may be shared.

Writes ``<out>/scaling.csv`` and ``<out>/scaling.png`` (log-log time against
objects with a least-squares slope per stage, and peak memory). Usage::

    python benchmarks/scaling.py [--sizes 5 10 20 40] [--out results/bench] [--rebuild]
                                 [--stages build proxies ...] [--plot-only]

Existing scenes are reused (their earlier ``build`` row is kept) unless ``--rebuild``.
The whole run takes about 3 minutes on an idle core; on a busy machine run it with
``nohup`` and follow ``results/bench/scaling/nXX/<stage>.log``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("build", "proxies", "topology", "ground", "ground_warm", "physical")
#: Stages whose growth the plot fits (``build`` is the benchmark generator, not the method).
FIT_STAGES = ("proxies", "topology", "ground", "ground_warm", "physical")


def _rss_mb() -> float:
    """Peak resident set size of this process so far (MiB; Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _paths(work: Path, n: int) -> dict[str, Path]:
    d = work / f"n{n:02d}"
    return {"dir": d, "scene": d / "scene", "initial": d / "scene/initial/scene.json", "cache": d / "cache",
            "build_cache": work / "build_cache", "proxies": d / "proxies.npz", "topology": d / "topology.json",
            "grounded": d / "ground/scene.json", "ground_log": d / "ground/log.json", "physical": d / "physical.json"}


def worker(stage: str, n: int, work: Path, cfg: dict) -> dict:
    """Run one stage for the ``n``-object scene in this process; return its measurements.

    The stage's modules (torch, pybullet, ...) are imported before the clock starts, so
    ``seconds`` and ``stage_mb`` are the stage's own work, not the interpreter's start-up.
    """
    from phiscene import pipeline
    from phiscene.config import method_assembly
    from phiscene.runner import set_threads

    set_threads(1)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(name)s: %(message)s")
    import pybullet  # noqa: F401  (imported lazily by the stages)
    import torch  # noqa: F401

    import phiscene.assembly.assemble  # noqa: F401  (warm imports: torch, pybullet, trimesh, scipy)
    import phiscene.bench.build  # noqa: F401
    import phiscene.metrics.physical  # noqa: F401
    import phiscene.sim.bullet  # noqa: F401
    import phiscene.topology  # noqa: F401

    p = _paths(work, n)
    # min_visible_pixels 0: at 40 objects some are always occluded in the 320x240 reference view; the
    # view is not an input of the timed stages, so the generator's visibility check is switched off
    render = {**cfg["benchmark"].get("render", {}), "min_visible_pixels": 0}
    bench = {**cfg["benchmark"], "n_objects": [n, n], "templates": ["tabletop"], "render": render,
             "sim": cfg["sim"], "proxies": cfg["proxies"]}
    calls = {
        "build": lambda: phiscene.bench.build.build_scene(p["scene"], "contact", 0, bench, p["build_cache"]),
        "proxies": lambda: pipeline.run_proxies(p["initial"], p["proxies"], cfg["proxies"], p["cache"]),
        "topology": lambda: pipeline.run_topology(p["initial"], p["topology"], "geometric",
                                                  cfg["topology"].get("geometric", {})),
        "ground": lambda: pipeline.run_ground(p["initial"], p["topology"], p["proxies"], p["grounded"],
                                              p["ground_log"], method_assembly(cfg, "phi_scene"), cfg["sim"],
                                              p["cache"], progress=lambda line: None),
        "physical": lambda: pipeline.run_metrics(
            [{"method": "phi_scene", "scene": p["grounded"], "out": p["physical"], "sections": ["physical"]}],
            {"physical": cfg["metrics"]["physical"], "sim": cfg["sim"]}, proxies_path=p["proxies"],
            cache_dir=p["cache"]),
    }
    calls["ground_warm"] = calls["ground"]
    if stage not in calls:
        raise ValueError(f"unknown stage {stage!r}; known: {STAGES}")
    start = _rss_mb()
    t0 = time.perf_counter()
    calls[stage]()
    seconds = time.perf_counter() - t0
    peak = _rss_mb()
    extra: dict = {}
    if stage in ("ground", "ground_warm"):
        rec = json.loads(p["ground_log"].read_text())
        objs = rec["objects"].values()
        extra = {"sdf_s": sum(o["seconds"]["sdf"] + o["seconds"].get("context", 0.0) for o in objs),
                 "settle_s": sum(o["seconds"]["settle"] for o in objs),
                 "pairs_evaluated": sum(len(o["sdf_context"]) for o in objs),
                 "unsettled": len(rec["summary"]["unsettled"])}
    elif stage == "physical":
        extra = {"pairs_evaluated": json.loads(p["physical"].read_text())["physical"]["pairs_evaluated"]}
    elif stage == "topology":
        extra = {"pairs_evaluated": topology_near_pairs(p["initial"], cfg)}
    elif stage == "proxies":
        from phiscene.scene import load_scene

        extra = {"unique_meshes": len({_digest(o.mesh_path) for o in load_scene(p["initial"]).objects})}
    return {"objects": n, "stage": stage, "seconds": seconds, "peak_rss_mb": peak, "stage_mb": peak - start,
            **extra}


def _digest(path: Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def topology_near_pairs(scene_path: Path, cfg: dict) -> int:
    """Ordered object pairs the geometric backend hands to its contact query (AABB-near), halved.

    Counted after the timed run by calling the backend's own per-object query
    (:func:`phiscene.topology.geometric.object_contacts`), which records a
    tolerance for exactly the pairs that passed its bounding-box test.
    """
    from phiscene.scene import load_scene
    from phiscene.topology.contacts import prepare_bodies
    from phiscene.topology.geometric import GROUND, GeometricParams, object_contacts

    scene = load_scene(scene_path)
    params = GeometricParams.from_dict(cfg["topology"].get("geometric", {}))
    bodies = prepare_bodies(scene, params)
    ordered = sum(len([k for k in object_contacts(b, bodies, scene.ground_height, params).tol if k != GROUND])
                  for b in bodies.values())
    return ordered // 2


def run_stage(stage: str, n: int, work: Path, config: Path) -> dict:
    """Run :func:`worker` in a child process (honest peak RSS per stage) and add the load averages."""
    load0 = os.getloadavg()[0]
    cmd = [sys.executable, __file__, "--worker", stage, "--n", str(n), "--work", str(work), "--config", str(config)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    log = work / f"n{n:02d}" / f"{stage}.log"  # the stage's log, to follow a long run
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as err:
        res = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=err, text=True, env=env)
    if res.returncode != 0:
        raise RuntimeError(f"stage {stage} of the {n}-object scene failed:\n{log.read_text()[-4000:]}")
    row = json.loads(res.stdout.strip().splitlines()[-1])
    row.update(load1_before=load0, load1_after=os.getloadavg()[0])
    return row


def fit_exponent(objects: np.ndarray, seconds: np.ndarray) -> float:
    """Least-squares slope of log(seconds) against log(objects): cost ~ objects ** slope."""
    return float(np.polyfit(np.log(objects), np.log(seconds), 1)[0])


def plot(df: pd.DataFrame, out_png: Path) -> dict[str, float]:
    """Log-log time per stage with fitted slopes, and memory per stage; returns the slopes.

    The time panel also shows the two parts of ``ground_warm`` (SDF solve, settling) and a
    slope-1 guide through the first ``ground_warm`` point.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullLocator

    from phiscene.atomic import atomic_path

    fig = Figure(figsize=(11, 5.6), dpi=110)
    FigureCanvasAgg(fig)
    ax_t, ax_m = fig.subplots(1, 2)
    slopes = {}
    sizes = sorted(set(df["objects"]))
    for k, stage in enumerate(s for s in STAGES if s in set(df["stage"])):
        d = df[df["stage"] == stage].sort_values("objects")
        x, y = d["objects"].to_numpy(float), d["seconds"].to_numpy(float)
        color = f"C{k}"
        label = stage
        if stage in FIT_STAGES and len(d) >= 2:
            slopes[stage] = s = fit_exponent(x, y)
            a = np.exp(np.polyfit(np.log(x), np.log(y), 1)[1])
            ax_t.plot(x, a * x ** s, "--", color=color, lw=1)
            label = f"{stage} (slope {s:.2f})"
        ax_t.plot(x, y, "o-" if stage in FIT_STAGES else "o:", color=color, label=label)
        ax_m.plot(x, d["peak_rss_mb"], "o-", color=color, label=f"{stage}: peak RSS")
        ax_m.plot(x, d["stage_mb"], "s--", color=color, ms=3, lw=1)
    d = df[df["stage"] == "ground_warm"].sort_values("objects")
    for extra, style in (("sdf_s", "^"), ("settle_s", "v")):
        if len(d) >= 2 and d[extra].notna().all():
            s = fit_exponent(d["objects"].to_numpy(float), d[extra].to_numpy(float))
            ax_t.plot(d["objects"], d[extra], style, color="0.35", ms=5, ls=":", lw=0.8,
                      label=f"ground_warm: {extra[:-2]} only (slope {s:.2f})")
    if len(d):
        x0, y0 = float(d["objects"].iloc[0]), float(d["seconds"].iloc[0])
        ax_t.plot(sizes, [y0 * v / x0 for v in sizes], color="0.6", lw=0.8, label="slope 1 (linear)")
    ax_t.set(xscale="log", yscale="log", xlabel="objects", ylabel="wall time (s)",
             title="time per stage (1 thread, log-log, dashed: fit)")
    ax_m.set(xscale="log", xlabel="objects", ylabel="MiB", ylim=(0, None),
             title="memory: peak RSS (solid), stage growth (dashed)")
    for ax in (ax_t, ax_m):
        ax.set_xticks(sizes, [str(v) for v in sizes])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.grid(True, which="both", alpha=0.3)
    for ax in (ax_t, ax_m):
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, frameon=False)
    fig.tight_layout()
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return slopes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5, 10, 20, 40])
    ap.add_argument("--out", default=str(ROOT / "results/bench"), help="folder of scaling.csv / scaling.png")
    ap.add_argument("--config", default=str(ROOT / "config/config.yaml"))
    ap.add_argument("--rebuild", action="store_true", help="rebuild scenes that exist already (build is timed then)")
    ap.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES),
                    help="stages to run (default: all; build only where the scene is missing or --rebuild)")
    ap.add_argument("--plot-only", action="store_true", help="redraw scaling.png from scaling.csv")
    ap.add_argument("--worker", choices=STAGES, help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--work", help=argparse.SUPPRESS)
    args = ap.parse_args()
    cfg = yaml.safe_load(Path(args.config).read_text())
    out = Path(args.out)
    work = Path(args.work) if args.work else out / "scaling"
    if args.worker:
        print(json.dumps(worker(args.worker, args.n, work, cfg)))
        return 0

    from phiscene.atomic import write_text

    csv = out / "scaling.csv"
    old = pd.read_csv(csv) if csv.exists() else pd.DataFrame()
    rows = []
    for n in [] if args.plot_only else args.sizes:
        p = _paths(work, n)
        stages = [s for s in STAGES if s in args.stages]
        if p["initial"].exists() and not args.rebuild and "build" in stages:
            stages.remove("build")
        if len(old):  # keep the earlier measurements of the stages not run now
            keep = old[(old["objects"] == n) & ~old["stage"].isin(stages)]
            rows.extend(keep.to_dict("records"))
        if "proxies" in stages:  # cold caches for the method stages
            shutil.rmtree(p["cache"], ignore_errors=True)
        for stage in stages:
            row = run_stage(stage, n, work, Path(args.config))
            rows.append(row)
            print(f"{n:3d} objects  {stage:9s} {row['seconds']:8.2f} s  peak {row['peak_rss_mb']:7.1f} MiB "
                  f"(+{row['stage_mb']:.1f})  load {row['load1_before']:.2f}->{row['load1_after']:.2f}", flush=True)
        done = pd.DataFrame(rows)
        if len(old):  # keep the sizes this run did not measure
            done = pd.concat([old[~old["objects"].isin(done["objects"])], done], ignore_index=True)
        done["pairs_total"] = done["objects"] * (done["objects"] - 1) // 2
        cols = ["objects", "stage", "seconds", "peak_rss_mb", "stage_mb", "pairs_total", "pairs_evaluated",
                "sdf_s", "settle_s", "unsettled", "unique_meshes", "load1_before", "load1_after"]
        done = done.reindex(columns=cols).sort_values(["objects", "stage"], key=_stage_key, kind="stable")
        write_text(csv, done.to_csv(index=False, float_format="%.4g"))
    df = pd.read_csv(csv)
    slopes = plot(df, out / "scaling.png")
    print(f"wrote {csv} and {out / 'scaling.png'}")
    print("fitted exponent (time ~ objects^k): " + ", ".join(f"{k} {v:.2f}" for k, v in slopes.items()))
    warm = df[df["stage"] == "ground_warm"]
    if len(warm) >= 2:
        print("ground_warm parts: " + ", ".join(
            f"{c[:-2]} {fit_exponent(warm['objects'].to_numpy(float), warm[c].to_numpy(float)):.2f}"
            for c in ("sdf_s", "settle_s")))
    return 0


def _stage_key(col: pd.Series) -> pd.Series:
    return col.map(STAGES.index) if col.name == "stage" else col


if __name__ == "__main__":
    sys.exit(main())
