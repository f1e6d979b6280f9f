"""3D-FRONT rooms in MIDI-3D's test layout -> the benchmark layout of one scene (``gt/``, ``initial/``, ``reference/``).

What a user downloads: the processed 3D-FRONT release of MIDI-3D (Hugging Face dataset
``huanngzh/3D-Front``), arranged as its dataset card says::

    ROOT/
      3D-FRONT-RENDER/<house>/<room>/render_0000.webp   the view MIDI evaluates (suffix: image_suffix)
      3D-FRONT-RENDER/<house>/<room>/semantic_0000.png  id map: pixel value k = k-th object of the room (0: none)
      3D-FRONT-SURFACE/<house>/<room>/<object>.npy      GT surface samples: dict with "surface_points" (N, 3)
      3D-FRONT-SCENE/<house>/<room>/<object>.glb        GT meshes (optional; preferred by gt: auto)
      midi_room_ids.json                                list of "<house>/<room>"
      midi_furniture_ids.json                           per room, its object names in id-map order

The test set is the last ``test_rooms`` (1000) rooms of ``midi_room_ids.json`` (MIDI-3D's split, which the
paper follows). Per room (paper §4.2.1):

* objects whose id-map mask covers at most ``min_mask_fraction`` (0.1 %) of the image, and objects whose
  label (the object name up to its first ``_``, e.g. ``Lighting_<uuid>_1``) is in ``drop_labels``
  (``Lighting``), are dropped;
* the support topology is ground -> object edges only (``gt/topology.json``);
* object ``k`` of the id map gets id ``obj_{k:02d}`` (so predictions name objects by their mask value);
  its name, label and mask fraction go to the object's ``meta.front3d``.

GT geometry: the object's GLB when ``gt`` is ``mesh`` (or ``auto`` and the GLB exists), else its surface
points as a *splat mesh* (:func:`points_mesh`: a tiny regular tetrahedron of edge ``splat_size`` on every
point), so that surface sampling for the reconstruction metrics draws from the GT points (up to
``splat_size``). The normalised scene frame is rotated so that its ``up`` axis (y in MIDI's glTF-derived
data) becomes +z; the ground height is the lowest GT point. Meshes keep world coordinates with the
identity pose.

Initial scene: ``initial`` (a path pattern with ``{scene}``, ``{house}``, ``{room}``) names a SAM 3D
Objects output folder per room (:mod:`phiscene.io.sam3d`, object folders named ``obj_XX``), imported and
restricted to the kept ids; without it the initial scene is a copy of the GT (only useful to exercise the
pipeline). Other methods' predictions are imported as method rows by ``kind: external``
(:mod:`phiscene.baselines.external`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from phiscene.atomic import write_json
from phiscene.errors import InputError
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.transforms import Y_UP_TO_Z_UP, transform_points

log = logging.getLogger(__name__)

FORMAT = "phiscene.front3d_import/1"


@dataclass(frozen=True)
class Front3dParams:
    """A 3D-FRONT source (``config.yaml`` ``suites.<suite>.source``, ``kind: front3d``).

    Attributes
    ----------
    root
        The folder holding MIDI-3D's 3D-FRONT release (module docstring).
    kind
        Always ``front3d``.
    rooms_file, objects_file
        Room list and per-room object lists (relative to ``root``).
    render_dir, surface_dir, scene_dir
        Sub-folders of renders + id maps, GT surface points and GT meshes.
    view, image_suffix
        The evaluated view (``render_<view>.<suffix>``, ``semantic_<view>.png``).
    test_rooms
        The test set is the last this many rooms of the room list (0: all rooms).
    max_rooms
        Keep only the first this many test rooms (0: all); for trial runs.
    min_mask_fraction
        Objects covering at most this fraction of the image are dropped.
    drop_labels
        Object labels that are dropped.
    gt
        ``auto`` (GLB when present, else points), ``mesh`` or ``points``.
    up
        Axis of the normalised scene frame that points up: ``y`` or ``z``.
    splat_size
        Edge (m) of the tetrahedron put on each GT surface point.
    initial
        Path pattern of per-room SAM 3D Objects outputs (``{scene}``, ``{house}``, ``{room}``), or ``None``.
    """

    root: str
    kind: str = "front3d"
    rooms_file: str = "midi_room_ids.json"
    objects_file: str = "midi_furniture_ids.json"
    render_dir: str = "3D-FRONT-RENDER"
    surface_dir: str = "3D-FRONT-SURFACE"
    scene_dir: str = "3D-FRONT-SCENE"
    view: str = "0000"
    image_suffix: str = "webp"
    test_rooms: int = 1000
    max_rooms: int = 0
    min_mask_fraction: float = 0.001
    drop_labels: tuple = ("Lighting",)
    gt: str = "auto"
    up: str = "y"
    splat_size: float = 0.002
    initial: str | None = None

    @classmethod
    def from_dict(cls, d: dict) -> "Front3dParams":
        """Build from a config mapping; unknown keys or values raise ``ValueError``."""
        d = dict(d or {})
        known = [f.name for f in fields(cls)]
        unknown = sorted(set(d) - set(known))
        if unknown:
            raise ValueError(f"unknown front3d source keys {unknown}; known: {known}")
        if "root" not in d:
            raise ValueError("a front3d source needs 'root' (the folder of MIDI-3D's 3D-FRONT release)")
        if "drop_labels" in d:
            d["drop_labels"] = tuple(d["drop_labels"])
        p = cls(**d)
        if p.kind != "front3d" or p.gt not in ("auto", "mesh", "points") or p.up not in ("y", "z"):
            raise ValueError(f"front3d source: kind must be front3d, gt auto|mesh|points, up y|z; got {p.kind!r}, "
                             f"{p.gt!r}, {p.up!r}")
        return p


def scene_id(room: str) -> str:
    """A workflow scene id (``[A-Za-z0-9_]+``) for a room path ``<house>/<room>``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", room.strip("/"))


def select_rooms(params: Front3dParams) -> list[tuple[int, str]]:
    """``(index in the room list, room path)`` of the test rooms (the last ``test_rooms``, capped by ``max_rooms``).

    Raises
    ------
    InputError
        A missing or malformed room list, or two rooms with the same scene id.
    """
    from phiscene.schemas import read_json

    path = Path(params.root) / params.rooms_file
    rooms = read_json(path)
    if not isinstance(rooms, list) or not all(isinstance(r, str) for r in rooms):
        raise InputError(path, None, "expected a JSON list of '<house>/<room>' strings")
    start = max(0, len(rooms) - params.test_rooms) if params.test_rooms else 0
    chosen = list(enumerate(rooms))[start:]
    if params.max_rooms:
        chosen = chosen[:params.max_rooms]
    ids = [scene_id(r) for _, r in chosen]
    if len(set(ids)) != len(ids):
        raise InputError(path, None, "two test rooms map to the same scene id")
    return chosen


def scene_ids(source: dict) -> list[str]:
    """Workflow scene ids of a ``front3d`` source mapping (read at DAG-build time)."""
    return [scene_id(r) for _, r in select_rooms(Front3dParams.from_dict(source))]


def points_mesh(points: np.ndarray, size: float):
    """A mesh whose surface is a tiny regular tetrahedron (edge ``size``) centred on every point.

    Parameters
    ----------
    points : (n, 3) float
    size : float
        Tetrahedron edge (m).

    Returns
    -------
    trimesh.Trimesh with 4 n vertices and 4 n faces.
    """
    import trimesh

    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float) * size / (2 * np.sqrt(2))
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    pts = np.asarray(points, dtype=float)
    verts = (pts[:, None, :] + tet[None]).reshape(-1, 3)
    allf = (faces[None] + 4 * np.arange(len(pts))[:, None, None]).reshape(-1, 3)
    return trimesh.Trimesh(verts, allf, process=False)


def read_points(path: Path) -> np.ndarray:
    """GT surface points (n, 3) of a ``.npy``: MIDI's pickled dict (``surface_points``) or a plain (n, 3+) array."""
    if not path.is_file():
        raise InputError(path, None, "GT surface file not found")
    try:
        data = np.load(path, allow_pickle=True)
    except Exception as exc:  # numpy raises several types for corrupt files
        raise InputError(path, None, f"cannot read ({type(exc).__name__})") from None
    if data.dtype == object and data.shape == ():
        data = data.item()
        if not isinstance(data, dict) or "surface_points" not in data:
            raise InputError(path, "surface_points", "missing")
        data = np.asarray(data["surface_points"], dtype=float)
    data = np.asarray(data, dtype=float)
    if data.ndim != 2 or data.shape[1] < 3 or len(data) < 4 or not np.all(np.isfinite(data[:, :3])):
        raise InputError(path, "surface_points", f"expected (n, 3) finite points, got shape {data.shape}")
    return data[:, :3]


@dataclass
class RoomObject:
    """One object of a room: its id-map value ``index``, name, label, mask fraction and whether it is kept."""

    index: int
    name: str
    label: str
    mask_fraction: float
    kept: bool
    why: str = ""

    @property
    def id(self) -> str:
        return f"obj_{self.index:02d}"


def room_objects(params: Front3dParams, list_index: int, room: str) -> tuple[list[RoomObject], np.ndarray, Path]:
    """The objects of a room with the paper's filters applied, its id map (H, W) and its render path."""
    from PIL import Image

    from phiscene.schemas import read_json

    root = Path(params.root)
    objects_path = root / params.objects_file
    lists = read_json(objects_path)
    if not isinstance(lists, list) or list_index >= len(lists) or not isinstance(lists[list_index], list):
        raise InputError(objects_path, f"[{list_index}]", f"no object list for room {room!r}")
    render_dir = root / params.render_dir / room
    image = render_dir / f"render_{params.view}.{params.image_suffix}"
    idmap_path = render_dir / f"semantic_{params.view}.png"
    for p in (image, idmap_path):
        if not p.is_file():
            raise InputError(p, None, "file not found")
    with Image.open(idmap_path) as im:
        idmap = np.asarray(im)
    if idmap.ndim == 3:
        idmap = idmap[:, :, 0]
    counts = np.bincount(idmap.reshape(-1).astype(np.int64), minlength=len(lists[list_index]) + 1)
    out = []
    for k, name in enumerate(lists[list_index], start=1):
        label = str(name).split("_", 1)[0]
        frac = float(counts[k]) / idmap.size
        why = ("label " + label) if label in params.drop_labels else (
            f"mask {frac:.5f} of the image" if frac <= params.min_mask_fraction else "")
        out.append(RoomObject(k, str(name), label, frac, not why, why))
    return out, idmap, image


def _gt_mesh(params: Front3dParams, room: str, name: str):
    from phiscene.meshes import load_mesh

    glb = Path(params.root) / params.scene_dir / room / f"{name}.glb"
    if params.gt == "mesh" or (params.gt == "auto" and glb.is_file()):
        mesh = load_mesh(glb).copy()
    else:
        mesh = points_mesh(read_points(Path(params.root) / params.surface_dir / room / f"{name}.npy"),
                           params.splat_size)
    if params.up == "y":
        mesh.vertices = transform_points(Y_UP_TO_Z_UP, mesh.vertices)
    return mesh


def import_front3d_room(params: Front3dParams, scene: str, out_dir: str | Path) -> dict:
    """Write one test room as ``out_dir/{gt,initial,reference}`` (module docstring).

    Parameters
    ----------
    params
        The source.
    scene
        The room's workflow scene id (:func:`scene_id`).
    out_dir
        The scene folder (``results/scenes/{suite}/{scene}``).

    Returns
    -------
    The import record (also written to ``out_dir/front3d.json``).

    Raises
    ------
    InputError
        Unknown scene id, missing files, an id map without kept objects, or an initial scene lacking kept objects.
    """
    from phiscene.meshes import save_mesh
    from phiscene.render import save_png, segmentation_colors

    out_dir = Path(out_dir)
    rooms = {scene_id(r): (i, r) for i, r in select_rooms(params)}
    if scene not in rooms:
        raise InputError(Path(params.root) / params.rooms_file, None, f"no test room with scene id {scene!r}")
    list_index, room = rooms[scene]
    objects, idmap, image = room_objects(params, list_index, room)
    kept = [o for o in objects if o.kept]
    if not kept:
        raise InputError(image, None, "no object of the room survives the filters (mask size, labels)")
    colors = segmentation_colors(len(objects))
    meshes = {o.id: _gt_mesh(params, room, o.name) for o in kept}
    ground = float(min(np.asarray(m.vertices)[:, 2].min() for m in meshes.values()))
    gt_objects = []
    for o in kept:
        path = save_mesh(meshes[o.id], out_dir / "gt" / "meshes" / f"{o.id}.glb")
        gt_objects.append(SceneObject(o.id, path.resolve(), np.eye(4), o.label.lower(), tuple(colors[o.index - 1]),
                                      {"front3d": {"name": o.name, "label": o.label,
                                                   "mask_fraction": round(o.mask_fraction, 6)}}))
    meta = {"source": {"kind": "front3d", "room": room, "view": params.view}}
    gt = Scene(gt_objects, ground_height=ground, meta={**meta, "state": "gt"})
    save_scene(gt, out_dir / "gt" / "scene.json")
    write_json(out_dir / "gt" / "topology.json", {
        "format": "phiscene.topology/1", "backend": "gt", "objects": ["ground", *gt.ids],
        "edges": [{"from": "ground", "to": oid, "relation": "supports", "confidence": 1.0,
                   "reason": "3D-FRONT protocol: ground -> object edges only"} for oid in gt.ids],
        "order": [], "dropped_edges": []})

    if params.initial:
        from phiscene.io.sam3d import import_sam3d

        house, _, room_name = room.partition("/")
        src = Path(params.initial.format(scene=scene, house=house, room=room_name))
        imported = import_sam3d(src, out_dir)
        missing = [oid for oid in gt.ids if oid not in imported.ids]
        if missing:
            raise InputError(src, None, f"SAM 3D Objects output lacks kept objects {missing}")
        extra = [oid for oid in imported.ids if oid not in gt.ids]
        if extra:
            log.warning("%s: ignoring objects dropped from the GT: %s", src, ", ".join(extra))
        by_id = {o.id: o for o in imported.objects}
        init_objects = []
        for g in gt.objects:
            o = by_id[g.id]
            init_objects.append(SceneObject(g.id, o.mesh_path, o.pose, g.description, g.color,
                                            {**o.meta, **g.meta}))
        initial = Scene(init_objects, ground_height=0.0, meta={**meta, **imported.meta, "state": "initial"})
    else:
        initial = Scene([SceneObject(o.id, o.mesh_path, o.pose, o.description, o.color, dict(o.meta))
                         for o in gt.objects], ground_height=ground, meta={**meta, "state": "initial (GT copy)"})
    save_scene(initial, out_dir / "initial" / "scene.json")

    ref = out_dir / "reference"
    if ref.is_dir():
        for stale in ("camera.json",):  # a SAM 3D camera does not describe the 3D-FRONT render
            (ref / stale).unlink(missing_ok=True)
    rgb = _read_rgb(image)
    if rgb.shape[:2] != idmap.shape:
        raise InputError(image, None, f"render size {rgb.shape[1::-1]} differs from the id map's {idmap.shape[::-1]}")
    save_png(rgb, ref / "image.png")
    seg = np.zeros((*idmap.shape, 3), dtype=np.uint8)
    for o in kept:
        seg[idmap == o.index] = colors[o.index - 1]
    save_png(seg, ref / "segmentation.png")
    record = {"format": FORMAT, "room": room, "scene": scene, "params": {**asdict(params),
                                                                         "drop_labels": list(params.drop_labels)},
              "objects": [{"id": o.id, "name": o.name, "label": o.label, "mask_fraction": o.mask_fraction,
                           "kept": o.kept, "dropped_because": o.why} for o in objects],
              "ground_height": ground}
    write_json(out_dir / "front3d.json", record)
    log.info("%s: kept %d of %d objects", room, len(kept), len(objects))
    return record


def _read_rgb(path: Path) -> np.ndarray:
    """An image as (H, W, 3) uint8; transparent pixels composited on white (MIDI's background)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            im = im.convert("RGBA")
            arr = np.asarray(im).astype(float)
    except Exception as exc:  # PIL raises several types
        raise InputError(path, None, f"cannot read image ({type(exc).__name__})") from None
    a = arr[:, :, 3:4] / 255.0
    return np.round(arr[:, :, :3] * a + 255.0 * (1 - a)).astype(np.uint8)


def run_front3d_scene(source: dict, scene: str, out_dir: str | Path) -> None:
    """File-level entry for the workflow: import one room of a ``front3d`` suite into ``out_dir``."""
    import_front3d_room(Front3dParams.from_dict(source), scene, out_dir)
    load_scene(Path(out_dir) / "gt" / "scene.json")  # validates what was written
