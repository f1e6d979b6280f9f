"""SAM 3D Objects importer: per-object meshes and camera-frame poses -> a gravity-aligned, z-up, metric scene.

Input folder (one SAM 3D Objects run on one image, one sub-folder per object mask)::

    IN_DIR/
      image.png            optional: the reference image
      segmentation.png     optional: instance segmentation (object colours in pose.json "color")
      camera.json          optional: pinhole intrinsics {"fx", "fy", "cx", "cy", "width", "height"} in pixels
                           (or "normalized": true with fx, cx in image widths and fy, cy in image heights)
      floor.json           optional: {"normal": [nx, ny, nz], "offset": d} in the camera frame
      <object id>/
        mesh.ply | mesh.obj    variant "mesh": the object in its local frame, z up, inside [-0.5, 0.5]^3
        mesh.glb               variant "glb": the same mesh rotated z-up -> y-up (exactly one mesh file)
        pose.json              {"rotation": [w, x, y, z], "translation": [x, y, z], "scale": s | [s, s, s],
                                "description": "...", "color": [r, g, b]}   (description, color optional)
        mask.png               optional: the object's binary mask (composed into segmentation.png)

Conventions (SAM 3D Objects, PyTorch3D):

* The camera frame is PyTorch3D's: +X left, +Y up, +Z forward (into the image).
* Poses use row vectors: ``p_cam = (s * p_local) R + t`` with ``R = quaternion_to_matrix(w, x, y, z)``
  (the usual rotation matrix of the quaternion). In the column-vector form phiscene uses
  (:mod:`phiscene.transforms`), the rotation block is therefore ``s * R.T``, not ``s * R``
  (:func:`sam3d_pose`).
* The GLB variant stores ``v_glb = v_local A`` (row vectors) with ``A = [[1,0,0],[0,0,-1],[0,1,0]]``,
  which sends local +z to glTF's +y; the importer undoes it with ``v_local = v_glb A^T``.

World frame of the output (:func:`world_from_camera`): the floor plane ``n . p + d = 0`` (camera frame,
``n`` unit and pointing to the side the objects are on) becomes ``z = 0`` with +z = ``n`` (gravity -z);
+x is the camera's right (-X) projected onto the floor; +y = z × x is the horizontal viewing direction;
the origin is the camera centre's foot on the floor (the camera sits at ``(0, 0, height)``). Units are
those of the poses (SAM 3D Objects' are metric when its point map is; ``Sam3dParams.unit_scale``
rescales otherwise).

Floor without ``floor.json`` / ``--floor`` (:func:`levelled_floor`): the camera frame is tilted by the camera's
pitch and roll, and nothing in a photo is labelled "floor" (a table-top photo shows none). Gravity is estimated as
for every placed scene (:func:`phiscene.levelling.estimate_up`, the camera's +Y as the prior: table tops, seats and
the canonical frames of furniture vote), and the ground is where the objects standing on it stand
(:func:`phiscene.levelling.floor_height`: the median of their resting bottoms, not the lowest vertex of the
scene, which belongs to the object sunk deepest by a depth error). The plane through that height, normal to the
estimated up, is the floor. (This importer's earlier estimate, the lowest facet of the convex hull of all objects
that the most objects touch, was 74 to 82 degrees off REST3D's levelling on three of the nine SAM 3D scenes of the
REST3D page assets, where the levelling is within 6.3 degrees on eight of nine; README "SAM 3D Objects".)

Once in the world frame, the walls are estimated from the panels hanging on them (:func:`phiscene.walls.estimate_walls`,
as for :mod:`phiscene.io.placed`) and written as the scene's ``structure``, unless the scene gives none to hang.

Output folder (the benchmark layout, so every downstream stage runs unchanged)::

    OUT_DIR/initial/scene.json, OUT_DIR/initial/meshes/<id>.glb      (mesh in the object's local frame)
    OUT_DIR/reference/image.png, segmentation.png, camera.json         (when given / derivable)
    OUT_DIR/import.json                                               floor, world_from_camera, variants,
                                                                      up estimate, walls' evidence
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from phiscene.atomic import atomic_path, write_json
from phiscene.errors import InputError
from phiscene.io import check_unit_scale, finite_numbers
from phiscene.io.source import SourceParams
from phiscene.levelling import LevelParams, UpEstimate
from phiscene.params import Params
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.transforms import (
    Y_UP_TO_Z_UP,
    Z_UP_TO_Y_UP,
    decompose,
    invert,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    transform_points,
)
from phiscene.walls import WallParams

log = logging.getLogger(__name__)

#: PyTorch3D camera (+X left, +Y up, +Z forward) -> OpenCV camera (x right, y down, z forward).
CV_FROM_P3D = np.diag([-1.0, -1.0, 1.0, 1.0])
#: Mesh file names of the two variants.
MESH_FILES = {"mesh.ply": "mesh", "mesh.obj": "mesh", "mesh.glb": "glb"}
IMPORT_FORMAT = "phiscene.sam3d_import/1"


@dataclass(frozen=True)
class Sam3dParams(Params):
    """Options of :func:`import_sam3d`.

    Attributes
    ----------
    unit_scale
        Multiplies every translation and scale (1 for metric SAM 3D Objects output).
    levelling
        The up estimate and ground height of a scene without a given floor (:class:`phiscene.levelling.LevelParams`).
    walls
        The walls estimated from the panels hanging on them (:class:`phiscene.walls.WallParams`).
    """

    _label = "SAM 3D import parameters"

    unit_scale: float = 1.0
    levelling: LevelParams = field(default_factory=LevelParams)
    walls: WallParams = field(default_factory=WallParams)

    def check(self) -> None:
        """Reject a non-positive or non-finite ``unit_scale`` (``ValueError``)."""
        check_unit_scale(self.unit_scale)


@dataclass(frozen=True)
class Floor:
    """A plane ``normal . p + offset = 0`` in the camera frame; ``normal`` is a unit vector."""

    normal: np.ndarray
    offset: float

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (n,) of points (n, 3) to the plane, positive on the normal's side."""
        return np.asarray(points, dtype=float) @ self.normal + self.offset

    def to_dict(self) -> dict:
        return {"normal": [float(v) for v in self.normal], "offset": float(self.offset)}


def make_floor(normal, offset: float, where: str | Path | None = None) -> Floor:
    """A :class:`Floor` from any non-zero normal (normalised, offset scaled with it).

    Raises
    ------
    InputError
        A normal that is not 3 finite numbers or is zero.
    """
    n = np.asarray(normal, dtype=float).reshape(-1)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or not np.isfinite(offset):
        raise InputError(where, "floor", f"expected a normal of 3 finite numbers and a finite offset, got {normal!r}, "
                         f"{offset!r}")
    length = float(np.linalg.norm(n))
    if length < 1e-12:
        raise InputError(where, "floor.normal", "normal is zero")
    return Floor(n / length, float(offset) / length)


# -- poses -----------------------------------------------------------------------------------------------------------
def sam3d_pose(rotation_wxyz, translation, scale) -> np.ndarray:
    """Camera-from-local similarity (column vectors) of a SAM 3D Objects pose.

    SAM 3D Objects applies ``p_cam = (s * p_local) R + t`` to row vectors, with ``R`` the rotation
    matrix of the quaternion; for column vectors that is ``p_cam = s R^T p_local + t``.

    Parameters
    ----------
    rotation_wxyz : (4,) float
        Quaternion ``(w, x, y, z)`` (normalised here).
    translation : (3,) float
    scale : float
        Isotropic scale.

    Returns
    -------
    pose : (4, 4) float
        ``p_cam = pose @ [p_local, 1]``.
    """
    q = np.asarray(rotation_wxyz, dtype=float)
    R = quat_wxyz_to_matrix(q / np.linalg.norm(q))
    pose = np.eye(4)
    pose[:3, :3] = float(scale) * R.T
    pose[:3, 3] = np.asarray(translation, dtype=float)
    return pose


def pose_to_sam3d(pose: np.ndarray) -> dict:
    """Inverse of :func:`sam3d_pose`: a camera-from-local similarity (4, 4) -> ``{rotation, translation, scale}``."""
    Rcol, t, s = decompose(pose)
    return {"rotation": matrix_to_quat_wxyz(Rcol.T).tolist(), "translation": t.tolist(), "scale": float(s)}


def read_pose(path: Path) -> tuple[np.ndarray, dict]:
    """``pose.json`` -> camera-from-local (4, 4) and the file's other fields.

    Raises
    ------
    InputError
        Naming the file and the field: missing keys, wrong lengths, a zero quaternion, an anisotropic or
        non-positive scale.
    """
    from phiscene.schemas import read_json

    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(path, None, "expected an object with rotation, translation and scale")
    values = {key: finite_numbers(data, path, key, size) for key, size in (("rotation", 4), ("translation", 3))}
    if np.linalg.norm(values["rotation"]) < 1e-9:
        raise InputError(path, "rotation", "zero quaternion")
    if "scale" not in data:
        raise InputError(path, "scale", "missing")
    try:
        s = np.asarray(data["scale"], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(path, "scale", f"not numeric: {data['scale']!r}") from None
    if s.size not in (1, 3) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError(path, "scale",
                         f"expected a positive number or 3 equal positive numbers, got {data['scale']!r}")
    if np.ptp(s) > 1e-6 * s.max():
        raise InputError(path, "scale", f"anisotropic scale {s.tolist()}: phiscene poses take one uniform scale")
    extra = {k: v for k, v in data.items() if k not in ("rotation", "translation", "scale")}
    return sam3d_pose(values["rotation"], values["translation"], float(s.mean())), extra


# -- floor and world frame -------------------------------------------------------------------------------------------
def orient_floor(floor: Floor, points: np.ndarray) -> Floor:
    """Flip ``floor`` so that the median of ``points`` (n, 3) lies on its positive side."""
    if np.median(floor.signed_distance(points)) < 0:
        return Floor(-floor.normal, -floor.offset)
    return floor


#: PyTorch3D camera axes (+X left, +Y up, +Z forward) -> a z-up frame (x right, y forward, z up): the frame in
#: which :func:`phiscene.levelling.estimate_up` takes the camera's up (+z) as its prior.
Z_UP_FROM_P3D = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


def levelled_floor(meshes: list, params: LevelParams | None = None) -> tuple[Floor, UpEstimate]:
    """The floor of a camera-frame scene from its objects (module docstring): up estimated, ground where they stand.

    Parameters
    ----------
    meshes
        The objects' meshes (trimesh) in the PyTorch3D camera frame.
    params
        The up estimate's and the ground height's settings (default: :class:`~phiscene.levelling.LevelParams`'s).

    Returns
    -------
    floor
        Camera-frame plane, normal (the estimated up) pointing to the objects.
    estimate
        The up estimate, its vector in the z-up frame of :data:`Z_UP_FROM_P3D`.
    """
    from phiscene.levelling import estimate_up, floor_height, rotation_between

    params = params or LevelParams()
    M = np.eye(4)
    M[:3, :3] = Z_UP_FROM_P3D
    estimate = estimate_up({str(k): m.copy().apply_transform(M) for k, m in enumerate(meshes)}, [0.0, 0.0, 1.0],
                           params)
    R = rotation_between(estimate.up, [0.0, 0.0, 1.0]) @ Z_UP_FROM_P3D  # camera frame -> levelled (z up)
    height = floor_height([np.asarray(m.vertices, dtype=float) @ R.T for m in meshes], params.floor_band,
                          params.floor_rest_deg)
    up = Z_UP_FROM_P3D.T @ estimate.up
    return Floor(up / np.linalg.norm(up), -height), estimate


def world_from_camera(floor: Floor) -> np.ndarray:
    """Rigid transform (4, 4) from the PyTorch3D camera frame to the z-up world of the module docstring.

    Parameters
    ----------
    floor
        Camera-frame floor, normal pointing up.
    """
    z = floor.normal
    right = np.array([-1.0, 0.0, 0.0])  # PyTorch3D +X is left
    x = right - (right @ z) * z
    if np.linalg.norm(x) < 1e-6:  # camera rolled by 90 deg: use the viewing direction instead
        fwd = np.array([0.0, 0.0, 1.0])
        y = fwd - (fwd @ z) * z
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # rows: world axes in camera coordinates
    foot = -floor.offset * z  # the camera centre's projection onto the floor
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ foot
    return T


# -- reading the input folder ----------------------------------------------------------------------------------------
@dataclass
class Sam3dObject:
    """One SAM 3D Objects output.

    Attributes
    ----------
    id
        The folder name.
    mesh
        The mesh in the object's local frame (z up; the GLB variant already rotated back).
    variant
        ``mesh`` or ``glb``.
    pose : (4, 4) float
        Camera-from-local similarity (column vectors, PyTorch3D camera frame).
    description, color, mask
        From ``pose.json`` and ``mask.png`` when present.
    """

    id: str
    mesh: object
    variant: str
    pose: np.ndarray
    description: str = ""
    color: tuple[int, int, int] | None = None
    mask: Path | None = None


def read_object(folder: Path) -> Sam3dObject:
    """Read one object folder (mesh file of either variant, ``pose.json``, optional ``mask.png``).

    Raises
    ------
    InputError
        No or several mesh files, unreadable mesh, bad pose.
    """
    from phiscene.meshes import load_mesh

    found = [folder / name for name in MESH_FILES if (folder / name).is_file()]
    if len(found) != 1:
        raise InputError(folder, None, f"expected exactly one of {', '.join(MESH_FILES)}, found "
                         f"{[p.name for p in found] or 'none'}")
    variant = MESH_FILES[found[0].name]
    mesh = load_mesh(found[0]).copy()
    if variant == "glb":
        mesh.vertices = transform_points(Y_UP_TO_Z_UP, mesh.vertices)  # SAM 3D Objects writes its GLB y-up
    pose, extra = read_pose(folder / "pose.json")
    color = extra.get("color")
    if color is not None:
        if not (isinstance(color, list) and len(color) == 3 and all(isinstance(c, int) and 0 <= c <= 255
                                                                      for c in color)):
            raise InputError(folder / "pose.json", "color", f"expected 3 integers in 0-255, got {color!r}")
        color = tuple(color)
    mask = folder / "mask.png"
    return Sam3dObject(folder.name, mesh, variant, pose, str(extra.get("description", "")), color,
                       mask if mask.is_file() else None)


def read_sam3d_dir(in_dir: str | Path) -> list[Sam3dObject]:
    """Every object sub-folder (one with a ``pose.json``) of a SAM 3D Objects run, sorted by name.

    Raises
    ------
    InputError
        A missing folder, no objects, or an object id that phiscene cannot use.
    """
    import re

    in_dir = Path(in_dir)
    if not in_dir.is_dir():
        raise InputError(in_dir, None, "input folder not found")
    folders = sorted(p for p in in_dir.iterdir() if p.is_dir() and (p / "pose.json").is_file())
    if not folders:
        raise InputError(in_dir, None, "no object folders (<id>/pose.json + mesh.ply|mesh.obj|mesh.glb)")
    for f in folders:
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", f.name) or f.name == "ground":
            raise InputError(f, None, "object folder names must be [A-Za-z0-9_.-]+ and not 'ground'")
    return [read_object(f) for f in folders]


def read_floor(path: Path) -> Floor:
    """``floor.json`` ``{"normal": [3], "offset": d}`` -> :class:`Floor`."""
    from phiscene.schemas import read_json

    data = read_json(path)
    if not isinstance(data, dict) or "normal" not in data or "offset" not in data:
        raise InputError(path, None, "expected {\"normal\": [nx, ny, nz], \"offset\": d}")
    return make_floor(data["normal"], data["offset"], path)


# -- reference image, segmentation, camera ---------------------------------------------------------------------------
def compose_segmentation(objects: list[Sam3dObject], colors: list[tuple[int, int, int]]) -> np.ndarray:
    """Instance segmentation (H, W, 3) uint8 from per-object binary masks (later objects drawn over earlier)."""
    from phiscene.render import load_png

    seg = None
    for o, c in zip(objects, colors):
        if o.mask is None:
            continue
        m = load_png(o.mask).max(axis=2) > 127
        if seg is None:
            seg = np.zeros((*m.shape, 3), dtype=np.uint8)
        if m.shape != seg.shape[:2]:
            raise InputError(o.mask, None, f"mask size {m.shape[::-1]} differs from the other masks' "
                             f"{seg.shape[1::-1]}")
        seg[m] = c
    return seg


def camera_json(intrinsics: dict, world_to_p3d: np.ndarray, near: float = 0.02, far: float = 50.0,
                where: Path | None = None) -> dict:
    """A ``phiscene.camera/1`` dict (see :mod:`phiscene.render`) from pinhole intrinsics and a pose.

    Parameters
    ----------
    intrinsics
        ``fx, fy, cx, cy, width, height`` in pixels, or with ``normalized: true`` fx, cx in image widths
        and fy, cy in image heights.
    world_to_p3d : (4, 4) float
        World -> PyTorch3D camera frame.
    """
    import pybullet as p

    try:
        W, H = int(intrinsics["width"]), int(intrinsics["height"])
        fx, fy, cx, cy = (float(intrinsics[k]) for k in ("fx", "fy", "cx", "cy"))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(where, None, f"camera intrinsics need numeric fx, fy, cx, cy, width, height ({exc})") from None
    if intrinsics.get("normalized"):
        fx, cx, fy, cy = fx * W, cx * W, fy * H, cy * H
    w2c = CV_FROM_P3D @ world_to_p3d
    gl = np.diag([1.0, -1.0, -1.0, 1.0]) @ w2c
    # frustum at the near plane; pixel centres at integers, so the image spans [-0.5, W - 0.5]
    left, right = -(cx + 0.5) / fx * near, (W - 0.5 - cx) / fx * near
    top, bottom = (cy + 0.5) / fy * near, -(H - 0.5 - cy) / fy * near
    proj = p.computeProjectionMatrix(left, right, bottom, top, near, far)
    from phiscene.render import CAMERA_FORMAT

    c2w = np.linalg.inv(w2c)
    return {
        "format": CAMERA_FORMAT, "width": W, "height": H, "fx": fx, "fy": fy, "cx": cx, "cy": cy,
        "world_to_camera": np.round(w2c, 12).tolist(), "camera_to_world": np.round(c2w, 12).tolist(),
        "convention": "world_to_camera maps world points (z up, m) to the OpenCV camera frame (x right, y down, "
                      "z forward); pixel (u, v) = (fx x/z + cx, fy y/z + cy). Imported from SAM 3D Objects.",
        "eye": c2w[:3, 3].tolist(), "target": (c2w[:3, 3] + c2w[:3, 2]).tolist(), "up": [0.0, 0.0, 1.0],
        "pybullet": {"view_matrix": [float(v) for v in gl.T.reshape(-1)], "projection_matrix": [float(v) for v in proj],
                     "fov_y_deg": float(np.degrees(2 * np.arctan(H / (2 * fy)))), "near": near, "far": far},
    }


# -- entry point -----------------------------------------------------------------------------------------------------
def _copy(src: Path, dst: Path) -> None:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def import_sam3d(in_dir: str | Path, out_dir: str | Path, floor: Floor | None = None,
                 params: Sam3dParams = Sam3dParams()) -> Scene:
    """Import one SAM 3D Objects run as ``OUT_DIR/initial/scene.json`` (+ ``reference/``, ``import.json``).

    Parameters
    ----------
    in_dir
        The input folder (module docstring).
    out_dir
        Output folder; ``initial/``, ``reference/`` and ``import.json`` are written below it.
    floor
        Camera-frame floor plane; else ``IN_DIR/floor.json``; else :func:`levelled_floor`.
    params
        Units, levelling and wall settings.

    Returns
    -------
    The written initial scene, loaded back (validated).

    Raises
    ------
    InputError
        Naming the file and field of the first problem in the input.
    """
    from phiscene.atomic import staged_folder
    from phiscene.meshes import save_mesh
    from phiscene.render import load_png, save_png, segmentation_colors
    from phiscene.schemas import read_json

    in_dir, final = Path(in_dir), Path(out_dir)
    with staged_folder(final) as out_dir:  # everything written there, moved into place when whole
        params.check()
        objects = read_sam3d_dir(in_dir)
        units = np.diag([params.unit_scale] * 3 + [1.0])
        cam_poses = [units @ o.pose for o in objects]
        cam_meshes = [o.mesh.copy().apply_transform(P) for o, P in zip(objects, cam_poses)]  # camera frame
        verts = [np.asarray(m.vertices) for m in cam_meshes]
        floor_source, estimate = "argument", None
        if floor is None and (in_dir / "floor.json").is_file():
            floor, floor_source = read_floor(in_dir / "floor.json"), "floor.json"
        if floor is None:
            floor, estimate = levelled_floor(cam_meshes, params.levelling)
            floor_source = "estimated"
        else:
            floor = orient_floor(Floor(floor.normal, floor.offset * params.unit_scale), np.concatenate(verts))
        W = world_from_camera(floor)
        lowest = float(min(floor.signed_distance(v).min() for v in verts))
        if lowest < -0.5 * float(np.ptp(np.concatenate(verts)[:, 1])):
            log.warning("%s: objects reach %.3f m below the floor plane; is the floor right?", in_dir, -lowest)

        colors = segmentation_colors(len(objects))
        given = [o.color for o in objects if o.color is not None]
        if given:
            if len(given) != len(objects):
                missing = [o.id for o in objects if o.color is None]
                raise InputError(in_dir, "color",
                                 f"some objects give a segmentation colour and others do not: {missing}")
            colors = given
        init_dir, ref_dir = out_dir / "initial", out_dir / "reference"
        scene_objects = []
        for o, P, c in zip(objects, cam_poses, colors):
            mesh_path = save_mesh(o.mesh, init_dir / "meshes" / f"{o.id}.glb")
            scene_objects.append(SceneObject(o.id, mesh_path.resolve(), W @ P, o.description or o.id, tuple(c),
                                             {"sam3d": {"variant": o.variant}}))
        camera_path = None
        if (in_dir / "image.png").is_file():
            _copy(in_dir / "image.png", ref_dir / "image.png")
        seg_src = in_dir / "segmentation.png"
        if seg_src.is_file():
            _copy(seg_src, ref_dir / "segmentation.png")
        elif any(o.mask is not None for o in objects):
            save_png(compose_segmentation(objects, colors), ref_dir / "segmentation.png")
        if (in_dir / "camera.json").is_file():
            cam = camera_json(read_json(in_dir / "camera.json"), invert(W), where=in_dir / "camera.json")
            image = ref_dir / "image.png"
            if image.is_file() and load_png(image).shape[:2] != (cam["height"], cam["width"]):
                raise InputError(in_dir / "camera.json", "width", "image size differs from image.png")
            camera_path = ref_dir / "camera.json"
            write_json(camera_path, cam)
        from phiscene.levelling import angle_deg
        from phiscene.walls import estimate_walls

        # the tilt corrected: the angle between the camera's up (PyTorch3D +Y) and the floor's normal
        tilt = angle_deg(floor.normal, [0.0, 1.0, 0.0])
        walls = estimate_walls(Scene(scene_objects, ground_height=0.0), params.walls, W[:3, 3])
        meta = {"source": {"kind": "sam3d", "path": str(in_dir)}, "floor": {**floor.to_dict(), "from": floor_source},
                "levelling": {"rotation_deg": tilt, "transform": np.round(W, 12).tolist()}, "walls": walls.record}
        scene = Scene(scene_objects, ground_height=0.0, camera=camera_path, meta=meta, structure=walls.planes)
        save_scene(scene, init_dir / "scene.json")
        write_json(out_dir / "import.json", {
            "format": IMPORT_FORMAT, "source": str(in_dir), "params": asdict(params),
            "floor": {**floor.to_dict(), "from": floor_source}, "world_from_camera": np.round(W, 12).tolist(),
            "camera_height": float(floor.offset), "levelling_rotation_deg": tilt,
            "up_estimate": None if estimate is None else estimate.to_dict(), "walls": walls.record,
            "objects": {o.id: o.variant for o in objects}, "lowest_below_floor": max(0.0, -lowest)})
        load_scene(init_dir / "scene.json")  # loads back whole (meshes checked) before it is moved into place
        log.info("%s: %d objects, floor %s (%s, %.2f deg from the camera's up), camera %.3f m above it, %d walls "
                 "estimated", in_dir, len(objects), np.round(floor.normal, 4).tolist(), floor_source, tilt,
                 floor.offset, len(walls.planes))
    # its meshes were loaded and checked in the staging folder; the move changed no byte of them
    return load_scene(final / "initial" / "scene.json", check_meshes=False)


# -- workflow source ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sam3dSource(SourceParams):
    """A suite of SAM 3D Objects runs (``config.yaml`` ``suites.<suite>.source`` with ``kind: sam3d``).

    ``root`` holds one folder per scene, each one run in the input layout of the module docstring
    (``<root>/<scene>/<object id>/pose.json`` + mesh, optional ``camera.json``, ``image.png``, ``floor.json``).

    Attributes
    ----------
    root
        The folder of runs, relative to the working directory.
    kind
        ``sam3d``.
    params
        Import settings (:class:`Sam3dParams`: units, levelling, walls).
    """

    _label = "SAM 3D source"

    kind: str = "sam3d"
    params: Sam3dParams = field(default_factory=Sam3dParams)


def scene_ids(root: str | Path) -> list[str]:
    """The runs under ``root``: its sub-folders holding at least one ``<object id>/pose.json``, sorted.

    Raises
    ------
    InputError
        ``root`` is not a folder, or holds no run.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, None, "folder of SAM 3D Objects runs not found")
    found = sorted(p.name for p in root.iterdir() if p.is_dir() and any(p.glob("*/pose.json")))
    if not found:
        raise InputError(root, None, "no SAM 3D Objects runs (<scene>/<object id>/pose.json + mesh) in the folder")
    return found


def run_sam3d_scene(source: dict, scene: str, out_dir: str | Path) -> Scene:
    """Workflow stage: one run of a ``sam3d`` source as ``OUT_DIR/initial/scene.json`` (+ ``reference/``)."""
    src = Sam3dSource.from_dict(source)
    return import_sam3d(Path(src.root) / scene, out_dir, params=src.params)


# -- exporter (fixtures, round trips) --------------------------------------------------------------------------------
def export_sam3d(scene: Scene, out_dir: str | Path, world_to_p3d: np.ndarray, variant: str = "mesh",
                 write_floor: bool = True) -> Path:
    """Write ``scene`` as SAM 3D Objects would have output it for a camera (the inverse of :func:`import_sam3d`).

    Each mesh is normalised into [-0.5, 0.5]^3 (centred bounding box, longest side 1) with the change folded
    into the pose, as SAM 3D Objects' meshes are.

    Parameters
    ----------
    scene
        A phiscene scene (world frame, z up).
    out_dir
        The folder to write (module docstring layout).
    world_to_p3d : (4, 4) float
        Rigid world -> PyTorch3D camera transform.
    variant
        ``mesh`` (``mesh.ply``) or ``glb`` (``mesh.glb``, rotated z-up -> y-up).
    write_floor
        Also write ``floor.json`` (the plane z = ground height, in the camera frame).
    """
    from phiscene.meshes import save_mesh

    if variant not in ("mesh", "glb"):
        raise ValueError(f"variant must be 'mesh' or 'glb', got {variant!r}")
    out_dir = Path(out_dir)
    T = np.asarray(world_to_p3d, dtype=float)
    for o in scene.objects:
        m = o.mesh().copy()
        lo, hi = m.bounds
        centre, size = (lo + hi) / 2, float((hi - lo).max())
        norm = np.eye(4)
        norm[:3, :3] *= size
        norm[:3, 3] = centre  # local = norm @ unit
        m.vertices = (np.asarray(m.vertices) - centre) / size
        pose = T @ o.pose @ norm
        d = {**pose_to_sam3d(pose), "description": o.description}
        if o.color is not None:
            d["color"] = [int(c) for c in o.color]
        if variant == "glb":
            m.vertices = transform_points(Z_UP_TO_Y_UP, m.vertices)
        save_mesh(m, out_dir / o.id / ("mesh.ply" if variant == "mesh" else "mesh.glb"))
        write_json(out_dir / o.id / "pose.json", d)
    if write_floor:
        Rinv = np.linalg.inv(T)
        n = Rinv[2, :3]  # world z as a function of camera coordinates: z = n.p + Rinv[2, 3]
        write_json(out_dir / "floor.json", {"normal": n.tolist(), "offset": float(Rinv[2, 3] - scene.ground_height)})
    return out_dir
