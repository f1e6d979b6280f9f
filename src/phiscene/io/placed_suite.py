"""A folder of placed-mesh scenes as a workflow suite (``suites.<suite>.source`` with ``kind: placed``).

Most image-to-3D pipelines other than SAM 3D Objects write one mesh file per object with every vertex already in a
common scene frame (:mod:`phiscene.io.placed`). A folder of such scenes is a suite::

    <root>/<scene>/<object>.glb|.gltf|.ply|.obj   one mesh per object, the file stem naming it (with ``objects:
                                                  nodes``: glTF/GLB files whose top-level nodes are the objects)
    <root>/<scene>/placements.json                optional: per-object placements (phiscene.io.placed's format)
    <root>/<scene>/camera.json                    optional: the photo's camera, source frame and units:
                                                  {"eye": [x, y, z], "target": [x, y, z], "fov_y_deg": 50}

Each scene is imported as ``phiscene import-placed`` imports one folder (:func:`phiscene.io.placed.import_placed`:
levelled, its walls estimated; ``params`` takes the up convention, units, levelling and walls), with the camera
when the scene gives one.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from phiscene.errors import InputError
from phiscene.io import OBJECT_MODES, finite_numbers
from phiscene.io.placed import MESH_SUFFIXES, Camera, PlacedParams, import_placed, read_placed_dir
from phiscene.io.source import SourceParams
from phiscene.scene import Scene

#: The optional files of a scene folder.
PLACEMENTS_FILE = "placements.json"
CAMERA_FILE = "camera.json"
#: Scene folder names the workflow takes (its ``scene`` wildcard).
SCENE_NAME = re.compile(r"^[A-Za-z0-9_]+$")


@dataclass(frozen=True)
class PlacedSource(SourceParams):
    """A suite of placed-mesh scenes (module docstring layout).

    Attributes
    ----------
    root
        The folder of scenes, relative to the working directory.
    kind
        ``placed``.
    params
        Import settings (:class:`~phiscene.io.placed.PlacedParams`: up convention, units, levelling, walls).
    objects
        How a scene folder's files are read (:data:`~phiscene.io.OBJECT_MODES`): ``files``, one object per
        mesh file; ``nodes``, each glTF/GLB file's top-level nodes (:func:`~phiscene.io.placed.read_scene_file`:
        a scene exported as one file).
    """

    _label = "placed-mesh source"

    kind: str = "placed"
    params: PlacedParams = field(default_factory=PlacedParams)
    objects: str = "files"

    def check(self) -> None:
        """Reject another kind (:class:`~phiscene.io.source.SourceParams`) or an unknown ``objects``
        (``ValueError``)."""
        super().check()
        if self.objects not in OBJECT_MODES:
            raise ValueError(f"{self._label} objects must be one of {list(OBJECT_MODES)}, got {self.objects!r}")


def scene_ids(root: str | Path) -> list[str]:
    """The scenes under ``root``: its sub-folders holding at least one mesh file, sorted.

    Raises
    ------
    InputError
        ``root`` is not a folder, holds no scene, or a scene folder's name is not ``[A-Za-z0-9_]+``.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, None, "folder of placed-mesh scenes not found")
    found = sorted(p for p in root.iterdir() if p.is_dir() and any(f.suffix.lower() in MESH_SUFFIXES
                                                                      for f in p.iterdir()))
    if not found:
        raise InputError(root, None, f"no scenes (<scene>/<object>{'|'.join(MESH_SUFFIXES)}) in the folder")
    for p in found:
        if not SCENE_NAME.match(p.name):
            raise InputError(p, None, "a scene folder's name may hold only letters, digits and '_': rename it")
    return [p.name for p in found]


def read_camera(path: str | Path) -> Camera:
    """The camera of a scene folder's ``camera.json`` (module docstring format).

    Raises
    ------
    InputError
        Unreadable JSON, a missing key, or a value of the wrong shape, naming the file and the key.
    """
    from phiscene.schemas import read_json

    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(path, None, 'expected {"eye": [x, y, z], "target": [x, y, z], "fov_y_deg": f}')
    eye, target = (finite_numbers(data, path, key, 3) for key in ("eye", "target"))
    if isinstance(data.get("fov_y_deg"), list):  # one number, not a list of one
        raise InputError(path, "fov_y_deg", f"expected a number, got {data['fov_y_deg']!r}")
    return Camera(eye, target, float(finite_numbers(data, path, "fov_y_deg", 1)[0]))


def run_placed_scene(source: dict, scene: str, out_dir: str | Path) -> Scene:
    """Workflow stage: one scene of a ``placed`` source as ``OUT_DIR/initial/scene.json`` (+ ``reference/``,
    ``import.json``)."""
    src = PlacedSource.from_dict(source)
    folder = Path(src.root) / scene
    placements = folder / PLACEMENTS_FILE
    objects = read_placed_dir(folder, placements if placements.is_file() else None, src.objects)
    camera = read_camera(folder / CAMERA_FILE) if (folder / CAMERA_FILE).is_file() else None
    return import_placed(objects, out_dir, src.params, camera,
                         source={"kind": "placed", "root": src.root, "scene": scene})
