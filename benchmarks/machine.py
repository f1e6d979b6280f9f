"""Seconds of two fixed reference workloads on one core: how fast this machine is, for timings made on another day.

The same commit's timings differ by a factor of two from one session's machine to the next (custom_viga's proxies
took 16.4 s in one session and 34.5 s in another, same code). A timing is comparable with an older one only
beside these reference seconds, or with the older commit timed again on the same machine.

* ``bullet``: pybullet stepping, what grounding spends most of its time on: 12 convex bodies of 256 vertices
  each (seeded ellipsoid samples) dropped onto the ground in a 3 x 4 grid and stepped 600 frames through
  :class:`phiscene.sim.bullet.BulletWorld` with the default simulation settings.
* ``kdtree``: nearest-neighbour queries, what the reconstruction metrics' ICP spends its time on: 50 rounds of
  20,480 queries into a KD-tree of 20,480 points (``scipy.spatial.cKDTree``, one worker).

Each workload runs ``repeat`` times; the minimum is reported.

Usage::

    python benchmarks/machine.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

#: Bodies, hull vertices and frames of the ``bullet`` workload.
BULLET_BODIES, BULLET_VERTICES, BULLET_FRAMES = 12, 256, 600
#: Points (each cloud) and query rounds of the ``kdtree`` workload.
KD_POINTS, KD_ROUNDS = 20480, 50


def bullet_seconds() -> float:
    """Wall seconds of the ``bullet`` workload (one run)."""
    import trimesh

    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld
    from phiscene.sim.settings import SimSettings
    from phiscene.transforms import make_pose

    rng = np.random.default_rng(0)
    sim = SimSettings()
    with tempfile.TemporaryDirectory() as tmp, BulletWorld(sim, tmp) as world:
        world.add_ground(0.0)
        for k in range(BULLET_BODIES):
            v = rng.normal(size=(BULLET_VERTICES, 3))
            v *= np.array([0.06, 0.05, 0.04]) / np.linalg.norm(v, axis=1, keepdims=True)
            hull = trimesh.convex.convex_hull(v)
            pose = make_pose(np.eye(3), [0.15 * (k % 4), 0.15 * (k // 4), 0.05 + 0.02 * k])
            world.add_body(f"b{k}", [hull.vertices], pose, rigid_props(hull, [hull.vertices], sim.density))
        t0 = time.perf_counter()
        world.step_frames(BULLET_FRAMES)
        return time.perf_counter() - t0


def kdtree_seconds() -> float:
    """Wall seconds of the ``kdtree`` workload (one run)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(0)
    target = rng.normal(size=(KD_POINTS, 3))
    source = rng.normal(size=(KD_POINTS, 3))
    t0 = time.perf_counter()
    tree = cKDTree(target)
    for _ in range(KD_ROUNDS):
        tree.query(source, k=1, workers=1)
    return time.perf_counter() - t0


def reference_seconds(repeat: int = 3) -> dict[str, float]:
    """The minimum over ``repeat`` runs of each workload, ``{"bullet": s, "kdtree": s}``."""
    return {"bullet": min(bullet_seconds() for _ in range(repeat)),
            "kdtree": min(kdtree_seconds() for _ in range(repeat))}


def describe(ref: dict[str, float]) -> str:
    """One line for a benchmark's output."""
    return f"machine reference (benchmarks/machine.py): bullet {ref['bullet']:.2f} s, kdtree {ref['kdtree']:.2f} s"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each workload; the minimum is reported")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be >= 1")
    print(describe(reference_seconds(args.repeat)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
