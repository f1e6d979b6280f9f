"""The scene data model and its ``scene.json`` file format (docs/DESIGN.md §3).

A :class:`Scene` is a list of :class:`SceneObject` (mesh in its local frame +
pose into the world) above a horizontal ground plane; z is up, units are
metres. Paths in the file are relative to the file. Loading validates the
schema, every pose, the id set and every mesh, and names the file and field
of the first problem.
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene import schemas
from phiscene.atomic import write_json
from phiscene.errors import InputError
from phiscene.tolerances import TOL
from phiscene.transforms import decompose, rigidity_error, transform_points

FORMAT = "phiscene.scene/1"


@dataclass
class SceneObject:
    """One object of a scene.

    Attributes
    ----------
    id
        Unique name (``ground`` is reserved).
    mesh_path
        Absolute path of the mesh file, geometry in the object's local frame.
    pose : (4, 4) float
        Local-to-world similarity transform.
    description
        Free text (used by the MLLM backend and reports).
    color
        RGB colour of the object in the instance segmentation, or ``None``.
    meta
        Free-form extra data carried through unchanged.
    attached
        ``None`` for a free rigid body; otherwise the id of what holds it in place (a :class:`Plane` of
        :attr:`Scene.structure`, e.g. ``wall_0``, or ``ground``): the object is static, kept where it is (never
        dropped or settled), a collider for the others, and left out of drift averages.
    com : (3,) float or None
        Declared centre of mass in the local (unscaled) mesh frame; ``None``: that of a uniform solid
        (:func:`phiscene.inertia.rigid_props`). Grounding declares one for an object at rest in the input that
        topples as a uniform solid (a vase whose flowers outweigh its base; remedy ``ballast`` of
        :mod:`phiscene.assembly.faithful`); every simulator, metric and export uses it.
    base : (k, 3) float or None
        Vertices (local, unscaled) of one more convex piece of the object's collision shape, under it: its base
        completed flat. A reconstruction guesses the hidden bottom of an object (a jug's, a fruit's), and a
        rounded guess cannot stand where the photo shows the object at rest; grounding declares one when
        nothing else lets the object rest level (remedy ``base`` of :mod:`phiscene.assembly.faithful`). Every
        simulator and export adds it to the object's convex proxies (:func:`phiscene.proxies.with_bases`);
        the visible mesh is unchanged.
    """

    id: str
    mesh_path: Path
    pose: np.ndarray
    description: str = ""
    color: tuple[int, int, int] | None = None
    meta: dict = field(default_factory=dict)
    attached: str | None = None
    com: np.ndarray | None = None
    base: np.ndarray | None = None

    def mesh(self):
        """The local-frame mesh, loaded once per path (see :func:`phiscene.meshes.load_mesh`)."""
        from phiscene.meshes import load_mesh

        return load_mesh(self.mesh_path)

    def world_mesh(self):
        """A copy of the mesh transformed into the world frame."""
        m = self.mesh().copy()
        m.apply_transform(self.pose)
        return m

    def world_points(self, points_local: np.ndarray) -> np.ndarray:
        """Map local points (n, 3) to world points (n, 3)."""
        return transform_points(self.pose, points_local)


#: Kinds of :class:`Plane`.
PLANE_KINDS = ("wall", "ceiling")


@dataclass(frozen=True)
class Plane:
    """A static structural plane of the scene (a wall or the ceiling), a supporter like the ground.

    Attributes
    ----------
    id
        Unique name among objects and planes (``wall_0``, ``ceiling``).
    kind
        ``wall`` or ``ceiling``.
    normal : (3,) float
        Unit normal pointing into the room (away from the solid side).
    offset
        Plane offset ``d``: points ``p`` on the plane satisfy ``normal . p + d = 0``; the room is where it is > 0.
    estimated
        Estimated from the objects hanging on it (:func:`phiscene.walls.estimate_walls`), not given: those
        objects stay exactly where the input has them (the plane is where they are), they are not made flush
        with it.
    """

    id: str
    kind: str
    normal: tuple[float, float, float]
    offset: float
    estimated: bool = False

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (n,) of points (n, 3) from the plane, positive on the room side."""
        return np.asarray(points, dtype=float) @ np.asarray(self.normal, dtype=float) + self.offset

    def frame(self) -> np.ndarray:
        """A frame (4, 4) of the plane: its +z axis the normal, its origin the plane's point nearest the world
        origin (how the exports pose a wall: a ground plane or slab whose top face is the plane)."""
        from phiscene.levelling import rotation_between

        n = np.asarray(self.normal, dtype=float)
        out = np.eye(4)
        out[:3, :3] = rotation_between([0.0, 0.0, 1.0], n)
        out[:3, 3] = -float(self.offset) * n
        return out

    def to_dict(self) -> dict:
        """JSON form (``structure`` entry of ``scene.json``)."""
        out = {"id": self.id, "kind": self.kind, "normal": [float(v) for v in self.normal],
               "offset": float(self.offset)}
        if self.estimated:
            out["estimated"] = True
        return out


@dataclass
class Scene:
    """A set of objects above a ground plane.

    Attributes
    ----------
    objects
        The objects, in file order.
    ground_height
        Height (z) of the ground plane in metres.
    camera
        Absolute path of the reference camera JSON, or ``None``.
    meta
        Free-form extra data carried through unchanged.
    source
        The file the scene was loaded from (``None`` for a scene built in memory).
    structure
        Static walls and ceiling (:class:`Plane`), supporters besides the ground; empty for most scenes.
    """

    objects: list[SceneObject]
    ground_height: float = 0.0
    camera: Path | None = None
    meta: dict = field(default_factory=dict)
    source: Path | None = None
    structure: list[Plane] = field(default_factory=list)

    @property
    def ids(self) -> list[str]:
        return [o.id for o in self.objects]

    @property
    def attached_ids(self) -> list[str]:
        """Ids of the objects fixed in place (:attr:`SceneObject.attached` set), in scene order."""
        return [o.id for o in self.objects if o.attached is not None]

    @property
    def free_ids(self) -> list[str]:
        """Ids of the free rigid bodies (not attached), in scene order."""
        return [o.id for o in self.objects if o.attached is None]

    def __len__(self) -> int:
        return len(self.objects)

    def get(self, object_id: str) -> SceneObject:
        """The object named ``object_id`` (KeyError with the known ids otherwise)."""
        for o in self.objects:
            if o.id == object_id:
                return o
        raise KeyError(f"no object {object_id!r} in scene (objects: {', '.join(self.ids)})")

    def with_poses(self, poses: dict[str, np.ndarray], meta: dict | None = None) -> "Scene":
        """A copy of the scene with some poses replaced (meshes shared)."""
        out = copy.deepcopy(self)
        for o in out.objects:
            if o.id in poses:
                o.pose = np.array(poses[o.id], dtype=float)
        if meta is not None:
            out.meta = {**out.meta, **meta}
        return out


def ground_below(scene: Scene, proxies: dict | None = None) -> float:
    """Height of a ground right below the scene: the lowest world z of what the free objects collide with (m).

    The drift tests of every simulator release the scene on this ground (not ``scene.ground_height``),
    so a scene floating above, or sunk into, its own ground plane is measured from where it rests. With
    ``proxies`` (object id -> :class:`~phiscene.proxies.Proxy`) it is the lowest vertex of the free objects'
    collision proxies, the only geometry the simulators see: a mesh vertex a few millimetres outside its proxies
    (a chair leg's tip through the floor) would lower the ground under every object and drop them all by that
    much; without, the lowest vertex of their meshes. Objects :attr:`~SceneObject.attached` to a wall or the
    ceiling are static in those tests and do not set it (a floor-length curtain reconstructed 6 cm through the
    floor would drop every free object 6 cm); when every object is attached, all of them do.

    Raises
    ------
    InputError
        The scene has no objects.
    """
    if not scene.objects:
        raise InputError(scene.source, "objects", "scene has no objects")
    free = [o for o in scene.objects if o.attached is None] or scene.objects

    def points(o: SceneObject) -> np.ndarray:
        if proxies is not None and o.id in proxies and proxies[o.id].hulls:
            return np.vstack(proxies[o.id].hulls)
        return np.asarray(o.mesh().vertices)

    return float(min(transform_points(o.pose, points(o))[:, 2].min() for o in free))


def _load_base(path: Path, where: str, value) -> np.ndarray:
    """An object's ``base`` (:attr:`SceneObject.base`) as a (k, 3) array: at least 4 finite points spanning a
    volume (``InputError`` naming ``where`` otherwise)."""
    try:
        base = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(path, where, "must be a list of [x, y, z] points") from None
    if base.ndim != 2 or base.shape[1] != 3 or len(base) < 4:
        raise InputError(path, where, f"must be at least 4 [x, y, z] points, got shape {list(base.shape)}")
    if not np.isfinite(base).all():
        raise InputError(path, where, "must be finite")
    if np.linalg.matrix_rank(base - base.mean(axis=0), tol=1e-9) < 3:
        raise InputError(path, where, "points are coplanar: they span no convex piece")
    return base


def _rel(target: Path, start: Path) -> str:
    return Path(os.path.relpath(Path(target).resolve(), Path(start).resolve())).as_posix()


#: Decimals a scene file keeps of each pose, declared centre of mass and completed base (:func:`scene_to_dict`).
WRITTEN_DECIMALS = 12


def as_written(scene: Scene) -> Scene:
    """A copy of ``scene`` with its poses, declared centres of mass and completed bases rounded as a scene file
    keeps them (:data:`WRITTEN_DECIMALS`): the scene a later job reads back. A resting pose on the edge of
    stability can go either way on that rounding in a simulator, so a test meant to answer for the written scene
    runs on this one."""
    out = copy.deepcopy(scene)
    for o in out.objects:
        o.pose = _written(o.pose)
        if o.com is not None:
            o.com = _written(o.com)
        if o.base is not None:
            o.base = _written(o.base)
    return out


def _written(values) -> np.ndarray:
    """``values`` as a float array rounded to :data:`WRITTEN_DECIMALS`."""
    return np.asarray(values, dtype=float).round(WRITTEN_DECIMALS)


def scene_to_dict(scene: Scene, json_dir: Path) -> dict:
    """Serialise ``scene`` with paths relative to ``json_dir`` (numbers rounded as :func:`as_written` rounds them)."""
    objs = []
    for o in scene.objects:
        d = {"id": o.id, "description": o.description, "mesh": _rel(o.mesh_path, json_dir),
             "pose": _written(o.pose).tolist()}
        if o.color is not None:
            d["color"] = [int(c) for c in o.color]
        if o.meta:
            d["meta"] = o.meta
        if o.attached is not None:
            d["attached"] = o.attached
        if o.com is not None:
            d["com"] = [float(v) for v in _written(o.com)]
        if o.base is not None:
            d["base"] = _written(o.base).tolist()
        objs.append(d)
    out = {"format": FORMAT, "units": "m", "up": [0, 0, 1], "ground": {"height": float(scene.ground_height)},
           "objects": objs}
    if scene.camera is not None:
        out["camera"] = _rel(scene.camera, json_dir)
    if scene.structure:
        out["structure"] = [p.to_dict() for p in scene.structure]
    if scene.meta:
        out["meta"] = scene.meta
    return out


def save_scene(scene: Scene, path: str | Path) -> Path:
    """Write ``scene`` to ``path`` atomically; mesh paths are made relative to it.

    Returns
    -------
    The written path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, scene_to_dict(scene, path.parent))
    return path


def load_scene(path: str | Path, check_meshes: bool = True) -> Scene:
    """Load and validate a ``scene.json``.

    Parameters
    ----------
    path
        The scene file.
    check_meshes
        Also load every mesh and check it is usable (non-empty, finite, positive volume).

    Raises
    ------
    InputError
        Naming the file and field of the first problem: schema violations
        (an empty ``objects`` list included), unknown format version, a
        non-finite ground height, non-rigid or non-finite poses, duplicate ids,
        missing or unusable mesh files, and (with ``check_meshes``) objects
        that reach beyond ``TOL.max_coordinate`` from the origin, are larger
        than ``TOL.max_object_size`` (a scene not in metres) or lie more than
        ``TOL.max_below_ground`` below the ground; a declared centre of mass
        (``com``) that is not finite, or (with ``check_meshes``) outside the mesh's bounds.
    """
    path = Path(path)
    data = schemas.read_json(path)
    if isinstance(data, dict) and "format" not in data:
        raise InputError(path, "format", "missing; expected 'phiscene.scene/1'")
    schemas.validate(data, "scene", path)
    root = path.parent
    ground = float(data.get("ground", {}).get("height", 0.0))
    if not np.isfinite(ground):
        raise InputError(path, "ground.height", f"must be finite, got {ground}")
    seen: set[str] = set()
    objects = []
    for i, d in enumerate(data["objects"]):
        where = f"objects[{i}]"
        if d["id"] in seen:
            raise InputError(path, f"{where}.id", f"duplicate object id {d['id']!r}")
        seen.add(d["id"])
        pose = np.asarray(d["pose"], dtype=float)
        why = rigidity_error(pose)
        if why:
            raise InputError(path, f"{where}.pose", why)
        if np.abs(pose[:3, 3]).max() > TOL.max_coordinate:
            raise InputError(path, f"{where}.pose", f"translation {pose[:3, 3].tolist()} is farther than "
                             f"{TOL.max_coordinate} m from the origin (units must be metres)")
        mesh_path = (root / d["mesh"]).resolve()
        if not mesh_path.is_file():
            raise InputError(path, f"{where}.mesh", f"mesh file not found: {d['mesh']}")
        color = tuple(d["color"]) if "color" in d else None
        com = np.asarray(d["com"], dtype=float) if "com" in d else None
        if com is not None and not np.isfinite(com).all():
            raise InputError(path, f"{where}.com", f"must be finite, got {d['com']}")
        base = _load_base(path, f"{where}.base", d["base"]) if "base" in d else None
        objects.append(SceneObject(id=d["id"], mesh_path=mesh_path, pose=pose, description=d.get("description", ""),
                                   color=color, meta=d.get("meta", {}), attached=d.get("attached"), com=com,
                                   base=base))
    structure = _load_structure(path, data.get("structure", []), seen)
    holders = {"ground"} | {p.id for p in structure}
    for i, o in enumerate(objects):
        if o.attached is not None and o.attached not in holders:
            raise InputError(path, f"objects[{i}].attached", f"{o.attached!r} is neither 'ground' nor a structure "
                             f"plane (planes: {sorted(p.id for p in structure)})")
    camera = data.get("camera")
    scene = Scene(objects=objects, ground_height=ground,
                  camera=(root / camera).resolve() if camera else None, meta=data.get("meta", {}), source=path,
                  structure=structure)
    if check_meshes:
        from phiscene.meshes import load_mesh

        for i, o in enumerate(objects):
            try:
                mesh = load_mesh(o.mesh_path)
            except InputError as exc:
                raise InputError(path, f"objects[{i}].mesh", exc.problem) from None
            _check_placement(path, i, o, mesh.bounds, ground)
            pad = TOL.com_bounds_pad
            if o.com is not None and not np.all((o.com >= mesh.bounds[0] - pad) & (o.com <= mesh.bounds[1] + pad)):
                raise InputError(path, f"objects[{i}].com", f"declared centre of mass {o.com.tolist()} lies outside "
                                 f"the mesh's bounds {mesh.bounds.tolist()} (local frame): no mass distribution "
                                 "of the object has it there")
            reach = TOL.base_bounds_share * float(np.max(mesh.extents))
            if o.base is not None and not np.all((o.base >= mesh.bounds[0] - reach)
                                                 & (o.base <= mesh.bounds[1] + reach)):
                raise InputError(path, f"objects[{i}].base", f"completed base reaches beyond the mesh's bounds "
                                 f"{mesh.bounds.tolist()} (local frame) by more than {TOL.base_bounds_share:g} of "
                                 "its largest extent: it is no base of this object")
    return scene


def _load_structure(path: Path, entries: list[dict], object_ids: set[str]) -> list[Plane]:
    """Planes of the ``structure`` list: unit normals, finite offsets, ids unique among planes and objects."""
    planes, seen = [], set()
    for i, d in enumerate(entries):
        where = f"structure[{i}]"
        if d["id"] in object_ids or d["id"] in seen:
            raise InputError(path, f"{where}.id", f"id {d['id']!r} is already used by an object or a plane")
        seen.add(d["id"])
        n = np.asarray(d["normal"], dtype=float)
        length = float(np.linalg.norm(n)) if np.all(np.isfinite(n)) else float("nan")
        if not np.isfinite(length) or abs(length - 1.0) > 1e-6:
            raise InputError(path, f"{where}.normal", f"must be a finite unit vector, got {n.tolist()}")
        if not np.isfinite(d["offset"]):
            raise InputError(path, f"{where}.offset", f"must be finite, got {d['offset']}")
        planes.append(Plane(id=d["id"], kind=d["kind"], normal=tuple(float(v) for v in n), offset=float(d["offset"]),
                            estimated=bool(d.get("estimated", False))))
    return planes


def _check_placement(path: Path, index: int, obj: SceneObject, local_bounds: np.ndarray, ground: float) -> None:
    """Refuse an object whose world bounding box is implausible for a scene in metres above its ground.

    Parameters
    ----------
    local_bounds : (2, 3) float
        The mesh's local axis-aligned bounds.
    """
    import trimesh

    world = transform_points(obj.pose, trimesh.bounds.corners(local_bounds))
    # its size from its own box, whatever its rotation: an object an import accepted is not refused once grounding
    # turned it (the corners of a turned box span up to sqrt(3) times its side)
    size = float(np.max(local_bounds[1] - local_bounds[0])) * decompose(obj.pose)[2]
    check_world_bounds(path, f"objects[{index}]", world.min(axis=0), world.max(axis=0), ground, size=size)


def check_world_bounds(path: str | Path | None, where: str, lo: np.ndarray, hi: np.ndarray, ground: float,
                       hint: str = "", size: float | None = None) -> None:
    """Refuse an object whose world bounding box is implausible for a scene in metres above its ground.

    Parameters
    ----------
    path, where
        The file and the object field named in the error (``where`` empty: the file alone).
    lo, hi : (3,) float
        Corners of the object's world axis-aligned bounding box (m).
    ground
        Height of the ground (m).
    hint
        Appended to the unit messages (an importer names its option for other units).
    size
        The object's size (m; default the largest side of the box): an object placed with a rotation gives the
        largest side of its own box, which the rotation does not change.

    Raises
    ------
    InputError
        Larger than ``TOL.max_object_size``, reaching farther than ``TOL.max_coordinate`` from the origin, or
        lying more than ``TOL.max_below_ground`` below the ground.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    pose_field = f"{where}.pose" if where else None
    size = float((hi - lo).max()) if size is None else float(size)
    if size > TOL.max_object_size:
        raise InputError(path, where or None, f"object is {size:.4g} m across (more than {TOL.max_object_size} m): "
                         f"units must be metres (is the scene in millimetres?){hint}")
    reach = float(np.abs(np.concatenate([lo, hi])).max())
    if reach > TOL.max_coordinate:
        raise InputError(path, pose_field, f"object reaches {reach:.4g} m from the origin (more than "
                         f"{TOL.max_coordinate} m; units must be metres){hint}")
    if hi[2] < ground - TOL.max_below_ground:
        raise InputError(path, pose_field, f"object lies {ground - hi[2]:.4g} m below the ground (top at "
                         f"z={hi[2]:.4g} m, ground at {ground:.4g} m; at most {TOL.max_below_ground} m is accepted)")
