"""Self-contained, offline, interactive 3D viewer page of a scene (three.js via trimesh).

:func:`scene_viewer_html` exports the scene as a binary glTF, embeds it as
base64 in trimesh's three.js viewer page (:func:`trimesh.viewer.notebook.scene_to_html`)
and adds a title and a legend of the objects.

Offline: trimesh's page template (``trimesh/resources/templates/viewer.zip``,
``viewer.html.template``) inlines the whole of three.js (r140), its
``GLTFLoader`` and ``TrackballControls`` in one ``<script>`` element; nothing is
fetched from a CDN. :func:`scene_viewer_html` checks the page it writes has no
``<script src=...>`` and no ``<link href=...>``, and fails rather than write a
page that needs the network.

Conventions: glTF and three.js are y-up, phiscene is z-up, so the exported
scene is rotated by :data:`phiscene.transforms.Z_UP_TO_Y_UP` (x, y, z) -> (x, z, -y); the page's
trackball then orbits about the scene's vertical. The page opens at the
scene's reference camera (``scene.camera``) when it has one, else at the
benchmark's default oblique camera (:func:`phiscene.render.camera_for`).
Objects are coloured by their segmentation ``color`` (``color_by="color"``,
the default) or by their natural colour ``meta["rgb"]`` (``color_by="rgb"``,
what the reference image shows), grey when unset; the
ground is a light-grey slab whose top is at ``scene.ground_height``.
Controls: left drag rotates, right drag pans, wheel zooms.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from phiscene.atomic import write_text
from phiscene.scene import Scene
from phiscene.transforms import Z_UP_TO_Y_UP

#: Ground slab: RGB (0-255), thickness (m), and its size as a multiple of the scene's horizontal extent.
GROUND_RGB = (209, 209, 204)
GROUND_THICKNESS = 0.01
GROUND_EXTENT = 2.0
#: Colour of an object without the requested colour.
DEFAULT_RGB = (150, 150, 150)
#: Colour sources of :func:`object_rgb`.
COLOR_BY = ("color", "rgb")

_REMOTE = re.compile(r"<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)\s*=\s*[\"']?\s*(?:https?:)?//", re.I)


def _material(rgb):
    import trimesh

    return trimesh.visual.material.PBRMaterial(baseColorFactor=[int(c) for c in rgb] + [255], metallicFactor=0.0,
                                               roughnessFactor=0.8, doubleSided=True)


def _colored(mesh, rgb):
    import trimesh

    m = mesh.copy()
    m.visual = trimesh.visual.TextureVisuals(material=_material(rgb))
    return m


def ground_slab(scene: Scene):
    """The ground as a light-grey box (world, z-up) under the scene, top at ``scene.ground_height``.

    Returns
    -------
    trimesh.Trimesh
    """
    import trimesh

    from phiscene.render import scene_bounds

    b = scene_bounds(scene)
    centre = b.mean(axis=0)
    size = GROUND_EXTENT * max(float(np.max(b[1, :2] - b[0, :2])), 0.1)
    T = np.eye(4)
    T[:3, 3] = [centre[0], centre[1], scene.ground_height - GROUND_THICKNESS / 2]
    return _colored(trimesh.creation.box(extents=[size, size, GROUND_THICKNESS], transform=T), GROUND_RGB)


def _view_camera(scene: Scene) -> dict:
    from phiscene.render import RenderParams, camera_for, read_camera

    if scene.camera is not None and Path(scene.camera).is_file():
        return read_camera(scene.camera)
    return camera_for(scene, RenderParams())


def object_rgb(obj, color_by: str = "color") -> tuple[int, int, int]:
    """Display colour (0-255) of ``obj``: its segmentation ``color`` or its ``meta["rgb"]`` (grey when unset)."""
    if color_by not in COLOR_BY:
        raise ValueError(f"color_by must be one of {list(COLOR_BY)}, got {color_by!r}")
    rgb = obj.color if color_by == "color" else obj.meta.get("rgb")
    return tuple(int(c) for c in rgb) if rgb is not None else DEFAULT_RGB


def to_trimesh_scene(scene: Scene, color_by: str = "color"):
    """The scene as a y-up :class:`trimesh.Scene`: one node per object (named by id), ground, camera.

    Parameters
    ----------
    scene
        The scene.
    color_by
        ``"color"`` (segmentation colour) or ``"rgb"`` (``meta["rgb"]``), see :func:`object_rgb`.

    Returns
    -------
    trimesh.Scene
    """
    import trimesh

    ts = trimesh.Scene()
    for o in scene.objects:
        m = _colored(o.world_mesh(), object_rgb(o, color_by))
        m.apply_transform(Z_UP_TO_Y_UP)
        ts.add_geometry(m, node_name=o.id, geom_name=o.id)
    ground = ground_slab(scene)
    ground.apply_transform(Z_UP_TO_Y_UP)
    ts.add_geometry(ground, node_name="ground", geom_name="ground")
    cam = _view_camera(scene)
    W, H = int(cam["width"]), int(cam["height"])
    fov_y = float(cam["pybullet"]["fov_y_deg"])
    fov_x = float(np.degrees(2 * np.arctan(np.tan(np.radians(fov_y) / 2) * W / H)))
    ts.camera = trimesh.scene.Camera(name="reference", resolution=(W, H), fov=(fov_x, fov_y),
                                     z_near=float(cam["pybullet"]["near"]), z_far=float(cam["pybullet"]["far"]))
    # camera.json holds an OpenCV camera (y down, z forward); glTF cameras look down -z with y up
    c2w_gl = np.asarray(cam["camera_to_world"], dtype=float) @ np.diag([1.0, -1.0, -1.0, 1.0])
    ts.camera_transform = Z_UP_TO_Y_UP @ c2w_gl
    return ts


def _legend(scene: Scene, title: str, color_by: str) -> str:
    rows = []
    for o in scene.objects:
        rgb = object_rgb(o, color_by)
        swatch = "#{:02x}{:02x}{:02x}".format(*(int(c) for c in rgb))
        rows.append(f'<li data-object="{html.escape(o.id)}"><span style="background:{swatch}"></span>'
                    f"{html.escape(o.id)} {html.escape(o.description)}</li>")
    return ('<div id="phiscene-legend"><style>#phiscene-legend{position:absolute;top:8px;left:8px;'
            "font:12px sans-serif;background:rgba(255,255,255,.85);padding:6px 10px;border-radius:4px;"
            "max-height:90vh;overflow:auto}#phiscene-legend ul{list-style:none;margin:4px 0 0;padding:0}"
            "#phiscene-legend span{display:inline-block;width:10px;height:10px;margin-right:6px;"
            f'border:1px solid #333}}</style><b>{html.escape(title)}</b><ul>{"".join(rows)}</ul>'
            "<small>drag: rotate, right drag: pan, wheel: zoom</small></div>")


def scene_viewer_html(scene: Scene, out_html: str | Path, title: str, color_by: str = "color") -> Path:
    """Write a self-contained interactive 3D viewer of ``scene`` (works offline, one file).

    Parameters
    ----------
    scene
        The scene (objects coloured by ``color``).
    out_html
        Output HTML file.
    title
        Page title, also shown above the object legend.
    color_by
        ``"color"`` (segmentation colour, default) or ``"rgb"`` (``meta["rgb"]``).

    Returns
    -------
    The written path.

    Raises
    ------
    RuntimeError
        When the installed trimesh's page template is not the expected one (no title tag or
        ``<body>`` to extend) or would load something from the network.
    """
    from trimesh.viewer.notebook import scene_to_html

    page = scene_to_html(to_trimesh_scene(scene, color_by))
    title_tag = re.search(r"<title>.*?</title>", page, flags=re.S)
    if title_tag is None or "<body>" not in page:
        raise RuntimeError("trimesh's viewer template changed (no <title> or <body>); cannot write the viewer")
    page = page[:title_tag.start()] + f"<title>{html.escape(title)}</title>" + page[title_tag.end():]
    page = page.replace("<body>", "<body>" + _legend(scene, title, color_by), 1)
    remote = _REMOTE.search(page)
    if remote is not None:
        raise RuntimeError(f"the viewer page would load from the network ({remote.group(0)[:80]}); refusing to write "
                           "a page that does not work offline")
    out_html = Path(out_html)
    write_text(out_html, page)
    return out_html
