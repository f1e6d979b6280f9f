"""Leaning objects against ground truth: how many leaning edges a topology backend finds, and how a grounded
method's leaning objects end up, their rotation error split about the lean direction.

Usage::

    python benchmarks/leaning.py --suite clutter [--results results] [--backend geometric] [--method phi_scene]

Reads ``results/scenes/<suite>/<scene>/{initial,gt}/scene.json`` and ``gt/topology.json``,
``results/topology/<backend>/<suite>/<scene>.json`` and ``results/methods/<method>/<suite>/<scene>/scene.json``.

Edges: the ground truth's ``leans_on`` edges, how many the backend has with the same relation, how many it has as
another relation (``supports`` for a book on a box's edge), and its ``leans_on`` edges ground truth lacks.
Objects: for every ground-truth leaning object, the rotation from its ground-truth orientation to the input's and
to the result's, as the rotation vector's components about the horizontal lean direction (roll: the object
stands on a corner), about the horizontal axis across it (pitch: the lean angle) and about the vertical (yaw),
in degrees; the lean direction points from the object's centre towards its wall (minus the wall's horizontal
normal) or towards the centre of the object it leans on.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from phiscene.metrics.pose import object_centre
from phiscene.metrics.topology import relations
from phiscene.scene import load_scene
from phiscene.topology.graph import load
from phiscene.transforms import decompose


def split_rotation(pose: np.ndarray, reference: np.ndarray, direction: np.ndarray) -> tuple[float, float, float]:
    """|roll|, |pitch|, |yaw| (deg) of the rotation from ``reference`` to ``pose`` (both (4, 4)) about the
    horizontal unit ``direction`` (3,), the horizontal axis across it and the vertical."""
    rv = Rotation.from_matrix(decompose(pose)[0] @ decompose(reference)[0].T).as_rotvec()
    across = np.array([-direction[1], direction[0], 0.0])
    return tuple(math.degrees(abs(float(rv @ a))) for a in (direction, across, np.array([0.0, 0.0, 1.0])))


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", required=True)
    ap.add_argument("--results", default="results", type=Path)
    ap.add_argument("--backend", default="geometric")
    ap.add_argument("--method", default="phi_scene")
    args = ap.parse_args(argv)
    scenes = sorted(p.parent.parent.name for p in (args.results / "scenes" / args.suite).glob("*/gt/topology.json"))
    if not scenes:
        sys.exit(f"leaning: no ground-truth topology under {args.results / 'scenes' / args.suite}")
    found = other = wrong = total = 0
    rows = []
    for s in scenes:
        base = args.results / "scenes" / args.suite / s
        gt_edges = relations(load(base / "gt/topology.json"))
        topo = args.results / "topology" / args.backend / args.suite / f"{s}.json"
        pred = relations(load(topo)) if topo.is_file() else {}
        lean = [k for k, r in gt_edges.items() if r == "leans_on"]
        total += len(lean)
        found += sum(pred.get(k) == "leans_on" for k in lean)
        other += sum(k in pred and pred[k] != "leans_on" for k in lean)
        wrong += sum(r == "leans_on" and k not in gt_edges for k, r in pred.items())
        result = args.results / "methods" / args.method / args.suite / s / "scene.json"
        if not result.is_file():
            continue
        gt, ini, out = load_scene(base / "gt/scene.json"), load_scene(base / "initial/scene.json"), load_scene(result)
        walls = {p.id: p for p in gt.structure}
        for partner, oid in lean:
            centre = object_centre(gt.get(oid))
            if partner in walls:
                u = -np.asarray(walls[partner].normal, float)
            else:
                u = object_centre(gt.get(partner)) - centre
            u[2] = 0.0
            if np.linalg.norm(u) < 1e-9:
                continue
            u /= np.linalg.norm(u)
            ref = np.asarray(gt.get(oid).pose, float)
            rows.append((s, oid, partner, split_rotation(np.asarray(ini.get(oid).pose, float), ref, u),
                         split_rotation(np.asarray(out.get(oid).pose, float), ref, u)))
    print(f"{args.suite}, {args.backend}: ground truth has {total} leaning edges; found as leans_on {found}, "
          f"as another relation {other}; leans_on edges ground truth lacks: {wrong}")
    if rows:
        print(f"\n{'scene':10s} {'object':8s} {'leans on':9s} {'input roll/pitch/yaw':>22s} "
              f"{args.method + ' roll/pitch/yaw':>26s}")
        for s, oid, partner, a, b in rows:
            print(f"{s:10s} {oid:8s} {partner:9s} {a[0]:7.1f}{a[1]:7.1f}{a[2]:7.1f}   "
                  f"{b[0]:7.1f}{b[1]:7.1f}{b[2]:7.1f}")
        a, b = np.array([r[3] for r in rows]).mean(axis=0), np.array([r[4] for r in rows]).mean(axis=0)
        print(f"mean over {len(rows)} objects: input {a[0]:.2f} / {a[1]:.2f} / {a[2]:.2f} deg, "
              f"{args.method} {b[0]:.2f} / {b[1]:.2f} / {b[2]:.2f} deg")


if __name__ == "__main__":
    main(sys.argv[1:])
