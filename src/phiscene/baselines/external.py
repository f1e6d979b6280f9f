"""Import another method's predicted scenes as a method row (the shared ``scene.json`` contract).

A prediction is one folder (or one GLB file) per scene, in one of three layouts:

``meshes``
    One mesh file per object, ``<object id>.<glb|obj|ply>``, in world
    coordinates, and no other mesh files. Each file is copied unchanged to
    ``meshes/`` next to the output ``scene.json`` and gets the identity pose
    (its local frame is the world frame), so the imported world mesh is
    exactly the file's mesh.
``poses``
    A ``poses.json`` mapping each object id to a 4x4 local-to-world pose
    (row-major nested lists, rotation times uniform scale plus translation)
    applied to the *initial* scene's mesh of that object.
``scene``
    One GLB/glTF scene whose node names are object ids. An object's geometry
    is every mesh on its node or on nodes below it; its pose is the node's
    world transform (``trimesh.load(..., force='scene')``, ``scene.graph``)
    and its local mesh is the geometry expressed in that node's frame,
    written to ``meshes/<id>.glb``. A node transform that is not a rotation
    times a uniform scale (shear, non-uniform scale) is baked into the
    geometry instead, with the identity pose.

``rest3d``
    A REST3D result folder (``meshes/*.glb`` + ``simulation.json``, :mod:`phiscene.io.rest3d`): object meshes
    placed by frame 0 of the simulation, REST3D's y-up frame made z-up (its own levelling kept).

``layout="auto"`` picks ``poses`` when ``poses.json`` exists, else ``rest3d`` when ``simulation.json`` and
``meshes/`` do, else
``meshes`` when a mesh file is named after an object id, else ``scene``
when the folder holds exactly one ``.glb``/``.gltf`` file (or the path is
such a file).

The output keeps the initial scene's ids, descriptions, colours, object
meta, camera, ground height and, but for a ``rest3d`` result (its own frame),
its walls and ceiling (``structure``). An object of the initial scene missing from
the prediction raises :class:`~phiscene.errors.InputError` naming the
folder and the missing ids; with ``missing="keep"`` it keeps its initial
mesh and pose instead (listed in the log). Predicted objects that are not in
the initial scene raise as well, unless ``extra="ignore"``.

Collision proxies of a ``meshes`` or ``scene`` import must be computed from
the imported ``scene.json`` (its meshes differ from the initial ones); a
``poses`` import reuses the initial meshes, hence their proxies.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phiscene.atomic import atomic_path
from phiscene.errors import InputError
from phiscene.params import Params
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.tolerances import TOL
from phiscene.transforms import rigidity_error

log = logging.getLogger(__name__)

#: Format tag of the import log.
LOG_FORMAT = "phiscene.external_import/1"
#: Suffixes of per-object mesh files (layout ``meshes``).
MESH_SUFFIXES = (".glb", ".obj", ".ply")
#: Suffixes of a scene file (layout ``scene``).
SCENE_SUFFIXES = (".glb", ".gltf")
#: File name of layout ``poses``.
POSES_FILE = "poses.json"
#: Layouts :func:`import_external` understands.
LAYOUTS = ("auto", "meshes", "poses", "scene", "rest3d")


@dataclass(frozen=True)
class ImportParams(Params):
    """Options of :func:`import_external`.

    Attributes
    ----------
    layout
        ``auto``, ``meshes``, ``poses`` or ``scene`` (see the module docstring).
    missing
        ``error``: an initial object missing from the prediction raises; ``keep``: it keeps its initial pose.
    extra
        ``error``: a predicted object that is not in the initial scene raises; ``ignore``: it is dropped
        (logged).
    """

    _label = "import parameters"

    layout: str = "auto"
    missing: str = "error"
    extra: str = "error"

    def check(self) -> None:
        """Reject an unknown ``layout``, ``missing`` or ``extra`` value (``ValueError``)."""
        if self.layout not in LAYOUTS:
            raise ValueError(f"import layout must be one of {list(LAYOUTS)}, got {self.layout!r}")
        if self.missing not in ("error", "keep") or self.extra not in ("error", "ignore"):
            raise ValueError(f"import missing must be error|keep and extra error|ignore, got {self.missing!r}, "
                             f"{self.extra!r}")


def read_rest3d_objects(folder: Path, ids: list[str]) -> tuple[dict[str, tuple], list[str]]:
    """Objects of a REST3D result folder (:mod:`phiscene.io.rest3d`) in REST3D's own frame, made z-up.

    Returns
    -------
    objects
        id -> (local mesh centred on its bounding box, pose (4, 4)) for the ids of the initial scene.
    extra
        Ids in the folder that the initial scene lacks.
    """
    from phiscene.io.rest3d import read_rest3d_dir
    from phiscene.transforms import Y_UP_TO_Z_UP

    out, extra = {}, []
    for obj in read_rest3d_dir(folder).objects:
        if obj.id not in set(ids):
            extra.append(obj.id)
            continue
        world = obj.mesh.copy()
        world.apply_transform(np.asarray(Y_UP_TO_Z_UP))
        centre = world.bounds.mean(axis=0)
        world.apply_translation(-centre)
        pose = np.eye(4)
        pose[:3, 3] = centre
        out[obj.id] = (world, pose)
    return out, extra


# -- layout detection ------------------------------------------------------------------------------------------------
def _mesh_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)


def detect_layout(pred: Path, ids: list[str]) -> str:
    """The layout of a prediction folder or file (see the module docstring).

    Raises
    ------
    InputError
        The path does not exist or matches no layout.
    """
    if pred.is_file():
        if pred.suffix.lower() in SCENE_SUFFIXES:
            return "scene"
        raise InputError(pred, None, f"a prediction file must be a GLB/glTF scene ({', '.join(SCENE_SUFFIXES)})")
    if not pred.is_dir():
        raise InputError(pred, None, "prediction folder not found")
    if (pred / POSES_FILE).is_file():
        return "poses"
    if (pred / "simulation.json").is_file() and (pred / "meshes").is_dir():
        return "rest3d"
    if any(p.stem in set(ids) for p in _mesh_files(pred)):
        return "meshes"
    scenes = sorted(p for p in pred.iterdir() if p.is_file() and p.suffix.lower() in SCENE_SUFFIXES)
    if len(scenes) == 1:
        return "scene"
    raise InputError(pred, None, f"cannot tell the prediction layout: expected {POSES_FILE}, files "
                     f"<object id>.<glb|obj|ply> or exactly one GLB scene (found {len(scenes)} GLB/glTF files)")


def _scene_file(pred: Path) -> Path:
    if pred.is_file():
        return pred
    scenes = sorted(p for p in pred.iterdir() if p.is_file() and p.suffix.lower() in SCENE_SUFFIXES)
    if len(scenes) != 1:
        raise InputError(pred, None, f"layout 'scene' needs exactly one GLB/glTF file, found {len(scenes)}")
    return scenes[0]


# -- readers: each returns {id: (mesh path or local mesh or None, pose)} for the predicted objects -------------------
def read_mesh_files(folder: Path, ids: list[str]) -> tuple[dict[str, Path], list[str]]:
    """Per-object world mesh files of layout ``meshes``.

    Returns
    -------
    files
        ``{object id: file}`` for the ids that have one.
    extra
        Stems of mesh files that name no object id.

    Raises
    ------
    InputError
        An id with several mesh files.
    """
    files: dict[str, Path] = {}
    extra = []
    for p in _mesh_files(folder):
        if p.stem not in set(ids):
            extra.append(p.stem)
        elif p.stem in files:
            raise InputError(folder, p.stem, f"several mesh files for one object: {files[p.stem].name}, {p.name}")
        else:
            files[p.stem] = p
    return files, extra


def read_poses_file(path: Path) -> dict[str, np.ndarray]:
    """``poses.json``: ``{object id: (4, 4) pose}``, each checked (rigid up to uniform scale, finite, in range).

    Raises
    ------
    InputError
        Naming the file and the offending id.
    """
    from phiscene.schemas import read_json

    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(path, None, "expected an object mapping object ids to 4x4 poses")
    poses = {}
    for oid, value in data.items():
        try:
            pose = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InputError(path, oid, "pose is not a numeric 4x4 matrix") from None
        why = rigidity_error(pose)
        if why:
            raise InputError(path, oid, why)
        if np.abs(pose[:3, 3]).max() > TOL.max_coordinate:
            raise InputError(path, oid, f"translation {pose[:3, 3].tolist()} is farther than {TOL.max_coordinate} m "
                             "from the origin (units must be metres)")
        poses[oid] = pose
    return poses


def _owner(graph, node: str, ids: set[str]) -> str | None:
    """The nearest node at or above ``node`` whose name is an object id."""
    parents = graph.transforms.parents
    while node is not None:
        if node in ids:
            return node
        node = parents.get(node)
    return None


def read_scene_file(path: Path, ids: list[str]) -> tuple[dict[str, tuple], list[str]]:
    """Objects of a GLB/glTF scene whose node names are object ids (layout ``scene``).

    Returns
    -------
    objects
        ``{object id: (local mesh, pose (4, 4))}``.
    extra
        Names of geometry nodes below no object-id node.

    Raises
    ------
    InputError
        Unreadable file, non-triangle geometry on an object node, or an object mesh without volume.
    """
    import trimesh

    from phiscene.meshes import check_mesh

    try:
        scene = trimesh.load(path, force="scene", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InputError(path, None, f"cannot read scene ({type(exc).__name__}: {str(exc)[:120]})") from None
    idset = set(ids)
    parts: dict[str, list[tuple[np.ndarray, object]]] = {}
    extra = []
    for node in scene.graph.nodes_geometry:
        transform, geom_name = scene.graph[node]
        owner = _owner(scene.graph, node, idset)
        if owner is None:
            extra.append(node)
            continue
        geom = scene.geometry[geom_name]
        if not isinstance(geom, trimesh.Trimesh):
            raise InputError(path, node, f"geometry {geom_name!r} is a {type(geom).__name__}, not a triangle mesh")
        parts.setdefault(owner, []).append((np.asarray(transform, dtype=float), geom))
    objects = {}
    for oid, pieces in parts.items():
        node_pose = np.asarray(scene.graph[oid][0], dtype=float)
        pose = node_pose if rigidity_error(node_pose) is None else np.eye(4)
        to_local = np.linalg.inv(pose)
        meshes = []
        for transform, geom in pieces:
            m = geom.copy()
            m.apply_transform(to_local @ transform)
            meshes.append(m)
        local = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)
        check_mesh(local, f"{path}#{oid}")
        objects[oid] = (local, pose)
    return objects, extra


# -- entry point -----------------------------------------------------------------------------------------------------
def _copy_file(src: Path, dst: Path) -> Path:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)
    return dst


def import_external(pred_dir: str | Path, initial_scene: Scene | str | Path, out_path: str | Path,
                    params: ImportParams = ImportParams()) -> tuple[Scene, dict]:
    """Turn another method's prediction of one scene into a ``scene.json`` method row.

    Parameters
    ----------
    pred_dir
        The prediction folder (or GLB scene file), see the module docstring for the layouts.
    initial_scene
        The initial scene (or its ``scene.json``): ids, descriptions, colours, camera, ground height and,
        for layout ``poses`` and kept objects, meshes.
    out_path
        The ``scene.json`` to write; object meshes of layouts ``meshes`` and ``scene`` go to
        ``<out_path folder>/meshes/<id>.<suffix>``.
    params
        Layout and the handling of missing and extra objects.

    Returns
    -------
    scene
        The written scene, loaded back (validated).
    record
        JSON-ready log: ``format``, ``source``, ``layout``, ``params``, ``objects`` (per id ``imported`` or
        ``kept_initial``), ``extra`` (predicted ids/nodes not in the initial scene, when ignored).

    Raises
    ------
    InputError
        Unknown layout, unreadable input, bad poses or meshes, objects missing from the prediction (naming the
        folder and the ids, unless ``missing="keep"``), or predicted objects not in the initial scene (unless
        ``extra="ignore"``).
    """
    from phiscene.meshes import load_mesh, save_mesh

    pred = Path(pred_dir)
    out_path = Path(out_path)
    initial = initial_scene if isinstance(initial_scene, Scene) else load_scene(initial_scene)
    ids = initial.ids
    layout = params.layout if params.layout != "auto" else detect_layout(pred, ids)
    mesh_dir = out_path.parent / "meshes"
    found: dict[str, tuple] = {}  # id -> (mesh file or local mesh, pose (4, 4)); meshes are written below
    if layout == "meshes":
        if not pred.is_dir():
            raise InputError(pred, None, "prediction folder not found")
        files, extra = read_mesh_files(pred, ids)
        source = pred
        for oid, f in files.items():
            load_mesh(f)  # check it is a usable mesh before adopting it
            found[oid] = (f, np.eye(4))
    elif layout == "poses":
        source = pred / POSES_FILE
        poses = read_poses_file(source)
        extra = [oid for oid in poses if oid not in set(ids)]
        for oid in ids:
            if oid in poses:
                found[oid] = (initial.get(oid).mesh_path, poses[oid])
    elif layout == "rest3d":
        source = pred / "simulation.json"
        objects, extra = read_rest3d_objects(pred, ids)
        for oid, (mesh, pose) in objects.items():
            found[oid] = (mesh, pose)
    elif layout == "scene":
        source = _scene_file(pred)
        objects, extra = read_scene_file(source, ids)
        for oid, (mesh, pose) in objects.items():
            found[oid] = (mesh, pose)  # mesh saved once the checks below have passed
    else:
        raise InputError(pred, "layout", f"unknown layout {layout!r}; known: {list(LAYOUTS[1:])}")

    missing = [oid for oid in ids if oid not in found]
    if missing and params.missing == "error":
        raise InputError(pred, None, f"prediction lacks objects of the initial scene: {missing}")
    if extra and params.extra == "error":
        raise InputError(pred, None, f"prediction has objects that are not in the initial scene: {sorted(extra)}")
    if extra:
        log.warning("%s: ignoring predicted objects not in the initial scene: %s", pred, ", ".join(sorted(extra)))
    if missing:
        log.warning("%s: objects missing from the prediction keep their initial pose: %s", pred, ", ".join(missing))

    objects_out = []
    status = {}
    for o in initial.objects:
        if o.id not in found:
            objects_out.append(o)
            status[o.id] = "kept_initial"
            continue
        mesh, pose = found[o.id]
        if layout == "meshes":
            mesh_path = _copy_file(mesh, mesh_dir / f"{o.id}{mesh.suffix.lower()}")
        elif layout in ("scene", "rest3d"):
            mesh_path = save_mesh(mesh, mesh_dir / f"{o.id}.glb")
        else:
            mesh_path = mesh
        objects_out.append(SceneObject(o.id, Path(mesh_path).resolve(), np.asarray(pose, dtype=float),
                                       o.description, o.color, dict(o.meta)))
        status[o.id] = "imported"
    record = {"format": LOG_FORMAT, "source": str(source), "layout": layout, "params": params.to_dict(),
              "objects": status, "extra": sorted(extra)}
    meta = {**initial.meta, "external": {"source": str(source), "layout": layout,
                                         "kept_initial": [k for k, v in status.items() if v == "kept_initial"]}}
    # walls and ceiling are the initial scene's in its frame; a rest3d result is in its own frame
    structure = [] if layout == "rest3d" else list(initial.structure)
    scene = Scene(objects_out, ground_height=initial.ground_height, camera=initial.camera, meta=meta,
                  structure=structure)
    save_scene(scene, out_path)
    return load_scene(out_path), record
