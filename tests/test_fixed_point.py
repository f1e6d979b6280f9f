"""A physically valid scene is a fixed point of grounding: what is already at rest stays where it was put.

The scene is what a reconstruction looks like to phiscene (meshes with holes, a table whose top and legs are
overlapping boxes, no closed manifold), written in a camera-tilted, y-up frame, then imported (levelled) and
grounded with the workflow's own config, as a user runs the two commands. The oracle is the scene itself: a table
standing on the floor and a stack of boxes resting flat on it are in equilibrium, so levelling must undo the tilt
exactly and grounding must move nothing farther than the simulators' resting noise (1 mm).
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import trimesh
from scenes import open_dense, table_mesh

from phiscene.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
TILT_DEG = 12.0


def phiscene(*args, cwd):
    res = subprocess.run([sys.executable, "-m", "phiscene.cli", *args], cwd=cwd, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    return res


def test_a_resting_tilted_reconstruction_is_returned_where_it_was_put(tmp_path):
    T = trimesh.transformations.translation_matrix
    objects = {"table": table_mesh(),
               "box0": trimesh.creation.box([0.3, 0.24, 0.1], transform=T([0.1, 0.0, 0.79])),
               "box1": trimesh.creation.box([0.2, 0.16, 0.08], transform=T([0.1, 0.0, 0.88]))}
    to_files = (trimesh.transformations.rotation_matrix(np.radians(TILT_DEG), [1, 0, 0])
                @ trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # z-up -> y-up, then tilted
    (tmp_path / "in").mkdir()
    for name, mesh in objects.items():
        open_dense(mesh, 8000).apply_transform(to_files).export(tmp_path / "in" / f"{name}.glb")
    cfg = ROOT / "config" / "config.yaml"
    out = phiscene("import-placed", "in", "imported", cwd=tmp_path)
    assert f"levelled by {TILT_DEG:.2f} deg" in out.stdout
    phiscene("ground", "imported/initial", "grounded", "--config", str(cfg), "--cache-dir", "cache", cwd=tmp_path)
    before, after = load_scene(tmp_path / "imported/initial/scene.json"), load_scene(tmp_path / "grounded/scene.json")
    for name, mesh in objects.items():
        # levelled: the object's box as built (z up), up to the import's placement of the floor at height 0
        np.testing.assert_allclose(before.get(name).world_mesh().bounds, mesh.bounds, atol=1e-6)
        # grounded: where it was put, to 1 mm (it was 7 mm higher per level when the proxies bulged past the mesh)
        np.testing.assert_allclose(after.get(name).world_mesh().bounds, mesh.bounds, atol=1e-3, err_msg=name)
