"""Small scenes in the REST3D page-asset layout (``assets/<scene>/<variant>/{meshes/*.glb, simulation.json}``).

Generated, never real data: a table (top on four legs), a box and a plate on it, optionally a poster on a wall,
built y-up in a levelled frame and then tilted by a known rotation, as a camera-frame foundation model would
write them. The analytic up direction of the written scene is ``tilt @ [0, 1, 0]``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation


def table(top_height: float = 0.75, size=(1.2, 0.8), thickness: float = 0.04) -> trimesh.Trimesh:
    """A table, y up, feet at y = 0: a top slab on four legs (one mesh)."""
    w, d = size
    top = trimesh.transformations.translation_matrix([0, top_height - thickness / 2, 0])
    parts = [trimesh.creation.box([w, thickness, d], transform=top)]
    for sx in (-1, 1):
        for sz in (-1, 1):
            leg_h = top_height - thickness
            parts.append(trimesh.creation.box([0.05, leg_h, 0.05], transform=trimesh.transformations.translation_matrix(
                [sx * (w / 2 - 0.05), leg_h / 2, sz * (d / 2 - 0.05)])))
    return trimesh.util.concatenate(parts)


def objects(with_poster: bool = True, top_height: float = 0.75) -> dict[str, trimesh.Trimesh]:
    """The fixture's objects in the levelled y-up frame (metres)."""
    T = trimesh.transformations.translation_matrix
    out = {"wooden_table_000": table(top_height),
           "cardboard_box_000": trimesh.creation.box([0.3, 0.2, 0.25], transform=T([0.2, top_height + 0.1, 0.05])),
           "white_plate_000": trimesh.creation.cylinder(
               0.12, 0.02, sections=48,
               transform=T([-0.3, top_height + 0.01, -0.1]) @ trimesh.transformations.rotation_matrix(np.pi / 2,
                                                                                                      [1, 0, 0]))}
    if with_poster:
        out["paper_poster_on_the_wall_000"] = trimesh.creation.box([0.6, 0.8, 0.01], transform=T([0.0, 1.6, -1.0]))
    return out


def write_scene(root: Path, scene: str, tilt_deg: tuple[float, float] = (12.0, 4.0), variant: str = "sam3d",
                with_poster: bool = True, offset=(0.0, 0.5, 0.0), open_meshes: bool = True) -> np.ndarray:
    """Write one fixture scene below ``root``; returns the tilt rotation (3, 3) applied to the levelled scene.

    Parameters
    ----------
    tilt_deg
        Pitch (about x) and roll (about z) of the camera frame, degrees.
    offset
        Frame-0 ``pos`` of every actor (REST3D's sam3d files hold such a shared offset); vertices are written
        without it, so that vertices + offset are the tilted scene.
    open_meshes
        Remove a few faces of every mesh, as real reconstructions are not watertight.
    """
    tilt = Rotation.from_euler("xz", tilt_deg, degrees=True).as_matrix()
    folder = root / "assets" / scene / variant
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    actors, tracks = [], {}
    for name, mesh in objects(with_poster).items():
        m = mesh.copy()
        if open_meshes:
            m.update_faces(np.arange(len(m.faces)) % 17 != 3)
        m.vertices = m.vertices @ tilt.T - np.asarray(offset)
        m.export(folder / "meshes" / f"{name}.glb")
        actors.append(name)
        tracks[name] = {"pos": [list(offset)], "quat": [[1.0, 0.0, 0.0, 0.0]]}
    eye, target = tilt @ np.array([0.0, 1.8, 3.0]), tilt @ np.array([0.0, 0.7, 0.0])
    sim = {"actors": actors, "n_frames": 1, "fps": 30, "tracks": tracks,
           "camera": {"position": eye.tolist(), "target": target.tolist(), "fov": 60.0}}
    (folder / "simulation.json").write_text(json.dumps(sim))
    return tilt
