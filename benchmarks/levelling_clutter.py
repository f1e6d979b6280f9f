"""Levelling against the exact answer: the up estimate on a built suite's camera-tilted initial scenes.

A ``foundation`` suite (``clutter``) writes each initial scene twice: levelled, and in the tilted camera frame it
was levelled from (``initial/camera_frame.json``, with the drawn tilt in ``meta.tilt_transform``). This re-runs
:func:`phiscene.levelling.estimate_up` on the tilted scenes with the given :class:`~phiscene.levelling.LevelParams`
and reports, per scene, the drawn tilt and the angle between the estimated and the true up direction, then the
median, mean, 90th percentile and maximum over the suite. Nothing is written.

    python benchmarks/levelling_clutter.py [RESULTS] [--suite clutter] [--set weight_power=1 ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from phiscene.levelling import LevelParams, angle_deg, estimate_up
from phiscene.scene import load_scene


def tilted_scenes(results: Path, suite: str) -> list[Path]:
    """The camera-frame initial scenes of a built suite, sorted (``SystemExit`` when there are none)."""
    found = sorted((results / "scenes" / suite).glob("*/initial/camera_frame.json"))
    if not found:
        raise SystemExit(f"no camera-frame scenes under {results / 'scenes' / suite} (build the {suite} suite: "
                         f"snakemake -j2 results/tables/phys_{suite}.csv)")
    return found


def levelling_error(path: Path, params: LevelParams) -> tuple[float, float]:
    """The drawn tilt and the error of the up estimate (deg) of one camera-frame scene."""
    scene = load_scene(path, check_meshes=False)
    true_up = np.asarray(scene.meta["tilt_transform"], dtype=float)[:3, :3] @ np.array([0.0, 0.0, 1.0])
    estimate = estimate_up({o.id: o.world_mesh() for o in scene.objects}, [0.0, 0.0, 1.0], params)
    return angle_deg(true_up, [0.0, 0.0, 1.0]), angle_deg(estimate.up, true_up)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="?", default="results")
    ap.add_argument("--suite", default="clutter")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="LevelParams overrides")
    args = ap.parse_args(argv)
    params = LevelParams.from_dict({k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)})
    errors = []
    print(f"{'scene':12s} {'tilt':>6s} {'error':>6s}")
    for path in tilted_scenes(Path(args.results), args.suite):
        tilt, err = levelling_error(path, params)
        errors.append(err)
        print(f"{path.parent.parent.name:12s} {tilt:6.2f} {err:6.2f}")
    e = np.array(errors)
    print(f"error (deg): median {np.median(e):.2f}, mean {e.mean():.2f}, 90th percentile {np.percentile(e, 90):.2f}, "
          f"max {e.max():.2f}; within 3 deg: {int((e <= 3).sum())} of {len(e)}")


if __name__ == "__main__":
    main()
