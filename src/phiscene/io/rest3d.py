"""The REST3D project's page assets: raw SAM 3D Objects scenes and REST3D's stabilised results.

Layout (a ``git clone --branch gh-pages https://github.com/ShirleyMaxx/REST3D``; CC BY-NC 4.0, never committed
here)::

    ROOT/assets/<scene>/<variant>/meshes/<actor>.glb      one object per file, y-up, metres, scene frame
    ROOT/assets/<scene>/<variant>/simulation.json         {"actors": [...], "camera": {"position", "target", "fov"},
                                                           "tracks": {actor: {"pos": [[x, y, z], ...],
                                                                              "quat": [[w, x, y, z], ...]}}}

``variant`` ``sam3d`` is the raw SAM 3D Objects output (its frame follows the camera: gravity is not levelled);
``ours`` is REST3D's physically stabilised result on the same meshes, in its own levelled y-up frame; ``dc``,
``gen3dsr`` and ``sg`` are the results of Digital Cousins, Gen3DSR and SceneGen on the same photos
(:data:`BASELINES`), in the same layout. Frame 0 of each track places the actor: ``world = R(quat) v + pos``.

:func:`import_rest3d` imports one variant through :func:`phiscene.io.placed.import_placed` (``sam3d`` and the
other methods': levelled by our estimate; ``ours``: y-up convention only, REST3D's own frame).
:func:`reference_levelling` is REST3D's levelling of a scene as the issue defines it: the Kabsch rotation between
the object centres of ``sam3d/`` and ``ours/`` (itself an estimate: REST3D also moves objects when it places them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.errors import InputError
from phiscene.io.placed import (
    Camera,
    PlacedObject,
    PlacedParams,
    description_of,
    import_placed,
    object_id,
    placement_matrix,
    read_mesh,
)
from phiscene.io.source import SourceParams
from phiscene.scene import Scene

#: The variants of a REST3D scene folder that the ``real`` suites pair: raw SAM 3D Objects and REST3D's result.
VARIANTS = ("sam3d", "ours")
#: The page's results of the other methods REST3D compares with, on the same photos (not every scene has each):
#: reconstructions that are not SAM 3D Objects' (other meshes, other errors), to import and ground as inputs.
BASELINES = {"dc": "Digital Cousins", "gen3dsr": "Gen3DSR", "sg": "SceneGen"}
#: Every variant this module reads.
ALL_VARIANTS = (*VARIANTS, *BASELINES)
#: How a user gets the data (printed when it is missing).
GET_DATA = "git clone --branch gh-pages https://github.com/ShirleyMaxx/REST3D <root>"


@dataclass(frozen=True)
class Rest3dSource(SourceParams):
    """A REST3D source (``config.yaml`` ``suites.<suite>.source`` with ``kind: rest3d``).

    Attributes
    ----------
    root
        The REST3D checkout (``git clone --branch gh-pages ...``), relative to the working directory.
    kind
        ``rest3d``.
    variant
        Which result is the suite's initial scene: ``sam3d`` (raw SAM 3D Objects, levelled here), ``ours``, or
        another method's reconstruction (:data:`BASELINES`, levelled here).
    placed
        Import settings (:class:`phiscene.io.placed.PlacedParams`: up convention, levelling, image size).
    """

    _label = "REST3D source"

    kind: str = "rest3d"
    variant: str = "sam3d"
    placed: PlacedParams = field(default_factory=PlacedParams)

    def check(self) -> None:
        """Reject another kind or an unknown variant (``ValueError``)."""
        super().check()
        if self.variant not in ALL_VARIANTS:
            raise ValueError(f"REST3D variant must be one of {ALL_VARIANTS}, got {self.variant!r}")


def scene_dir(root: str | Path, scene: str, variant: str) -> Path:
    """``ROOT/assets/<scene>/<variant>``; :class:`InputError` naming the missing path and how to get it."""
    root = Path(root)
    if not (root / "assets").is_dir():
        raise InputError(root, None, f"REST3D data not found (no assets/ folder); get it with `{GET_DATA}`")
    folder = root / "assets" / scene / variant
    if not (folder / "simulation.json").is_file():
        raise InputError(folder / "simulation.json", None, f"REST3D scene {scene!r} has no {variant} result")
    return folder


@dataclass
class Rest3dScene:
    """One variant of one REST3D scene, in its source frame (y up).

    Attributes
    ----------
    objects
        Objects with their frame-0 placement applied to the vertices.
    camera
        The page's camera.
    """

    objects: list[PlacedObject]
    camera: Camera | None


def read_rest3d(root: str | Path, scene: str, variant: str = "sam3d") -> Rest3dScene:
    """Read one variant of one REST3D scene (module docstring)."""
    return read_rest3d_dir(scene_dir(root, scene, variant))


def read_rest3d_dir(folder: str | Path) -> Rest3dScene:
    """Read one REST3D result folder (``meshes/*.glb`` + ``simulation.json``), frame-0 placements applied."""
    from phiscene.schemas import read_json

    folder = Path(folder)
    sim_path = folder / "simulation.json"
    if not sim_path.is_file():
        raise InputError(sim_path, None, "REST3D simulation.json not found")
    sim = read_json(sim_path)
    if not isinstance(sim, dict) or not isinstance(sim.get("actors"), list) or not isinstance(sim.get("tracks"), dict):
        raise InputError(sim_path, None, "expected {'actors': [...], 'tracks': {...}}")
    if not sim["actors"]:
        raise InputError(sim_path, "actors", "no actors")
    objects = []
    for actor in sim["actors"]:
        mesh_path = folder / "meshes" / f"{actor}.glb"
        if not mesh_path.is_file():
            raise InputError(mesh_path, None, f"mesh of actor {actor!r} not found")
        track = sim["tracks"].get(actor)
        if not isinstance(track, dict) or not track.get("pos") or not track.get("quat"):
            raise InputError(sim_path, f"tracks.{actor}", "needs non-empty 'pos' and 'quat' lists")
        mesh = read_mesh(mesh_path)
        entry = {"pos": track["pos"][0], "quat": track["quat"][0]}
        mesh.apply_transform(placement_matrix(entry, sim_path, f"tracks.{actor}"))
        objects.append(PlacedObject(object_id(actor), mesh, description_of(actor), mesh_path))
    camera = None
    cam = sim.get("camera")
    if isinstance(cam, dict) and {"position", "target", "fov"} <= set(cam):
        camera = Camera(np.asarray(cam["position"], float), np.asarray(cam["target"], float), float(cam["fov"]))
    return Rest3dScene(objects, camera)


def import_rest3d(root: str | Path, scene: str, out_dir: str | Path, variant: str = "sam3d",
                  params: PlacedParams | None = None) -> Scene:
    """Import one REST3D scene variant as ``OUT_DIR/initial/scene.json`` (+ ``reference/camera.json``).

    ``sam3d`` and the other methods' reconstructions (:data:`BASELINES`) are levelled by our estimate
    (``params.level``); ``ours`` keeps REST3D's frame (y-up only).
    """
    data = read_rest3d(root, scene, variant)
    params = params or PlacedParams()
    if variant == "ours":
        params = PlacedParams(**{**params.to_dict(), "level": False})
    source = {"kind": "rest3d", "root": str(root), "scene": scene, "variant": variant}
    return import_placed(data.objects, out_dir, params, data.camera, source)


def reference_levelling(root: str | Path, scene: str) -> np.ndarray:
    """REST3D's levelling rotation (3, 3) of a scene, source (``sam3d``) frame -> ``ours`` frame (both y up).

    The Kabsch rotation between the centres (area-weighted surface centroids, which move rigidly with the object)
    of the objects both variants share.
    """
    from scipy.spatial.transform import Rotation

    a = {o.id: surface_centroid(o.mesh) for o in read_rest3d(root, scene, "sam3d").objects}
    b = {o.id: surface_centroid(o.mesh) for o in read_rest3d(root, scene, "ours").objects}
    ids = sorted(set(a) & set(b))
    if len(ids) < 3:
        raise InputError(Path(root) / "assets" / scene, None, "fewer than 3 objects shared by sam3d/ and ours/")
    A = np.array([a[i] for i in ids])
    B = np.array([b[i] for i in ids])
    rot, _ = Rotation.align_vectors(B - B.mean(axis=0), A - A.mean(axis=0))
    return rot.as_matrix()


def surface_centroid(mesh) -> np.ndarray:
    """Area-weighted centroid (3,) of a mesh's surface (defined for open meshes; moves rigidly with the mesh)."""
    w = mesh.area_faces
    return (mesh.triangles_center * w[:, None]).sum(axis=0) / w.sum()


def reference_up(root: str | Path, scene: str) -> np.ndarray:
    """REST3D's up direction (3,) in the ``sam3d`` source frame (``ours``' +y mapped back)."""
    return reference_levelling(root, scene).T @ np.array([0.0, 1.0, 0.0])


def run_rest3d_scene(source: dict, scene: str, out_dir: str | Path) -> Scene:
    """Workflow stage: one scene of a ``rest3d`` source as ``OUT_DIR/initial/scene.json`` (+ ``reference/``)."""
    src = Rest3dSource.from_dict(source)
    return import_rest3d(src.root, scene, out_dir, src.variant, src.placed)


def scene_ids(root: str | Path, variant: str = "sam3d") -> list[str]:
    """Scenes of a REST3D checkout that have both a ``sam3d`` and an ``ours`` result (``variant`` ``sam3d`` or
    ``ours``), or a result of ``variant``, another method's (:data:`BASELINES`)."""
    assets = Path(root) / "assets"
    if not assets.is_dir():
        raise InputError(root, None, f"REST3D data not found (no assets/ folder); get it with `{GET_DATA}`")
    needed = VARIANTS if variant in VARIANTS else (variant,)
    return sorted(p.name for p in assets.iterdir()
                  if all((p / v / "simulation.json").is_file() for v in needed))
