"""Scenes made of per-object meshes already placed in one frame -> a levelled ``initial/scene.json``.

This is what most 3D foundation-model pipelines write: one mesh file per object (GLB, PLY or OBJ), every
vertex already in the common scene frame (or placed by an optional per-object transform), a known up-axis
convention (glTF files are y-up) and a camera whose pitch leaves gravity off by a few to 20 degrees.

:func:`read_placed_dir` reads such a folder; :func:`import_placed` levels the scene with
:func:`phiscene.levelling.estimate_up` (the camera's up as the prior) and writes the benchmark layout, so every
stage downstream runs unchanged::

    OUT_DIR/initial/scene.json, OUT_DIR/initial/meshes/<id>.glb   object meshes, local frame centred on the box
    OUT_DIR/reference/camera.json                                  when a camera is known
    OUT_DIR/import.json                                            source, up convention, the levelling applied

Once levelled, the walls are estimated from the panels hanging on them (:func:`phiscene.walls.estimate_walls`:
posters, paintings, windows) and written as the scene's ``structure``; ``import.json`` and the scene's ``meta``
record their evidence and the groups given up.

Placement file (``--placements``, optional): ``{"<id>": {"pos": [x, y, z], "quat": [w, x, y, z]}}`` or
``{"<id>": 4x4}``, in the source frame, applied to the mesh's vertices (the REST3D ``simulation.json`` layout
is read by :mod:`phiscene.io.rest3d`).
"""

from __future__ import annotations

import json
import logging
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from phiscene.atomic import write_json
from phiscene.errors import InputError
from phiscene.io import OBJECT_MODES, UP_AXES, check_unit_scale
from phiscene.levelling import LevelParams, UpEstimate, angle_deg, estimate_up, levelling_transform, rotation_between
from phiscene.params import Params
from phiscene.scene import Scene, SceneObject, check_world_bounds, load_scene, save_scene
from phiscene.transforms import Y_UP_TO_Z_UP, make_pose, quat_wxyz_to_matrix, rigidity_error
from phiscene.walls import WallParams, estimate_walls

log = logging.getLogger(__name__)

#: Format tag of ``import.json``.
IMPORT_FORMAT = "phiscene.placed_import/1"
#: What a refused import suggests for a scene in other units than metres.
UNIT_HINT = "; pass the metres per source unit (--unit-scale 0.001 for millimetres, 0.01 for centimetres)"
#: The median object of a scene larger than this across (bounding-box diagonal, m) gets a warning: a scene's objects
#: are cups, chairs and beds (2.5 m), and a reconstruction written in decimetres or centimetres passes the bounds
#: checks with 4 m chairs (a REST3D ``dc`` result), which then settle as slowly as towers and clear a table top only
#: by metres. Smaller than the lower bound (1 cm): a scene in kilometres or normalised to a unit box.
PLAUSIBLE_MEDIAN_DIAGONAL = (0.01, 3.0)
#: Thickness (m) given to a flat mesh of the room itself (a floor or wall quad: :func:`solid_structure`), behind its
#: face; what stands on it or hangs on it touches the face, so only the simulators' margin sees the thickness.
STRUCTURE_THICKNESS = 0.05
#: Mesh file suffixes read as objects.
MESH_SUFFIXES = (".glb", ".gltf", ".ply", ".obj")
#: Files whose nodes can be the objects (:func:`read_scene_file`): a glTF scene names and places its nodes; a PLY
#: holds one mesh, and an OBJ's groups are read merged.
SCENE_SUFFIXES = (".glb", ".gltf")
#: A levelling that turns the scene farther than this (deg) from the given up axis gets a warning: the camera tilts of
#: the 9 real SAM 3D Objects scenes measure 2.5 to 29 deg (``benchmarks/levelling.py``), while files whose up axis is
#: not the one given (``--up z`` on y-up files) level onto whatever lies within reach of it (``max_tilt_deg``, and
#: :data:`phiscene.levelling.STEEP_PRIOR_DEG` more when few votes agree).
LARGE_TILT_DEG = 33.0


@dataclass(frozen=True)
class PlacedParams(Params):
    """Settings of a placed-mesh import.

    Attributes
    ----------
    up
        Up-axis convention of the source files (:data:`UP_AXES`): ``y`` (glTF, SAM 3D Objects' GLBs), ``z``, or
        another axis, signed (``-y``: OpenCV's camera frame).
    unit_scale
        Metres per source unit: multiplies every vertex, placement translation and camera position (1 for metric
        output such as SAM 3D Objects'; 0.001 for millimetres, 0.01 for centimetres). A scene whose levelled
        objects are implausible in metres (an object more than ``TOL.max_object_size`` across, or reaching
        farther than ``TOL.max_coordinate`` from the origin; a scene lying that far away in its own frame is first
        centred, :func:`~phiscene.levelling.levelling_transform`) is refused before anything is written.
    level
        Estimate gravity and level the scene (false: trust the up convention).
    levelling
        See :class:`phiscene.levelling.LevelParams`.
    image_width, image_height
        Size of the reference camera's image when the source gives only a field of view.
    walls
        The walls estimated from the panels hanging on them, once levelled (:class:`phiscene.walls.WallParams`).
    """

    _label = "import parameters"

    up: str = "y"
    unit_scale: float = 1.0
    level: bool = True
    levelling: LevelParams = field(default_factory=LevelParams)
    image_width: int = 640
    image_height: int = 480
    walls: WallParams = field(default_factory=WallParams)

    def check(self) -> None:
        """Reject an unknown up axis or image size (``ValueError``)."""
        if self.up not in UP_AXES:
            raise ValueError(f"import parameter 'up' must be one of {list(UP_AXES)}, got {self.up!r}")
        check_unit_scale(self.unit_scale)
        if self.image_width < 1 or self.image_height < 1:
            raise ValueError("import parameters 'image_width' and 'image_height' must be >= 1")


@dataclass
class PlacedObject:
    """One object of a placed-mesh scene.

    Attributes
    ----------
    id
        Object id (file stem, or node name, sanitised).
    mesh
        The mesh with its vertices in the source frame.
    description
        Free text (from the file stem or node name unless given).
    source
        The file it came from.
    node
        The node of a scene file it is (:func:`read_scene_file`); ``None`` for a file per object.
    """

    id: str
    mesh: trimesh.Trimesh
    description: str
    source: Path
    node: str | None = None

    @property
    def origin(self) -> str:
        """Where the object came from: its file's name, ``file:node`` for a node of a scene file."""
        return self.source.name if self.node is None else f"{self.source.name}:{self.node}"


@dataclass(frozen=True)
class Camera:
    """A reference camera in the source frame.

    Attributes
    ----------
    eye, target : (3,) float
        Camera centre and a point it looks at.
    fov_y_deg
        Vertical field of view.
    """

    eye: np.ndarray
    target: np.ndarray
    fov_y_deg: float


def object_id(stem: str) -> str:
    """A scene-safe object id from a file stem (characters outside ``[A-Za-z0-9_.-]`` become ``_``)."""
    oid = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)
    return "obj_" + oid if oid == "ground" else oid


def description_of(stem: str) -> str:
    """Free text from a file stem: ``wooden_table_000`` -> ``wooden table``."""
    words = [w for w in re.split(r"[_\s]+", stem) if w]
    if words and words[-1].isdigit():
        words = words[:-1]
    return " ".join(words) or stem


def read_mesh(path: Path) -> trimesh.Trimesh:
    """One mesh file as one mesh (scene graphs flattened), checked for finite vertices and faces."""
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InputError(path, None, f"cannot read mesh ({type(exc).__name__}: {str(exc)[:120]})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        points = _point_count(path)
        raise InputError(path, None, "no triangles in the file" + (
            f": a point cloud of {points} points (a Gaussian splat?); give the object's mesh (SAM 3D Objects "
            "writes it as a GLB)" if points else ""))
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(path, None, "vertices contain NaN or inf")
    return mesh


def _point_count(path: Path) -> int:
    """The points of a file read as a point cloud (0 when it is none): what a mesh file without triangles holds."""
    try:
        cloud = trimesh.load(path, process=False)
    except Exception:  # read once already; only the message depends on this
        return 0
    return len(cloud.vertices) if isinstance(cloud, trimesh.PointCloud) else 0


def placement_matrix(entry, where: Path, key: str) -> np.ndarray:
    """A placement entry (``{"pos", "quat" (w, x, y, z)}`` or a 4x4) as a rigid (4, 4) matrix."""
    if isinstance(entry, dict):
        try:
            T = np.eye(4)
            T[:3, :3] = quat_wxyz_to_matrix(np.asarray(entry["quat"], dtype=float))
            T[:3, 3] = np.asarray(entry["pos"], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(where, key, f"expected {{'pos': [3], 'quat': [w, x, y, z]}} ({exc})") from None
    else:
        T = np.asarray(entry, dtype=float)
        if T.shape != (4, 4):
            raise InputError(where, key, f"expected a 4x4 matrix, got shape {T.shape}")
    why = rigidity_error(T)
    if why:
        raise InputError(where, key, why)
    return T


def _where_the_meshes_are(folder: Path) -> str:
    """A hint for a folder without mesh files: the SAM 3D Objects run it holds (``<id>/pose.json``), or the one
    sub-folder that holds the meshes (a REST3D scene's ``sam3d/meshes``); empty when there is neither."""
    subs = [d for d in sorted(folder.iterdir()) if d.is_dir()]
    if any((d / "pose.json").is_file() for d in subs):
        return "; its sub-folders hold a SAM 3D Objects run (<object id>/pose.json): `phiscene import-sam3d` reads it"
    meshes = [d for d in subs if any(p.suffix.lower() in MESH_SUFFIXES for p in d.iterdir())]
    return f"; its sub-folder {meshes[0].name}/ has them: pass {meshes[0]}" if len(meshes) == 1 else ""


def read_placed_dir(folder: str | Path, placements: str | Path | dict | None = None,
                    objects: str = "files") -> list[PlacedObject]:
    """The objects of a folder of mesh files placed in one frame.

    Parameters
    ----------
    folder
        Holds one mesh file per object (:data:`MESH_SUFFIXES`), the file stem naming the object; with ``objects``
        ``nodes``, glTF/GLB scene files whose top-level nodes are the objects (:func:`read_scene_file`).
    placements
        Optional placement file or mapping (module docstring) applied to each object's vertices, keyed by object
        id (file stem or node name).
    objects
        ``files`` (one object per file) or ``nodes`` (:data:`OBJECT_MODES`).

    Raises
    ------
    InputError
        Missing folder, no mesh files, unreadable meshes, duplicate ids, bad or unknown placements; with
        ``nodes``, a PLY or OBJ file (no nodes to read).
    """
    folder = Path(folder)
    if objects not in OBJECT_MODES:
        raise ValueError(f"objects must be one of {OBJECT_MODES}, got {objects!r}")
    if not folder.is_dir():
        raise InputError(folder, None, "folder not found")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise InputError(folder, None, f"no mesh files ({', '.join(MESH_SUFFIXES)}) in the folder"
                         + _where_the_meshes_are(folder))
    if objects == "nodes":
        found = [o for f in files for o in _node_objects(f)]
    else:
        found = [PlacedObject(object_id(f.stem), read_mesh(f), description_of(f.stem), f) for f in files]
        if len(files) == 1 and files[0].suffix.lower() in SCENE_SUFFIXES:
            nodes = [n for n, parts in scene_nodes(files[0]).items() if parts]
            if len(nodes) > 1:
                log.warning("%s holds %d top-level nodes (%s): imported as one object; with --objects nodes "
                            "(`objects: nodes` in a suite's source) each node is an object", files[0], len(nodes),
                            ", ".join(nodes[:4]) + (", ..." if len(nodes) > 4 else ""))
    return _placed(found, folder, placements)


def read_scene_file(path: str | Path, placements: str | Path | dict | None = None) -> list[PlacedObject]:
    """The objects of one glTF/GLB scene file: each top-level node (:func:`scene_nodes`) is an object, its
    sub-nodes' meshes in the file's frame merged, named by the node.

    Parameters
    ----------
    path
        The scene file (:data:`SCENE_SUFFIXES`).
    placements
        As :func:`read_placed_dir`'s, keyed by node name or object id.

    Raises
    ------
    InputError
        Missing or unreadable file, not glTF/GLB, no node with triangles, two nodes with one id, bad or unknown
        placements.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "file not found")
    return _placed(_node_objects(path), path, placements)


def scene_nodes(path: Path) -> dict[str, list[tuple[np.ndarray, trimesh.Trimesh]]]:
    """The top-level nodes of a glTF/GLB file, each with its meshes (world (4, 4) transform, mesh in the node's
    frame), sorted by node name.

    The top level is the children of the scene's root, below any chain of single nodes without meshes (an
    exporter's ``Scene`` or ``RootNode`` wrapper); a mesh on that last wrapper is an object of its own. Geometry
    other than triangles (points, lines) is left out; a node under which none is left keeps an empty list.

    Raises
    ------
    InputError
        Not a glTF/GLB file, or unreadable.
    """
    if path.suffix.lower() not in SCENE_SUFFIXES:
        raise InputError(path, None, f"its nodes cannot be read as objects: a scene file is glTF or GLB "
                         f"({', '.join(SCENE_SUFFIXES)}); give a folder with one {path.suffix} file per object")
    try:
        scene = trimesh.load_scene(path, process=False, skip_materials=True)  # geometry only, as load_mesh
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InputError(path, None, f"cannot read scene ({type(exc).__name__}: {str(exc)[:120]})") from None
    graph = scene.graph
    children = graph.transforms.children

    def meshes_under(node: str, own_only: bool = False) -> list[tuple[np.ndarray, trimesh.Trimesh]]:
        out, stack = [], [node]
        while stack:
            n = stack.pop()
            T, name = graph[n]
            geometry = scene.geometry.get(name) if name is not None else None
            if isinstance(geometry, trimesh.Trimesh) and len(geometry.faces):
                out.append((np.asarray(T, dtype=float), geometry))
            if not own_only:
                stack.extend(children.get(n, []))
        return out

    top = graph.base_frame
    while len(children.get(top, [])) == 1 and not meshes_under(top, own_only=True):
        top = children[top][0]
    nodes = {n: meshes_under(n) for n in sorted(children.get(top, []))}
    if top != graph.base_frame and meshes_under(top, own_only=True):
        nodes[top] = meshes_under(top, own_only=True)
    return dict(sorted(nodes.items()))


def _node_objects(path: Path) -> list[PlacedObject]:
    """:func:`scene_nodes` of one file as objects, each node's meshes merged in the file's frame; nodes without
    triangles (an exporter's camera, lights, empties, point sets) are left out, with a warning naming them."""
    out, empty = [], []
    for node, parts in scene_nodes(path).items():
        if not parts:
            empty.append(node)
            continue
        meshes = [m.copy().apply_transform(T) for T, m in parts]
        mesh = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)
        mesh = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), process=False)
        if not np.all(np.isfinite(mesh.vertices)):
            raise InputError(path, None, f"node {node!r}: vertices contain NaN or inf")
        out.append(PlacedObject(object_id(node), mesh, description_of(node), path, node))
    if not out:
        raise InputError(path, None, "no nodes with triangles in the file")
    if empty:
        log.warning("%s: %d top-level nodes without triangles left out (%s)", path, len(empty), ", ".join(empty))
    return out


def _placed(objects: list[PlacedObject], where: Path, placements: str | Path | dict | None) -> list[PlacedObject]:
    """``objects`` with their placements applied (module docstring; keyed by file stem, node name or object id),
    checked for ids used twice (:func:`unique_ids`) and for placements of objects that are not there."""
    if isinstance(placements, (str, Path)):
        where = Path(placements)
        try:
            placements = json.loads(where.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(where, None, f"cannot read placements ({exc})") from None
    placements = placements or {}
    if not isinstance(placements, dict):
        raise InputError(where, None, f"expected a mapping of object ids (file stems) to placements, got a "
                         f"{type(placements).__name__}")
    unique_ids(objects)
    names = set()
    for o in objects:
        name = o.node if o.node is not None else o.source.stem
        names.add(name)
        if name in placements or o.id in placements:
            key = name if name in placements else o.id
            o.mesh.apply_transform(placement_matrix(placements[key], where, key))
    unknown = sorted(set(placements) - names - {o.id for o in objects})
    if unknown:
        raise InputError(where, None, f"placements for objects without a mesh: {unknown}")
    return objects


def source_to_z_up(up: str) -> np.ndarray:
    """Rotation (3, 3) from a source convention (:data:`UP_AXES`: the axis that points up) to phiscene's z-up axes:
    glTF's ``y`` as :data:`~phiscene.transforms.Y_UP_TO_Z_UP`, ``z`` unchanged, any other the least rotation taking
    that axis to +z (``-y``: OpenCV's camera frame, y down, z forward, becomes x, z forward -> +y)."""
    if up == "y":
        return np.asarray(Y_UP_TO_Z_UP, dtype=float)[:3, :3]
    if up == "z":
        return np.eye(3)
    axis = np.zeros(3)
    axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    return rotation_between(axis, [0.0, 0.0, 1.0])


@dataclass
class Levelling:
    """How a placed scene was levelled.

    Attributes
    ----------
    transform : (4, 4) float
        Source frame -> levelled world frame (rigid).
    estimate
        The up estimate (``None`` when levelling was off).
    """

    transform: np.ndarray
    estimate: UpEstimate | None

    @property
    def rotation_deg(self) -> float:
        """Angle of the levelling rotation after the up-axis convention change (the tilt corrected)."""
        return 0.0 if self.estimate is None else float(self.estimate.tilt_deg)


def level_objects(objects: list[PlacedObject], params: PlacedParams, camera: Camera | None = None) -> Levelling:
    """The levelling transform of placed objects: convention to z-up, estimated up to +z, the ground at z = 0."""
    A = source_to_z_up(params.up)
    meshes = {o.id: o.mesh.copy().apply_transform(make_pose(A)) for o in objects}
    estimate = estimate_up(meshes, [0.0, 0.0, 1.0], params.levelling) if params.level else None
    up = estimate.up if estimate is not None else np.array([0.0, 0.0, 1.0])
    if estimate is not None and estimate.tilt_deg > LARGE_TILT_DEG:
        log.warning("levelled by %.1f deg from the given up axis %r, more than a camera at eye level tilts a real "
                    "scene (up to about 30 deg): a camera looking steeply down, or files whose up axis is another one "
                    "(then give it: --up)", estimate.tilt_deg, params.up)
    forward = None if camera is None else A @ (np.asarray(camera.target, float) - np.asarray(camera.eye, float))
    parts = [np.asarray(m.vertices) for m in meshes.values()]
    T = levelling_transform(parts, up, forward, params.levelling.floor_band,
                             params.levelling.floor_rest_deg) @ make_pose(A)
    return Levelling(T, estimate)


def import_placed(objects: list[PlacedObject], out_dir: str | Path, params: PlacedParams = PlacedParams(),
                  camera: Camera | None = None, source: dict | None = None,
                  transform: np.ndarray | None = None) -> Scene:
    """Write a placed scene, levelled, as ``OUT_DIR/initial/scene.json`` (+ ``reference/camera.json``, ``import.json``).

    Parameters
    ----------
    objects
        The objects, vertices in the source frame (source units: ``params.unit_scale`` makes them metres).
    out_dir
        Output folder.
    camera
        The reference camera in the source frame, if known.
    source
        Free-form description of the source for ``import.json``.
    transform : (4, 4) float, optional
        A given source -> world transform instead of the estimated levelling (applied after ``unit_scale``).

    Raises
    ------
    InputError
        Naming the source file and the problem, and nothing is written (what ``OUT_DIR`` held stays as it was):
        no objects, two objects with one id, a camera whose eye is its target or whose field of view is not in
        (0, 180) degrees, a mesh with no volume in metres, an object implausible in metres once levelled
        (:func:`phiscene.scene.check_world_bounds`), ``OUT_DIR`` an existing file. The scene is written into a
        staging folder beside ``OUT_DIR`` and moved into place once it loads back whole
        (:func:`phiscene.atomic.staged_folder`).

    Returns
    -------
    The written scene, loaded back (validated).
    """
    from phiscene.atomic import staged_folder

    out_dir = Path(out_dir)
    objects, camera = in_metres(objects, camera, params.unit_scale)
    objects = solid_structure(objects)
    check_placed(objects, camera, out_dir)
    with staged_folder(out_dir) as stage:
        _write_placed(objects, stage, params, camera, source, transform)
    # its meshes were loaded and checked in the staging folder; the move changed no byte of them
    scene = load_scene(out_dir / "initial" / "scene.json", check_meshes=False)
    log.info("%s: %d objects, levelled by %.2f deg, %d walls estimated", out_dir, len(scene),
             scene.meta["levelling"]["rotation_deg"], len(scene.structure))
    return scene


def solid_structure(objects: list[PlacedObject], thickness: float = STRUCTURE_THICKNESS) -> list[PlacedObject]:
    """The objects, each flat mesh of the room itself (a floor or wall quad: a description naming one,
    :func:`~phiscene.topology.words.names_structure`, and every vertex on one plane) made a slab ``thickness`` (m)
    thick behind its face: the convex hull of its vertices and of their copies moved along the plane's normal, away
    from the other objects' centre (down for a floor alone). Every other object is returned as it is (a flat mesh
    of anything else is refused by :func:`check_placed`)."""
    from phiscene.meshes import hull_volume
    from phiscene.tolerances import TOL
    from phiscene.topology.words import names_structure

    out = []
    for k, o in enumerate(objects):
        v = np.asarray(o.mesh.vertices, dtype=float)
        if not names_structure(o.description) or len(v) < 3:
            out.append(o)
            continue
        centre = v.mean(axis=0)
        _, sv, vt = np.linalg.svd(v - centre, full_matrices=False)
        if hull_volume(o.mesh) >= TOL.min_volume or sv[1] <= 1e-9:  # a solid (kept), or a line (refused later)
            out.append(o)
            continue
        normal = vt[-1]
        others = [np.asarray(q.mesh.vertices, dtype=float).mean(axis=0) for j, q in enumerate(objects) if j != k]
        towards = np.mean(others, axis=0) - centre if others else np.array([0.0, 0.0, 1.0])
        if normal @ towards > 0:
            normal = -normal
        slab = trimesh.convex.convex_hull(np.vstack([v, v + thickness * normal]))
        log.info("%s is flat (%s): made a slab %.3g m thick behind its face", o.origin, o.description, thickness)
        out.append(PlacedObject(o.id, slab, o.description, o.source, o.node))
    return out


def unique_ids(objects: list[PlacedObject]) -> None:
    """Raise :class:`InputError` naming the second of two objects with one id and where the first came from
    (:attr:`PlacedObject.origin`)."""
    seen: dict[str, PlacedObject] = {}
    for o in objects:
        if o.id in seen:
            raise InputError(o.source, None, f"object id {o.id!r} is also the id of {seen[o.id].origin} (ids keep "
                             "only [A-Za-z0-9_.-] of a name: rename one of them)")
        seen[o.id] = o


def check_placed(objects: list[PlacedObject], camera: Camera | None, out_dir: Path) -> None:
    """The checks of :func:`import_placed` that need no levelling, on objects and camera in metres (``InputError``
    naming the file and the problem); a warning for a scene whose median object is implausibly large or small in
    metres (:data:`PLAUSIBLE_MEDIAN_DIAGONAL`; the room's own meshes, a floor or a wall, left out of the median)."""
    from phiscene.meshes import check_mesh
    from phiscene.topology.words import names_structure

    if not objects:
        raise InputError(out_dir, None, "no objects to import")
    unique_ids(objects)
    for o in objects:
        check_mesh(o.mesh, o.source)
    # the room's own meshes (a floor, a wall) are metres across in any scene
    sized = [o for o in objects if not names_structure(o.description)] or objects
    median = float(np.median([np.linalg.norm(o.mesh.extents) for o in sized]))
    low, high = PLAUSIBLE_MEDIAN_DIAGONAL
    if not low <= median <= high:
        log.warning("%s: its median object is %.3g m across (%d objects, from %s): are the meshes in metres%s",
                    out_dir, median, len(objects), objects[0].source.parent, UNIT_HINT)
    if camera is not None:
        eye, target = np.asarray(camera.eye, dtype=float), np.asarray(camera.target, dtype=float)
        if not (np.all(np.isfinite(eye)) and np.all(np.isfinite(target)) and np.linalg.norm(target - eye) > 0):
            raise InputError(None, "camera", f"the camera's eye {eye.tolist()} and target {target.tolist()} must be "
                             "finite and apart")
        if not 0.0 < float(camera.fov_y_deg) < 180.0:
            raise InputError(None, "camera", f"field of view {camera.fov_y_deg} deg is not in (0, 180)")


def _write_placed(objects: list[PlacedObject], out_dir: Path, params: PlacedParams, camera: Camera | None,
                  source: dict | None, transform: np.ndarray | None) -> Scene:
    """:func:`import_placed`'s writing, into ``out_dir`` (its staging folder), of objects and camera in metres."""
    from phiscene.meshes import save_mesh
    from phiscene.render import look_at_camera

    out_dir = Path(out_dir)
    if transform is None:
        levelling = level_objects(objects, params, camera)
    else:
        levelling = Levelling(np.asarray(transform, dtype=float), None)
    T = levelling.transform
    init_dir = out_dir / "initial"
    worlds = []
    for o in objects:  # every object checked before anything is written: a refused import leaves no output
        world = o.mesh.copy()
        world.apply_transform(T)
        check_world_bounds(o.source, "", *world.bounds, 0.0, hint=UNIT_HINT)
        worlds.append(world)
    scene_objects = []
    for o, world in zip(objects, worlds):
        centre = world.bounds.mean(axis=0)
        local = world.copy()
        local.apply_translation(-centre)
        mesh_path = save_mesh(local, init_dir / "meshes" / f"{o.id}.glb")
        pose = np.eye(4)
        pose[:3, 3] = centre
        meta = {"source_file": o.source.name} if o.node is None else {"source_file": o.source.name,
                                                                          "source_node": o.node}
        scene_objects.append(SceneObject(o.id, mesh_path.resolve(), pose, o.description, None, meta))
    camera_path = None
    if camera is not None:
        eye = T[:3, :3] @ np.asarray(camera.eye, dtype=float) + T[:3, 3]
        target = T[:3, :3] @ np.asarray(camera.target, dtype=float) + T[:3, 3]
        cam = look_at_camera(eye, target, params.image_width, params.image_height, camera.fov_y_deg, 0.02, 100.0)
        camera_path = out_dir / "reference" / "camera.json"
        write_json(camera_path, cam)
    up_record = levelling.estimate.to_dict() if levelling.estimate is not None else None
    walls = estimate_walls(Scene(scene_objects, ground_height=0.0), params.walls,
                           None if camera is None else T[:3, :3] @ np.asarray(camera.eye, dtype=float) + T[:3, 3])
    meta = {"source": source or {}, "levelling": {"rotation_deg": levelling.rotation_deg,
                                                  "transform": np.round(T, 12).tolist()},
            "walls": walls.record}
    save_scene(Scene(scene_objects, ground_height=0.0, camera=camera_path, meta=meta, structure=walls.planes),
               init_dir / "scene.json")
    write_json(out_dir / "import.json", {
        "format": IMPORT_FORMAT, "source": source or {}, "params": asdict(params),
        "transform": np.round(T, 12).tolist(), "levelling_rotation_deg": levelling.rotation_deg,
        "up_estimate": up_record, "walls": walls.record, "objects": {o.id: o.origin for o in objects}})
    return load_scene(init_dir / "scene.json")  # loads back whole (meshes checked) before it is moved into place


def in_metres(objects: list[PlacedObject], camera: Camera | None,
              unit_scale: float) -> tuple[list[PlacedObject], Camera | None]:
    """The objects (copies of their meshes) and the camera with every coordinate multiplied by ``unit_scale``."""
    if unit_scale == 1.0:
        return objects, camera
    scaled = [PlacedObject(o.id, o.mesh.copy().apply_scale(unit_scale), o.description, o.source, o.node)
              for o in objects]
    if camera is not None:
        camera = Camera(np.asarray(camera.eye, dtype=float) * unit_scale,
                        np.asarray(camera.target, dtype=float) * unit_scale, camera.fov_y_deg)
    return scaled, camera


def tilt_between(T_a: np.ndarray, T_b: np.ndarray) -> float:
    """Angle (degrees) between the up directions two levelling transforms (4, 4) assume, in the source frame."""
    up_a = np.linalg.inv(T_a[:3, :3]) @ [0.0, 0.0, 1.0]
    up_b = np.linalg.inv(T_b[:3, :3]) @ [0.0, 0.0, 1.0]
    return angle_deg(up_a, up_b)
