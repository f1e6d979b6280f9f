"""What the ``ballast`` remedy's declared centres of mass and the ``base`` remedy's completed bases hold: each
grounded scene that has one, released in the drift protocol (pybullet and MuJoCo) as written, then without the
completed bases (when it has any), then with every object a uniform solid without a completed base, from the same
poses.

A declared centre (``com`` in ``scene.json``) is a modelling choice: an object at rest in the photo that topples as
a uniform solid (a vase of flowers reconstructed as one solid) is given its mass low in its base, and every
simulator, metric and export uses it. This shows, per scene, what that choice is worth: the drift with the
declared centres (what the tables report) next to the drift without them, and the ballasted object that moves most
without its centre. A completed base (``base`` in ``scene.json``, one more convex piece under an object whose round
bottom, a guess of its hidden side, cannot stand) is the same kind of choice, about shape.

Usage::

    python benchmarks/ballast.py [--results results] [--suite real] [--method phi_scene] [--config config/config.yaml]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml

from phiscene.metrics.drift import drift_bullet, drift_mujoco
from phiscene.metrics.physical import PhysicalParams
from phiscene.proxies import read_proxies
from phiscene.scene import load_scene
from phiscene.sim.mujoco import MujocoParams
from phiscene.sim.settings import SimSettings


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"))
    ap.add_argument("--suite", default="real")
    ap.add_argument("--method", default="phi_scene")
    ap.add_argument("--config", type=Path, default=Path("config/config.yaml"))
    ap.add_argument("--cache-dir", type=Path, default=Path("results/cache"))
    a = ap.parse_args(argv)
    cfg = yaml.safe_load(a.config.read_text()) if a.config.is_file() else {}
    metrics = cfg.get("metrics", {}) or {}
    sim = SimSettings.from_dict(cfg.get("sim", {}) or {})
    phys = PhysicalParams.from_dict(metrics.get("physical", {}) or {})
    mj = MujocoParams.from_dict(metrics.get("mujoco", {}) or {})
    root = a.results / "methods" / a.method / a.suite
    if not root.is_dir():
        sys.exit(f"ballast: no results of method {a.method!r} on suite {a.suite!r} under {root}")
    found = 0
    for d in sorted(p for p in root.iterdir() if (p / "scene.json").is_file()):
        scene = load_scene(d / "scene.json")
        ballasted = [o.id for o in scene.objects if o.com is not None]
        based = [o.id for o in scene.objects if o.base is not None]
        if not ballasted and not based:
            continue
        found += 1
        proxies = read_proxies(a.results / "proxies" / a.suite / f"{d.name}.npz")
        rows = {}
        for label in ("declared", "no bases", "uniform"):
            if label == "no bases" and not based:
                continue
            scene = load_scene(d / "scene.json")
            for o in scene.objects:
                if label != "declared":
                    o.base = None
                if label == "uniform":
                    o.com = None
            rows[label] = (drift_bullet(scene, proxies, phys, sim, a.cache_dir),
                           drift_mujoco(scene, proxies, phys, sim, mj))
        changed = ballasted + [i for i in based if i not in ballasted]
        parts = [f"{d.name}: {len(ballasted)} ballasted, {len(based)} with a completed base"]
        for label, (b, m) in rows.items():
            worst = max(changed, key=lambda i: b["objects"][i]["drift_trans"])
            parts.append(f"{label}: pybullet {b['drift_trans'] * 1000:.1f} mm / {b['drift_rot']:.2f} deg, MuJoCo "
                         f"{m['drift_trans'] * 1000:.1f} mm / {m['drift_rot']:.2f} deg, most moved {worst} "
                         f"({b['objects'][worst]['drift_trans'] * 1000:.0f} mm in pybullet)")
        print("; ".join(parts), flush=True)
    if not found:
        print(f"ballast: no scene of {a.method!r} on {a.suite!r} has a declared centre of mass or a completed base")


if __name__ == "__main__":
    main()
