"""Reference image, instance segmentation and camera of a scene, rendered on the CPU.

Images use pybullet's TinyRenderer (``ER_TINY_RENDERER``) in a DIRECT
client, so they need neither a GPU nor a display. Each object becomes a
visual-only body built from a temporary OBJ of its world-frame mesh (flat
shaded); the ground is a large light-grey slab. Instance labels (the
reference segmentation, the masks the alignment metric compares) are cast
instead (:func:`instance_labels`: open3d's ``RaycastingScene``, one ray
through each pixel centre of ``camera.json``'s pinhole model against the
full meshes): 5x faster than a TinyRenderer pass on a 17-object scene of
30k-face reconstructions (0.5 s against 2.4 s), exact to the documented pixel
convention (TinyRenderer's segmentation buffer sits half a pixel off it).

``camera.json`` (format ``phiscene.camera/1``)::

    {"format": "phiscene.camera/1", "width": W, "height": H,
     "fx": .., "fy": .., "cx": .., "cy": ..,
     "world_to_camera": 4x4, "camera_to_world": 4x4,
     "convention": "...", "eye": [..], "target": [..], "up": [0, 0, 1],
     "pybullet": {"view_matrix": [16], "projection_matrix": [16], "fov_y_deg": .., "near": .., "far": ..}}

``world_to_camera`` maps world points to the OpenCV camera frame (x right,
y down, z forward, metres); a camera-frame point ``(x, y, z)`` projects to the
pixel ``(u, v) = (fx x / z + cx, fy y / z + cy)`` with pixel centres at integer
coordinates and ``(0, 0)`` the centre of the top-left pixel. The pybullet
matrices are the column-major lists that ``computeViewMatrix`` and
``computeProjectionMatrixFOV`` return (OpenGL conventions).
"""

from __future__ import annotations

import colorsys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phiscene.errors import InputError
from phiscene.params import Params
from phiscene.scene import Scene

CAMERA_FORMAT = "phiscene.camera/1"

#: Colour of the ground slab in the reference image (RGB 0-1).
GROUND_RGB = (0.82, 0.82, 0.80)


@dataclass(frozen=True)
class RenderParams(Params):
    """Reference camera and renderer settings.

    Attributes
    ----------
    width, height
        Image size in pixels.
    fov_y_deg
        Vertical field of view (deg).
    azimuth_deg
        Direction from the scene centre to the camera, counter-clockwise from +x, seen from above (deg).
    elevation_deg
        Camera elevation above the horizontal (deg).
    margin
        Distance factor (>= 1) applied to the distance at which the scene's bounding box just fits.
    near, far
        Clipping planes (m).
    light_direction
        Direction towards the light (world, unnormalised).
    shadow
        Cast shadows in the reference image.
    min_visible_pixels
        Fewest segmentation pixels an object must cover (the benchmark rejects scenes with hidden objects).
    """

    _label = "render parameters"
    _coerce = {"light_direction": lambda v: tuple(float(x) for x in v)}

    width: int = 320
    height: int = 240
    fov_y_deg: float = 45.0
    azimuth_deg: float = -60.0
    elevation_deg: float = 35.0
    margin: float = 1.1
    near: float = 0.02
    far: float = 20.0
    light_direction: tuple[float, float, float] = (0.4, -0.6, 1.0)
    shadow: bool = True
    min_visible_pixels: int = 40


def segmentation_colors(n: int) -> list[tuple[int, int, int]]:
    """``n`` distinct, saturated, non-black RGB colours (golden-ratio hue steps, alternating brightness).

    Returns
    -------
    list of (r, g, b) ints in 0-255
    """
    out = []
    for i in range(n):
        h = (0.11 + i * 0.618033988749895) % 1.0
        v = 1.0 if i % 2 == 0 else 0.7
        s = 0.9 if (i // 2) % 2 == 0 else 0.6
        out.append(tuple(int(round(255 * c)) for c in colorsys.hsv_to_rgb(h, s, v)))
    return out


def scene_bounds(scene: Scene) -> np.ndarray:
    """World AABB (2, 3) of all objects."""
    b = np.array([o.world_mesh().bounds for o in scene.objects])
    return np.array([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])


def fit_distance(bounds: np.ndarray, target: np.ndarray, back: np.ndarray, half_fov_y: float,
                 aspect: float) -> float:
    """Smallest eye distance along ``back`` at which all 8 corners of ``bounds`` (2, 3) are in view.

    Parameters
    ----------
    bounds : (2, 3) float
        World AABB.
    target : (3,) float
        Point the camera looks at.
    back : (3,) unit float
        Direction from the target to the eye.
    half_fov_y
        Half the vertical field of view (rad).
    aspect
        Width / height.
    """
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    tan_y = np.tan(half_fov_y)
    tan_x = tan_y * aspect
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    c = corners - target
    x, y, b = c @ right, c @ up, c @ back
    # a corner at depth (dist - b) is in view when |x| <= tan_x (dist - b) and |y| <= tan_y (dist - b)
    need = np.maximum(np.abs(x) / tan_x, np.abs(y) / tan_y) + b
    return float(need.max())


def camera_for(scene: Scene, params: RenderParams) -> dict:
    """The fixed oblique camera framing ``scene``: looks at the AABB centre from the configured direction.

    Returns
    -------
    camera dict (the ``camera.json`` content)
    """
    bounds = scene_bounds(scene)
    target = bounds.mean(axis=0)
    aspect = params.width / params.height
    half_fov = np.radians(params.fov_y_deg) / 2
    az, el = np.radians(params.azimuth_deg), np.radians(params.elevation_deg)
    back = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])  # target -> eye
    dist = params.margin * fit_distance(bounds, target, back, half_fov, aspect)
    eye = target + dist * back
    return look_at_camera(eye, target, params.width, params.height, params.fov_y_deg, params.near, params.far)


#: :func:`raised_cameras`: elevations tried above the configured one (deg), in order, and the steepest one.
RAISED_ELEVATIONS = (10.0, 20.0, 30.0)
MAX_ELEVATION = 75.0


def raised_cameras(scene: Scene, params: RenderParams) -> list[dict]:
    """The cameras of :func:`camera_for` from :data:`RAISED_ELEVATIONS` above the configured elevation (capped at
    :data:`MAX_ELEVATION`, duplicates dropped), same azimuth: looking down more steeply, the nearer objects hide
    less of the ones behind them.

    Returns
    -------
    list of camera dicts, lowest first
    """
    from dataclasses import replace

    elevations = []
    for extra in RAISED_ELEVATIONS:
        el = min(params.elevation_deg + extra, MAX_ELEVATION)
        if el > params.elevation_deg and el not in elevations:
            elevations.append(el)
    return [camera_for(scene, replace(params, elevation_deg=el)) for el in elevations]


def camera_elevation(camera: dict) -> float:
    """Elevation of a camera dict's eye above its target, seen from the target (deg)."""
    d = np.asarray(camera["eye"], dtype=float) - np.asarray(camera["target"], dtype=float)
    return float(np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1]))))


def hidden_objects(scene: Scene, labels: np.ndarray, min_pixels: int) -> list[str]:
    """Ids of the objects that cover fewer than ``min_pixels`` pixels of an :func:`instance_labels` image (H, W)."""
    counts = np.bincount(labels[labels >= 0].ravel(), minlength=len(scene.objects))
    return [o.id for o, c in zip(scene.objects, counts) if c < min_pixels]


def look_at_camera(eye: np.ndarray, target: np.ndarray, width: int, height: int, fov_y_deg: float, near: float,
                   far: float) -> dict:
    """The camera dict of a pinhole camera at ``eye`` looking at ``target`` with world z up.

    Parameters
    ----------
    eye, target : (3,) float
        Camera centre and the point it looks at (world, m); ``eye - target`` must not be vertical.
    width, height
        Image size in pixels.
    fov_y_deg
        Vertical field of view (deg).
    near, far
        Clipping planes (m).

    Returns
    -------
    camera dict (the ``camera.json`` content)
    """
    import pybullet as p

    eye, target = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
    half_fov = np.radians(fov_y_deg) / 2
    view = p.computeViewMatrix(eye.tolist(), target.tolist(), [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(fov_y_deg, width / height, near, far)
    gl_world_to_cam = np.asarray(view, dtype=float).reshape(4, 4).T
    w2c = np.diag([1.0, -1.0, -1.0, 1.0]) @ gl_world_to_cam
    fy = (height / 2) / np.tan(half_fov)
    return {
        "format": CAMERA_FORMAT, "width": width, "height": height,
        "fx": float(fy), "fy": float(fy), "cx": width / 2 - 0.5, "cy": height / 2 - 0.5,
        "world_to_camera": np.round(w2c, 12).tolist(), "camera_to_world": np.round(np.linalg.inv(w2c), 12).tolist(),
        "convention": "world_to_camera maps world points (z up, m) to the OpenCV camera frame (x right, y down, "
                      "z forward); pixel (u, v) = (fx x/z + cx, fy y/z + cy), pixel centres at integers, (0, 0) = "
                      "top-left pixel centre. pybullet matrices are column-major OpenGL (as pybullet returns them).",
        "eye": eye.tolist(), "target": target.tolist(), "up": [0.0, 0.0, 1.0],
        "pybullet": {"view_matrix": [float(v) for v in view], "projection_matrix": [float(v) for v in proj],
                     "fov_y_deg": fov_y_deg, "near": near, "far": far},
    }


def read_camera(path: str | Path) -> dict:
    """Load and check a ``camera.json`` (InputError naming the file and field on problems)."""
    from phiscene.schemas import read_json

    cam = read_json(path)
    if not isinstance(cam, dict) or cam.get("format") != CAMERA_FORMAT:
        raise InputError(path, "format", f"expected {CAMERA_FORMAT!r}")
    for key in ("width", "height", "fx", "fy", "cx", "cy", "world_to_camera", "pybullet"):
        if key not in cam:
            raise InputError(path, key, "missing")
    for key in ("view_matrix", "projection_matrix"):
        if len(cam["pybullet"].get(key, [])) != 16:
            raise InputError(path, f"pybullet.{key}", "expected 16 numbers")
    return cam


def camera_eye(camera: dict) -> np.ndarray:
    """The camera's centre (3,), world frame, from its ``world_to_camera``."""
    T = np.asarray(camera["world_to_camera"], dtype=float)
    return -T[:3, :3].T @ T[:3, 3]


def project(camera: dict, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (n, 2) ``(u, v)`` of world points (n, 3) under ``camera``."""
    T = np.asarray(camera["world_to_camera"], dtype=float)
    pc = np.asarray(points, dtype=float) @ T[:3, :3].T + T[:3, 3]
    return np.stack([camera["fx"] * pc[:, 0] / pc[:, 2] + camera["cx"],
                     camera["fy"] * pc[:, 1] / pc[:, 2] + camera["cy"]], axis=1)


#: Meshes with more faces are drawn from a quadric-decimated copy (a 30k-face reconstruction takes most of a
#: render in OBJ export alone; at benchmark resolutions the silhouette moves by less than a pixel).
RENDER_MAX_FACES = 8000


def _flat_obj(mesh, path: Path) -> None:
    from phiscene.proxies import decimated

    m = decimated(mesh, RENDER_MAX_FACES).copy()
    m.unmerge_vertices()
    m.export(path, file_type="obj", include_normals=True, include_texture=False)


def render(scene: Scene, camera: dict, colors: list | None = None, shadow: bool = True,
           light_direction=(0.4, -0.6, 1.0)) -> np.ndarray:
    """Render ``scene`` from ``camera`` with TinyRenderer.

    Parameters
    ----------
    scene
        Objects to draw (the ground at ``scene.ground_height``).
    camera
        A camera dict (see :func:`camera_for`).
    colors
        RGB (0-255) of each object in the image; defaults to the object's ``meta["rgb"]``,
        else its segmentation colour.
    shadow, light_direction
        Shading.

    Returns
    -------
    rgb : (H, W, 3) uint8
        The image (its instance labels: :func:`instance_labels`).
    """
    W, H = int(camera["width"]), int(camera["height"])
    from phiscene.sim.bullet import open_client

    client = open_client()
    try:
        with tempfile.TemporaryDirectory(prefix="phiscene-render-") as tmp:
            ground = client.createVisualShape(client.GEOM_BOX, halfExtents=[50, 50, 0.05], rgbaColor=[*GROUND_RGB, 1])
            client.createMultiBody(0, -1, ground, basePosition=[0, 0, scene.ground_height - 0.05])
            for k, o in enumerate(scene.objects):
                rgb = (colors[k] if colors is not None else o.meta.get("rgb") or o.color or (150, 150, 150))
                f = Path(tmp) / f"{k}.obj"
                _flat_obj(o.world_mesh(), f)
                vis = client.createVisualShape(client.GEOM_MESH, fileName=str(f),
                                               rgbaColor=[c / 255 for c in rgb] + [1])
                client.createMultiBody(0, -1, vis)
            _, _, px, _, _ = client.getCameraImage(
                W, H, viewMatrix=camera["pybullet"]["view_matrix"],
                projectionMatrix=camera["pybullet"]["projection_matrix"], renderer=client.ER_TINY_RENDERER,
                shadow=int(shadow), lightDirection=list(light_direction))
    finally:
        client.disconnect()
    return np.asarray(px, dtype=np.uint8).reshape(H, W, 4)[:, :, :3].copy()


def instance_labels(scene: Scene, camera: dict) -> np.ndarray:
    """Which object each pixel of ``camera`` sees: one ray through each pixel centre, cast with open3d.

    The ray of pixel ``(u, v)`` leaves the camera centre along ``((u - cx) / fx, (v - cy) / fy, 1)`` in the
    camera frame (``camera.json``'s convention, the inverse of :func:`project`); the first hit among the
    objects' world-frame meshes and the ground plane decides.

    Returns
    -------
    labels : (H, W) int32
        Index into ``scene.objects`` of the object hit first, -1 for the ground and for no hit.
    """
    from phiscene.o3d import open3d

    o3d = open3d()
    W, H = int(camera["width"]), int(camera["height"])
    cast = o3d.t.geometry.RaycastingScene()
    for o in scene.objects:  # geometry ids 0 .. n - 1 in object order
        m = o.world_mesh()
        cast.add_triangles(o3d.core.Tensor(np.asarray(m.vertices, dtype=np.float32)),
                           o3d.core.Tensor(np.asarray(m.faces, dtype=np.uint32)))
    lut = [*range(len(scene.objects)), -1, -1]  # the objects, the ground, then "no hit" (mapped below)
    g = float(scene.ground_height)
    cast.add_triangles(o3d.core.Tensor(np.array([[-50, -50, g], [50, -50, g], [50, 50, g], [-50, 50, g]],
                                                dtype=np.float32)),
                       o3d.core.Tensor(np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)))
    hit = cast.cast_rays(o3d.core.Tensor(pixel_rays(camera)))["geometry_ids"].numpy().astype(np.int64)
    hit[hit == o3d.t.geometry.RaycastingScene.INVALID_ID] = len(lut) - 1
    return np.asarray(lut, dtype=np.int32)[hit].reshape(H, W)


def pixel_rays(camera: dict) -> np.ndarray:
    """One ray per pixel centre of ``camera``, row by row: (H * W, 6) float32, origin then direction (world).

    The ray of pixel ``(u, v)`` leaves the camera centre along ``((u - cx) / fx, (v - cy) / fy, 1)`` in the camera
    frame (the inverse of :func:`project`), the layout open3d's ``RaycastingScene.cast_rays`` takes.
    """
    W, H = int(camera["width"]), int(camera["height"])
    c2w = np.linalg.inv(np.asarray(camera["world_to_camera"], dtype=float))
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    d = np.stack([(u - camera["cx"]) / camera["fx"], (v - camera["cy"]) / camera["fy"], np.ones_like(u)], axis=-1)
    d = d.reshape(-1, 3) @ c2w[:3, :3].T
    return np.hstack([np.broadcast_to(c2w[:3, 3], d.shape), d]).astype(np.float32)


def visible_shares(scene: Scene, camera: dict) -> dict[str, float]:
    """Share of each object that ``camera`` sees: its pixels in :func:`instance_labels` over its pixels alone.

    An object's pixels alone are those whose ray meets its world-frame mesh, whatever lies in front; the share
    is 1 for an object nothing hides, 0 for one entirely hidden behind others (or the ground), and ``nan`` for
    one outside the image. Its rays are cast only within :func:`pixel_window` (a ray outside it cannot meet the
    mesh), so a small object costs a few rays, not the whole image's.

    Returns
    -------
    dict
        Object id -> share in [0, 1] (or ``nan``).
    """
    from phiscene.o3d import open3d

    o3d = open3d()
    labels = instance_labels(scene, camera).ravel()
    W, H = int(camera["width"]), int(camera["height"])
    rays = pixel_rays(camera).reshape(H, W, 6)
    shares = {}
    for index, o in enumerate(scene.objects):
        m = o.world_mesh()
        rows, cols = pixel_window(camera, np.asarray(m.vertices, dtype=float))
        window = np.ascontiguousarray(rays[rows, cols].reshape(-1, 6))
        total = 0
        if len(window):
            alone = o3d.t.geometry.RaycastingScene()
            alone.add_triangles(o3d.core.Tensor(np.asarray(m.vertices, dtype=np.float32)),
                                o3d.core.Tensor(np.asarray(m.faces, dtype=np.uint32)))
            total = int(np.isfinite(alone.cast_rays(o3d.core.Tensor(window))["t_hit"].numpy()).sum())
        shares[o.id] = float(np.count_nonzero(labels == index) / total) if total else float("nan")
    return shares


def pixel_window(camera: dict, points: np.ndarray) -> tuple[slice, slice]:
    """Rows and columns of ``camera``'s image holding every pixel whose ray can meet a mesh with these vertices.

    A point a ray meets lies on a triangle of the mesh; when every vertex is in front of the camera, the
    triangle projects into the image plane as a triangle inside the box of the vertices' projections, so the
    pixel lies in that box (widened here by one pixel against rounding, and clipped to the image). A mesh
    reaching behind the camera has no bounded projection: the whole image.

    Parameters
    ----------
    points : (n, 3) float
        The mesh's vertices, world frame.

    Returns
    -------
    rows, cols : slice
        Possibly empty (a mesh wholly outside the image).
    """
    W, H = int(camera["width"]), int(camera["height"])
    T = np.asarray(camera["world_to_camera"], dtype=float)
    depth = np.asarray(points, dtype=float) @ T[2, :3] + T[2, 3]
    if len(depth) == 0 or not depth.min() > 0.0:
        return slice(0, H), slice(0, W)
    uv = project(camera, points)
    lo, hi = np.floor(uv.min(axis=0)) - 1, np.ceil(uv.max(axis=0)) + 1
    cols = slice(int(np.clip(lo[0], 0, W)), int(np.clip(hi[0] + 1, 0, W)))
    rows = slice(int(np.clip(lo[1], 0, H)), int(np.clip(hi[1] + 1, 0, H)))
    return rows, cols


def render_instance_mask(scene: Scene, camera: dict | str | Path) -> np.ndarray:
    """Instance mask of ``scene`` seen from ``camera`` (a dict or a ``camera.json`` path).

    Returns
    -------
    labels : (H, W) int32
        Index into ``scene.objects`` of the object seen at each pixel, -1 where none.
    """
    cam = camera if isinstance(camera, dict) else read_camera(camera)
    return instance_labels(scene, cam)


def labels_to_colors(labels: np.ndarray, colors: list) -> np.ndarray:
    """Colour an instance mask: pixel of object ``k`` gets ``colors[k]``, background black.

    Returns
    -------
    (H, W, 3) uint8
    """
    out = np.zeros((*labels.shape, 3), dtype=np.uint8)
    for k, c in enumerate(colors):
        out[labels == k] = c
    return out


def colors_to_labels(image: np.ndarray, colors: list) -> np.ndarray:
    """Inverse of :func:`labels_to_colors`: (H, W, 3) uint8 -> (H, W) int32 (-1 for unknown colours)."""
    labels = np.full(image.shape[:2], -1, dtype=np.int32)
    for k, c in enumerate(colors):
        labels[np.all(image[:, :, :3] == np.asarray(c, dtype=np.uint8), axis=2)] = k
    return labels


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write an (H, W, 3) uint8 image as PNG atomically (no metadata, so bytes are reproducible)."""
    from PIL import Image

    from phiscene.atomic import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image[:, :, :3], dtype=np.uint8)).save(tmp, format="PNG", optimize=False)
    return path


def load_png(path: str | Path) -> np.ndarray:
    """Read a PNG as (H, W, 3) uint8."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))
