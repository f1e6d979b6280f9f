"""How many real SAM 3D Objects meshes are hollow, double-walled shells (needs the REST3D page assets).

For every ``sam3d`` mesh of the REST3D page assets (README "Real scenes"): its faces, whether it is closed once
its vertices are merged, the share of its faces that face a sealed cavity (:func:`phiscene.solid.inner_faces`),
the generalised winding number at the deepest point of its largest cavity before and after the inner walls are
dropped, the share of its solid in cavities (:func:`phiscene.solid.cavity_share`, voxels) and the volume the raw
mesh encloses (closed once merged: the wall) against the solid's (:func:`phiscene.solid.solid_surface`). A line
per mesh, then a summary: how many meshes hold a cavity, the mean cavity share, how many hold at least 0.2.

    python benchmarks/hollow_shells.py [ROOT]      # ROOT defaults to data/REST3D
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import trimesh

from phiscene.meshes import load_mesh
from phiscene.sdf import winding_number_exact
from phiscene.solid import ShellParams, cavity_share, inner_faces, solid_surface, voxel_shell

#: Grid cells along the longest axis of the closed solid surface the wall's volume is compared with.
SOLID_RESOLUTION = 64


def closed_volume(mesh: trimesh.Trimesh) -> float:
    """Volume enclosed by ``mesh`` once its vertices are merged (NaN when it is not closed)."""
    m = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    return float(m.volume) if m.is_watertight else float("nan")


def main(root: str = "data/REST3D") -> int:
    files = sorted(Path(root, "assets").glob("*/sam3d/meshes/*.glb"))
    if not files:
        print(f"no meshes under {root}/assets/*/sam3d/meshes (README 'Real scenes' says how to get them)")
        return 1
    params = ShellParams()
    rows = []
    print(f"{'scene':14s} {'mesh':34s} {'faces':>6s} closed inner  wn_before wn_after cavity wall/solid  s")
    for f in files:
        mesh = load_mesh(f)
        t0 = time.perf_counter()
        inner = inner_faces(mesh, params)
        seconds = time.perf_counter() - t0
        wn_before = wn_after = ratio = float("nan")
        if inner.any():
            vox = voxel_shell(mesh, params)
            deepest = vox.deepest[np.argmax(np.bincount(vox.deepest_region))][None]
            wn_before = float(winding_number_exact(mesh.triangles, deepest)[0])
            wn_after = float(winding_number_exact(mesh.triangles[~inner], deepest)[0])
            solid = solid_surface(mesh, SOLID_RESOLUTION)
            if solid.is_watertight and solid.volume > 0:
                ratio = closed_volume(mesh) / float(solid.volume)
        closed = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True).is_watertight
        cavity = cavity_share(mesh, params)
        rows.append((inner.any(), cavity, closed))
        print(f"{f.parts[-4][:14]:14s} {f.stem[:34]:34s} {len(mesh.faces):6d} {str(closed):6s} {inner.mean():5.2f} "
              f"{wn_before:9.2f} {wn_after:8.2f} {cavity:6.3f} {ratio:10.3f} {seconds:5.2f}")
    cav = np.array([c for _, c, _ in rows])
    print(f"\n{len(rows)} meshes: {sum(c for *_, c in rows)} closed once merged, {sum(h for h, *_ in rows)} with "
          f"a sealed cavity behind an inner wall; cavity share of the solid mean {cav.mean():.3f}, "
          f"{int((cav >= 0.2).sum())} meshes at least 0.2 (their median {np.median(cav[cav >= 0.2]):.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:2]))
