"""Inputs no suite holds, as other tools write them: imported and grounded with the ``phiscene`` command.

Each scene is built here from trimesh primitives in a y-up frame (glTF's), one GLB per object unless said, and run
as a user would run it: ``phiscene import-placed SRC OUT/<name>/import``, then ``phiscene ground
OUT/<name>/import/initial OUT/<name>/ground --cache-dir OUT/cache``. Printed per scene: the import's line and
grounding's closing line (displacement and rotation change from the input, attached objects, objects far from the
input). ``docs/measurements.md`` ("Inputs no suite holds") has what each did before the commits that fixed it.

Scenes:

* ``layout``: a floor slab, a wall, a table, a box on it, a poster touching the wall (the room's own meshes named
  as such: reason ``structure``);
* ``quads``: the same with the floor and the wall as single flat quads (made slabs at import);
* ``overlap``: a wall mesh reaching through the floor slab and under the ground, a table, a poster (the room's own
  meshes are kept where they are, never lifted or cleared of each other);
* ``aframe``: two 60 cm planks leaning on each other 20 deg off vertical, and a box (the support cycle's stand-in);
* ``rug``: a 6 mm rug, a coffee table on it, a sheet of paper, a plate and an orange on the table;
* ``duplicate``: a table and the same box twice in place (a duplicate detection);
* ``ceiling``: a floor and a ceiling slab, a pendant lamp hanging from it, a stool, a pair of shoes as one mesh;
* ``lean``: a mattress leaning against a wall mesh, a stool;
* ``scene_file``: one GLB holding the scene (a wrapper node, a table of five part nodes, a book, a camera node),
  imported from the file itself (one object per top-level node).

    python benchmarks/unseen_inputs.py OUT [SCENE ...]
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
from trimesh.transformations import rotation_matrix, translation_matrix

#: z-up construction -> the files' y-up frame (glTF's).
TO_Y_UP = rotation_matrix(-np.pi / 2, [1.0, 0.0, 0.0])


def _save(folder: Path, name: str, mesh: trimesh.Trimesh, at: np.ndarray | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    mesh.copy().apply_transform(np.eye(4) if at is None else at).apply_transform(TO_Y_UP).export(folder / f"{name}.glb")


def _box(extents, at) -> tuple[trimesh.Trimesh, np.ndarray]:
    return trimesh.creation.box(extents), translation_matrix(at)


def _table(width=1.2, depth=0.8, height=0.75) -> trimesh.Trimesh:
    top = trimesh.creation.box((width, depth, 0.05)).apply_translation((0.0, 0.0, height - 0.025))
    legs = [trimesh.creation.box((0.05, 0.05, height - 0.05)).apply_translation((x, y, (height - 0.05) / 2))
            for x in (-width / 2 + 0.05, width / 2 - 0.05) for y in (-depth / 2 + 0.05, depth / 2 - 0.05)]
    return trimesh.util.concatenate([top, *legs])


def _quad(corners) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.asarray(corners, dtype=float), [[0, 1, 2], [0, 2, 3]], process=False)


def layout(folder: Path, flat: bool = False) -> Path:
    if flat:
        _save(folder, "floor", _quad([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]))
        _save(folder, "white_wall", _quad([[-2, 2, 0], [2, 2, 0], [2, 2, 2.5], [-2, 2, 2.5]]))
    else:
        _save(folder, "floor", *_box((4.0, 4.0, 0.05), (0.0, 0.0, -0.025)))
        _save(folder, "white_wall", *_box((4.0, 0.05, 2.5), (0.0, 2.025, 1.25)))
    _save(folder, "wooden_table", _table(), translation_matrix((0.0, 0.5, 0.01)))
    _save(folder, "cardboard_box", *_box((0.3, 0.2, 0.1), (0.2, 0.5, 0.81)))
    _save(folder, "framed_poster", *_box((0.6, 0.02, 0.4), (-1.0, 1.99, 1.5)))
    return folder


def overlap(folder: Path) -> Path:
    _save(folder, "floor", *_box((4.0, 4.4, 0.05), (0.0, 0.2, -0.025)))
    _save(folder, "white_wall", *_box((4.0, 0.1, 2.6), (0.0, 2.05, 1.2)))  # through the floor slab, as layouts' are
    _save(folder, "wooden_table", _table(), translation_matrix((0.0, 0.5, 0.01)))
    _save(folder, "framed_poster", *_box((0.6, 0.02, 0.4), (-1.0, 1.99, 1.5)))
    return folder


def aframe(folder: Path) -> Path:
    length, thick, a = 0.6, 0.02, np.radians(20.0)
    plank = trimesh.creation.box((0.3, thick, length))
    z = length / 2 * np.cos(a) + thick / 2 * np.sin(a)
    y = length / 2 * np.sin(a) + thick / 2 * np.cos(a)
    _save(folder, "left_plank", plank, translation_matrix((0.0, -y, z)) @ rotation_matrix(-a, [1, 0, 0]))
    _save(folder, "right_plank", plank, translation_matrix((0.0, y, z)) @ rotation_matrix(a, [1, 0, 0]))
    _save(folder, "cardboard_box", *_box((0.3, 0.3, 0.3), (0.8, 0.0, 0.15)))
    return folder


def rug(folder: Path) -> Path:
    _save(folder, "grey_rug", *_box((2.0, 1.5, 0.006), (0.0, 0.0, 0.003)))
    _save(folder, "coffee_table", _table(), translation_matrix((0.0, 0.0, 0.01)))
    _save(folder, "sheet_of_paper", *_box((0.21, 0.297, 0.001), (0.2, 0.1, 0.7525)))
    _save(folder, "orange", trimesh.creation.icosphere(2, 0.04), translation_matrix((-0.3, 0.1, 0.793)))
    _save(folder, "plate", trimesh.creation.cylinder(0.12, 0.01, sections=48), translation_matrix((-0.3, -0.2, 0.757)))
    return folder


def duplicate(folder: Path) -> Path:
    _save(folder, "wooden_table", _table(), translation_matrix((0.0, 0.5, 0.01)))
    for name in ("cardboard_box", "cardboard_box_copy"):
        _save(folder, name, *_box((0.3, 0.2, 0.1), (0.2, 0.5, 0.81)))
    return folder


def ceiling(folder: Path) -> Path:
    _save(folder, "floor", *_box((4.0, 4.0, 0.05), (0.0, 0.0, -0.025)))
    _save(folder, "ceiling", *_box((4.0, 4.0, 0.05), (0.0, 0.0, 2.625)))
    shade = trimesh.creation.cone(0.2, 0.2).apply_transform(rotation_matrix(np.pi, [1, 0, 0]))
    lamp = trimesh.util.concatenate([trimesh.creation.cylinder(0.01, 0.6).apply_translation((0.0, 0.0, 0.3)), shade])
    _save(folder, "pendant_lamp", lamp, translation_matrix((0.5, 0.5, 2.0)))
    shoes = trimesh.util.concatenate([trimesh.creation.box((0.1, 0.28, 0.1)).apply_translation((-0.08, 0.0, 0.05)),
                                      trimesh.creation.box((0.1, 0.28, 0.1)).apply_translation((0.08, 0.03, 0.05))])
    _save(folder, "pair_of_shoes", shoes, translation_matrix((1.0, -1.0, 0.003)))
    _save(folder, "wooden_stool", *_box((0.45, 0.45, 0.45), (-1.0, 0.0, 0.225)))
    return folder


def lean(folder: Path) -> Path:
    _save(folder, "floor", *_box((4.0, 4.0, 0.05), (0.0, 0.0, -0.025)))
    _save(folder, "white_wall", *_box((4.0, 0.1, 2.5), (0.0, 1.55, 1.25)))
    a = np.radians(15.0)
    at = translation_matrix((0.0, 1.5 - 0.1 / np.cos(a) - 0.95 * np.sin(a) - 0.02,
                             0.95 * np.cos(a) + 0.1 * np.sin(a))) @ rotation_matrix(-a, [1, 0, 0])
    _save(folder, "mattress_leaning_against_wall", trimesh.creation.box((0.9, 0.2, 1.9)), at)
    _save(folder, "wooden_stool", *_box((0.4, 0.4, 0.45), (1.2, 0.3, 0.225)))
    return folder


def scene_file(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    s = trimesh.Scene()
    s.graph.update(frame_from=s.graph.base_frame, frame_to="Root", matrix=np.eye(4))
    s.graph.update(frame_from="Root", frame_to="wooden table", matrix=translation_matrix((0.3, 0.0, -0.2)))
    s.add_geometry(trimesh.creation.box((1.2, 0.05, 0.8)), node_name="top", geom_name="top",
                   parent_node_name="wooden table", transform=translation_matrix((0.0, 0.75, 0.0)))
    for i, (x, z) in enumerate([(-0.5, -0.3), (0.5, -0.3), (-0.5, 0.3), (0.5, 0.3)]):
        s.add_geometry(trimesh.creation.box((0.05, 0.725, 0.05)), node_name=f"leg{i}", geom_name=f"leg{i}",
                       parent_node_name="wooden table", transform=translation_matrix((x, 0.3625, z)))
    s.add_geometry(trimesh.creation.box((0.2, 0.1, 0.15)), node_name="book", geom_name="book",
                   parent_node_name="Root", transform=translation_matrix((0.4, 0.825, -0.2)))
    s.graph.update(frame_from="Root", frame_to="Camera", matrix=translation_matrix((0.0, 1.0, 3.0)))
    path = folder / "scene.glb"
    s.export(path)
    return path


SCENES = {"layout": layout, "quads": lambda f: layout(f, flat=True), "overlap": overlap, "aframe": aframe, "rug": rug,
          "duplicate": duplicate, "ceiling": ceiling, "lean": lean, "scene_file": scene_file}


def run(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "phiscene.cli", *args], capture_output=True, text=True)


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    out = Path(argv[0])
    names = argv[1:] or list(SCENES)
    unknown = sorted(set(names) - set(SCENES))
    if unknown:
        print(f"unknown scenes {unknown}; known: {list(SCENES)}")
        return 2
    for name in names:
        t0 = time.perf_counter()
        source = SCENES[name](out / name / "source")
        imp = run(["import-placed", str(source), str(out / name / "import")])
        print(f"{name}: {imp.stdout.strip() or imp.stderr.strip()}")
        if imp.returncode:
            continue
        ground = run(["ground", str(out / name / "import" / "initial"), str(out / name / "ground"), "--cache-dir",
                      str(out / "cache")])
        lines = [ln.strip() for ln in ground.stdout.splitlines() if ln.strip().startswith(("result:", "far from"))]
        print("\n".join(f"  {ln}" for ln in lines) or f"  failed: {ground.stderr.strip()[-500:]}")
        print(f"  {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
