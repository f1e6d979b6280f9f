"""SDF grid error and build time of a suite's initial meshes, under the grid settings and under overrides.

The SDF stage reads every object through its grid (:mod:`phiscene.sdf_grid`); ``SdfGrid.error`` is the grid's
largest and mean deviation from the exact signed distance of the full mesh near its surface. This script builds
the grid of every initial mesh with more than ``--min-faces`` faces once per setting and prints each one's error
and build time, then the medians and the count over 1 cm. Each build runs in a fresh process (no in-process cache
carries over from one setting to the next), and nothing is written to the disk cache.

Usage::

    python benchmarks/sdf_grids.py results/scenes/clutter --set max_faces=0 [--min-faces 10000] [--limit 20]

``--set`` may be repeated (one setting per flag, ``key=value`` of ``GridParams``); the grid settings as they are
always run first. What it found on ``clutter`` is in ``docs/measurements.md`` (the SDF grids of decimated meshes,
after GROUND 35): the decimation to 5000 faces reads thin or open reconstructions up to 26 cm off, the full mesh
(``max_faces=0``) 0.7-2.4 cm on the same five meshes, in about the same time.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from phiscene import sdf_grid  # noqa: E402
from phiscene.scene import load_scene  # noqa: E402


def settings(pairs: list[str]) -> list[dict]:
    """``key=value`` strings -> GridParams overrides (values read as YAML), the grid settings first."""
    out = [{}]
    for pair in pairs:
        key, _, value = pair.partition("=")
        if not key or not _:
            raise SystemExit(f"--set takes key=value, got {pair!r}")
        out.append({key: yaml.safe_load(value)})
    return out


def build(scene_path: str, oid: str, overrides: dict) -> tuple[float, float, float]:
    """Max and mean grid error (m) and build time (s) of one object's grid (run in a fresh process: every
    in-process cache cold)."""
    mesh = load_scene(scene_path).get(oid).mesh()
    t0 = time.perf_counter()
    grid = sdf_grid.build_grid(mesh, sdf_grid.GridParams(**overrides))
    return grid.error["max_abs"], grid.error["mean_abs"], time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite_dir", type=Path, help="results/scenes/<suite> (each scene's initial/scene.json)")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="GridParams override key=value")
    ap.add_argument("--min-faces", type=int, default=10000)
    ap.add_argument("--limit", type=int, default=0, help="at most this many meshes (0 = all)")
    args = ap.parse_args()
    scenes = sorted(args.suite_dir.glob("*/initial/scene.json"))
    if not scenes:
        print(f"{args.suite_dir}: no */initial/scene.json", file=sys.stderr)
        return 1
    runs = settings(args.sets)
    rows = []
    for path in scenes:
        scene = load_scene(path)
        for obj in scene.objects:
            mesh = obj.mesh()
            if len(mesh.faces) <= args.min_faces:
                continue
            with mp.get_context("spawn").Pool(1, maxtasksperchild=1) as pool:
                res = [pool.apply(build, (str(path), obj.id, o)) for o in runs]
            rows.append(res)
            cells = "  ".join(f"{m * 100:6.2f} cm {t:5.2f} s" for m, _, t in res)
            print(f"{path.parent.parent.name}/{obj.id:40s} {len(mesh.faces):6d} faces  {cells}", flush=True)
            if args.limit and len(rows) >= args.limit:
                break
        if args.limit and len(rows) >= args.limit:
            break
    if not rows:
        print(f"no mesh with more than {args.min_faces} faces under {args.suite_dir}", file=sys.stderr)
        return 1
    a = np.array(rows)  # (meshes, settings, 3)
    for k, o in enumerate(runs):
        name = ", ".join(f"{key}={v}" for key, v in o.items()) or "grid settings"
        print(f"{name}: {len(a)} meshes, max error median {np.median(a[:, k, 0]) * 100:.2f} cm, over 1 cm "
              f"{int((a[:, k, 0] > 0.01).sum())}, mean error median {np.median(a[:, k, 1]) * 1000:.2f} mm, build "
              f"median {np.median(a[:, k, 2]):.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
