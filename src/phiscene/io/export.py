"""Simulation-ready export of a settled scene: GLB, URDF, MJCF and the support graph.

A settled scene is meant to be loaded into someone else's simulator or viewer
as it is (paper supplement, "Simulation-ready 3D scene reconstruction"). One
call of :func:`export_scene` writes into an output folder::

    scene.glb               visual meshes at their poses (one glTF node per object, +Y up)
    scene.xml               MJCF (mujoco.MjSpec): free bodies, convex hull meshes, visual meshes,
                            the pipeline's contact and solver settings, a ground plane
    scene_urdf.json         the URDF scene index: world settings, ground, walls and ceiling (``structure``: the
                            ground slab's URDF posed so that its top face is the plane), per-object URDF + pose
    urdf/<id>.urdf          one link per object: visual mesh, convex proxies as collision, inertial
    urdf/ground.urdf        the static ground slab
    meshes/<id>/visual.obj  the object's mesh in its link frame (pose scale applied)
    meshes/<id>/hull_<k>.stl  its convex proxies in the same frame
    scene.usda              OpenUSD stage with UsdPhysics rigid bodies, mass properties, convex colliders and a
                            physics material (:mod:`phiscene.io.usd`; Isaac Sim, Omniverse, usdview)
    support_graph.json      the full multi-parent support graph (``phiscene.topology/1``)
    export.json             manifest: files, settings, object ids

GLB
    glTF is +Y up (glTF 2.0 spec, "Coordinate System and Units"); phiscene is
    +Z up. The objects hang under one root node ``z_up_to_y_up`` that rotates
    by -90 degrees about x (:data:`phiscene.transforms.Z_UP_TO_Y_UP`), so the scene stands upright
    in glTF viewers and Blender; each object is a node named by its id whose
    matrix is the object's pose (uniform scale included) and whose mesh is the
    local-frame mesh with the object's colour as its base colour.

URDF: one file per object
    A URDF describes one tree with one root link; pybullet's ``loadURDF``
    turns one file into one multibody, and it does not support ``floating``
    joints (a scene in one URDF would be one articulated body, or a welded
    one). MuJoCo's URDF compiler, ``yourdfpy`` and ``urdf_parser_py`` also
    read one tree per file. So every object is its own URDF with a single link
    (a free base when loaded with ``useFixedBase=False``), and
    ``scene_urdf.json`` gives each file's world pose (the link frame: the
    rigid part of the object's pose; the scale is baked into the meshes) plus
    the world settings. :func:`load_urdf_scene` loads it into a pybullet
    client; the README shows the same in a few lines of plain pybullet.

    Each link has one ``<collision>`` per convex proxy (a binary STL of the
    hull; every reader takes a mesh collision's convex hull). STL, not OBJ:
    pybullet turns an STL collision mesh into one convex hull shape, which
    ``changeDynamics(collisionMargin=...)`` reaches, but an OBJ into a nested
    compound whose hulls keep the URDF importer's 1 mm default margin, so
    every resting body would float 1 mm per contact (measured: 1.0 mm drift
    of each ground object of a settled benchmark scene, 0.01 mm with STL).
    One ``<visual>`` holds the mesh (OBJ) and
    the object's colour, and an ``<inertial>`` from
    :func:`phiscene.inertia.rigid_props` at ``SimSettings.density``: mass,
    centre of mass and principal moments, the principal axes as ``rpy``
    (fixed-axis roll-pitch-yaw). pybullet ignores URDF inertia tensors unless
    loaded with ``URDF_USE_INERTIA_FROM_FILE`` (by default it recomputes them
    from the mass and the collision shapes), so the index lists that flag.
    Friction, rolling and spinning friction and restitution are in pybullet's
    ``<contact>`` extension of each link; damping and the collision margin
    have no URDF element and are in the index (``dynamics``), applied with
    ``changeDynamics``.

    A URDF tree has one parent per link, but an object can rest on several
    supports; the full support graph goes to ``support_graph.json`` instead
    (every edge ``from`` carries ``to``; ``meta.urdf`` maps ids to files).

MJCF
    :func:`phiscene.sim.mujoco.build_spec` (the cross-simulator drift's model:
    free bodies in their principal frames, explicit inertia, convex hull
    meshes, the matched friction, contact and solver settings) plus, per
    body, a visual mesh geom (``<id>/visual``, group 2, no contacts); the
    hull geoms go to group 3 (hidden by default in MuJoCo's viewer, toggle
    group 3 to see the collision proxies). A checker floor material and a
    light are added for viewing. Damping: Bullet's velocity damping is a
    decay rate per degree of freedom (``rate * mass`` translational,
    ``rate * I_k`` rotational, see :func:`phiscene.sim.mujoco.compile_model`),
    while an MJCF joint holds one damping value for all six degrees of
    freedom of a free joint; any single value would damp rotations tens to
    hundreds of times too strongly, so the exported free joints carry no
    damping (the pipeline's damping, 0.04, is a velocity decay of about
    4 % per second). ``compile_model`` on the spec adds the exact values.
"""

from __future__ import annotations

import math
import shutil
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from phiscene.atomic import atomic_path, write_json, write_text
from phiscene.errors import InputError
from phiscene.inertia import RigidProps, rigid_props
from phiscene.proxies import check_proxies, with_base
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import (
    Y_UP_TO_Z_UP,
    Z_UP_TO_Y_UP,
    decompose,
    make_pose,
    matrix_to_quat_xyzw,
    quat_xyzw_to_matrix,
    rotation_angle,
)

if TYPE_CHECKING:
    import mujoco

    from phiscene.proxies import Proxy
    from phiscene.scene import Scene, SceneObject
    from phiscene.sim.mujoco import MujocoParams
    from phiscene.topology.graph import SupportGraph

#: Format tag of ``scene_urdf.json``.
URDF_SCENE_FORMAT = "phiscene.urdf_scene/1"
#: Format tag of ``export.json``.
EXPORT_FORMAT = "phiscene.export/1"
#: Name of the GLB root node that carries :data:`phiscene.transforms.Z_UP_TO_Y_UP` (+Z up to glTF's +Y up).
GLB_ROOT = "z_up_to_y_up"
#: Colour of objects without one (RGB 0-255).
DEFAULT_RGB = (150, 150, 150)
#: MuJoCo geom groups: visual meshes and collision hulls.
MJ_VISUAL_GROUP, MJ_COLLISION_GROUP = 2, 3
#: File names inside an export folder.
FILES = {"glb": "scene.glb", "mjcf": "scene.xml", "urdf_index": "scene_urdf.json", "usd": "scene.usda",
         "support_graph": "support_graph.json", "manifest": "export.json"}


def object_rgb(obj: "SceneObject") -> tuple[int, int, int]:
    """Display colour of an object (RGB 0-255), the rule of the reference renderer.

    ``meta["rgb"]`` (the asset's colour), else the segmentation ``color``, else grey.
    """
    rgb = obj.meta.get("rgb") or obj.color or DEFAULT_RGB
    return tuple(int(c) for c in rgb[:3])


def _check_ids(scene: "Scene") -> None:
    if not scene.objects:
        raise InputError(scene.source, "objects", "scene has no objects")
    for i, o in enumerate(scene.objects):
        if o.id in (".", "..", "ground"):
            raise InputError(scene.source, f"objects[{i}].id", f"{o.id!r} cannot be exported (reserved name)")


def _f(x: float) -> str:
    """Shortest exact decimal text of a float (round-trips bit for bit)."""
    return repr(float(x))


def _vec(v) -> str:
    return " ".join(_f(x) for x in np.asarray(v, dtype=float).ravel())


def object_props(scene: "Scene", proxies: dict[str, "Proxy"], sim: SimSettings) -> dict[str, RigidProps]:
    """Mass properties of every object at its pose's scale (:func:`phiscene.inertia.rigid_props`)."""
    out = {}
    for o in scene.objects:
        _, _, scale = decompose(o.pose)
        out[o.id] = rigid_props(o.mesh(), with_base(proxies[o.id], o.base).hulls, sim.density, scale, o.com)
    return out


# -- GLB --------------------------------------------------------------------------------------
def glb_scene(scene: "Scene") -> trimesh.Scene:
    """A :class:`trimesh.Scene` of the objects' visual meshes at their poses, +Y up (see the module notes).

    Returns
    -------
    A scene whose graph is ``world -> z_up_to_y_up -> <object id>``; each object node's
    transform is its pose and its geometry (named by the id) is the local-frame mesh.
    """
    out = trimesh.Scene()
    out.graph.update(frame_from=out.graph.base_frame, frame_to=GLB_ROOT, matrix=Z_UP_TO_Y_UP)
    for o in scene.objects:
        mesh = trimesh.Trimesh(np.asarray(o.mesh().vertices), np.asarray(o.mesh().faces), process=False)
        rgba = [*object_rgb(o), 255]
        mesh.visual = trimesh.visual.TextureVisuals(
            material=trimesh.visual.material.PBRMaterial(name=o.id, baseColorFactor=rgba, metallicFactor=0.0,
                                                         roughnessFactor=0.8))
        out.add_geometry(mesh, node_name=o.id, geom_name=o.id, parent_node_name=GLB_ROOT,
                         transform=np.asarray(o.pose, dtype=float))
    return out


def export_glb(scene: "Scene", path: str | Path) -> Path:
    """Write the scene's visual meshes at their poses as a binary glTF (``.glb``) atomically."""
    _check_ids(scene)
    path = Path(path)
    data = glb_scene(scene).export(file_type="glb")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def read_glb_world_meshes(path: str | Path) -> dict[str, trimesh.Trimesh]:
    """World-frame (+Z up) meshes of a GLB written by :func:`export_glb`, by node name.

    Reads the file with trimesh and undoes the +Y-up root (any other root is left as is).
    """
    loaded = trimesh.load(path, force="scene", process=False)
    to_z_up = Y_UP_TO_Z_UP
    out = {}
    for node in loaded.graph.nodes_geometry:
        transform, geom = loaded.graph[node]
        m = loaded.geometry[geom].copy()
        m.apply_transform(to_z_up @ transform)
        out[node] = m
    return out


# -- URDF -------------------------------------------------------------------------------------
def _contact_xml(link: ET.Element, sim: SimSettings) -> None:
    contact = ET.SubElement(link, "contact")  # pybullet's URDF extension
    for tag, value in (("lateral_friction", sim.friction), ("rolling_friction", sim.rolling_friction),
                       ("spinning_friction", sim.spinning_friction), ("restitution", sim.restitution)):
        ET.SubElement(contact, tag, value=_f(value))


def _xml_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def urdf_text(name: str, visual: str, hulls: list[str], props: RigidProps, rgb, sim: SimSettings) -> str:
    """URDF of one object: a single link ``name`` with inertial, visual and collision elements.

    Parameters
    ----------
    name
        Robot and link name (the object id).
    visual
        Path of the visual mesh, relative to the URDF file, in the link frame (metres).
    hulls
        Paths of the convex proxy meshes, relative to the URDF file, in the link frame.
    props
        Mass properties in the link frame (the scaled local frame).
    rgb
        Colour, 0-255.
    sim
        Surface settings (friction, rolling and spinning friction, restitution).

    Returns
    -------
    The URDF XML text.
    """
    from scipy.spatial.transform import Rotation

    robot = ET.Element("robot", name=name)
    link = ET.SubElement(robot, "link", name=name)
    _contact_xml(link, sim)
    inertial = ET.SubElement(link, "inertial")
    with warnings.catch_warnings():  # gimbal lock (pitch = +-90 deg, common for boxes) still gives a valid triple
        warnings.simplefilter("ignore", UserWarning)
        rpy = Rotation.from_matrix(props.principal_axes).as_euler("xyz")  # extrinsic x-y-z = URDF roll, pitch, yaw
    if not np.allclose(Rotation.from_euler("xyz", rpy).as_matrix(), props.principal_axes, atol=1e-9):
        raise RuntimeError(f"{name}: roll-pitch-yaw {rpy} does not reproduce the principal axes")
    ET.SubElement(inertial, "origin", xyz=_vec(props.com), rpy=_vec(rpy))
    ET.SubElement(inertial, "mass", value=_f(props.mass))
    i1, i2, i3 = (float(v) for v in props.principal_moments)
    ET.SubElement(inertial, "inertia", ixx=_f(i1), ixy="0", ixz="0", iyy=_f(i2), iyz="0", izz=_f(i3))
    vis = ET.SubElement(link, "visual", name=f"{name}_visual")
    ET.SubElement(vis, "origin", xyz="0 0 0", rpy="0 0 0")
    ET.SubElement(ET.SubElement(vis, "geometry"), "mesh", filename=visual)
    mat = ET.SubElement(vis, "material", name=f"{name}_color")
    ET.SubElement(mat, "color", rgba=_vec([c / 255.0 for c in rgb] + [1.0]))
    for k, hull in enumerate(hulls):
        col = ET.SubElement(link, "collision", name=f"{name}_hull{k}")
        ET.SubElement(col, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(ET.SubElement(col, "geometry"), "mesh", filename=hull)
    return _xml_text(robot)


def ground_urdf_text(sim: SimSettings) -> str:
    """URDF of the static ground: a massless slab whose top face is the link's ``z = 0`` plane."""
    from phiscene.render import GROUND_RGB
    from phiscene.sim.bullet import GROUND_HALF_EXTENT, GROUND_HALF_THICKNESS

    robot = ET.Element("robot", name="ground")
    link = ET.SubElement(robot, "link", name="ground")
    _contact_xml(link, sim)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
    ET.SubElement(inertial, "mass", value="0")
    ET.SubElement(inertial, "inertia", ixx="0", ixy="0", ixz="0", iyy="0", iyz="0", izz="0")
    size = _vec([2 * GROUND_HALF_EXTENT, 2 * GROUND_HALF_EXTENT, 2 * GROUND_HALF_THICKNESS])
    for tag in ("visual", "collision"):
        el = ET.SubElement(link, tag, name=f"ground_{tag}")
        ET.SubElement(el, "origin", xyz=_vec([0, 0, -GROUND_HALF_THICKNESS]), rpy="0 0 0")
        ET.SubElement(ET.SubElement(el, "geometry"), "box", size=size)
        if tag == "visual":
            mat = ET.SubElement(el, "material", name="ground_color")
            ET.SubElement(mat, "color", rgba=_vec([*GROUND_RGB, 1.0]))
    return _xml_text(robot)


def _obj_text(mesh: trimesh.Trimesh) -> str:
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_color=False,
                                           include_texture=False, write_texture=False, header=None, digits=9)


def export_urdf(scene: "Scene", proxies: dict[str, "Proxy"], out_dir: str | Path, sim: SimSettings,
                props: dict[str, RigidProps] | None = None, support_graph: str | None = None) -> Path:
    """Write one URDF per object, their meshes, a ground URDF and the scene index ``scene_urdf.json``.

    Parameters
    ----------
    scene
        Objects at their (settled) poses; the ground at ``scene.ground_height``.
    proxies
        Convex proxies by object id (unscaled local hull vertices).
    out_dir
        Export folder.
    sim
        Density (mass properties), surface settings, world settings.
    props
        Mass properties by id (computed when omitted).
    support_graph
        File name of the support graph sidecar, recorded in the index.

    Returns
    -------
    The path of ``scene_urdf.json``.
    """
    _check_ids(scene)
    check_proxies(scene, proxies)
    out_dir = Path(out_dir)
    props = props or object_props(scene, proxies, sim)
    write_text(out_dir / "urdf" / "ground.urdf", ground_urdf_text(sim))
    objects = []
    for o in scene.objects:
        R, t, scale = decompose(o.pose)
        mesh_dir = out_dir / "meshes" / o.id
        visual = o.mesh().copy()
        visual.apply_scale(scale)
        write_text(mesh_dir / "visual.obj", _obj_text(visual))
        hull_names = []
        for k, h in enumerate(with_base(proxies[o.id], o.base).hulls):
            hull = trimesh.convex.convex_hull(np.asarray(h, dtype=float) * scale)
            with atomic_path(mesh_dir / f"hull_{k}.stl") as tmp:
                tmp.write_bytes(trimesh.exchange.stl.export_stl(hull))
            hull_names.append(f"../meshes/{o.id}/hull_{k}.stl")
        p = props[o.id]
        write_text(out_dir / "urdf" / f"{o.id}.urdf",
                   urdf_text(o.id, f"../meshes/{o.id}/visual.obj", hull_names, p, object_rgb(o), sim))
        objects.append({"id": o.id, "urdf": f"urdf/{o.id}.urdf", "position": t.tolist(),
                        "orientation_xyzw": matrix_to_quat_xyzw(R).tolist(), "scale": scale,
                        "mass": p.mass, "com_local": p.com.tolist(), "n_hulls": len(hull_names),
                        "description": o.description, "fixed": o.attached is not None})
    index = {
        "format": URDF_SCENE_FORMAT, "units": "m", "up": [0, 0, 1],
        "how_to_load": "pybullet: loadURDF(ground.urdf, ground.position, useFixedBase=True), the same for each "
                       "structure entry (walls, ceiling) at its position and orientation_xyzw; per object "
                       "loadURDF(urdf, position, orientation_xyzw, useFixedBase=fixed, "
                       "flags=URDF_USE_INERTIA_FROM_FILE), then changeDynamics(uid, -1, **dynamics); positions are "
                       "link frames (not centres of mass)",
        "gravity": [0.0, 0.0, -GRAVITY],
        "physics": {"time_step": sim.frame_dt / sim.substeps, "frame_dt": sim.frame_dt, "substeps": sim.substeps,
                    "solver_iterations": sim.solver_iterations},
        "load_flags": ["URDF_USE_INERTIA_FROM_FILE"],
        "contact": {"lateral_friction": sim.friction, "rolling_friction": sim.rolling_friction,
                    "spinning_friction": sim.spinning_friction, "restitution": sim.restitution},
        "dynamics": {"linear_damping": sim.linear_damping, "angular_damping": sim.angular_damping,
                     "collision_margin": sim.collision_margin},
        "ground": {"urdf": "urdf/ground.urdf", "position": [0.0, 0.0, float(scene.ground_height)],
                   "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], "fixed": True},
        "objects": objects,
    }
    if scene.structure:
        index["structure"] = [_plane_entry(q) for q in scene.structure]
    if support_graph:
        index["support_graph"] = support_graph
    path = out_dir / FILES["urdf_index"]
    write_json(path, index)
    return path


def _plane_entry(plane) -> dict:
    """Index entry of a wall or ceiling (:class:`phiscene.scene.Plane`): the ground slab's URDF (top face at its
    link's ``z = 0``) posed so that its top face is the plane (:meth:`phiscene.scene.Plane.frame`)."""
    frame = plane.frame()
    return {"id": plane.id, "kind": plane.kind, "estimated": bool(plane.estimated), "urdf": "urdf/ground.urdf",
            "position": frame[:3, 3].tolist(), "orientation_xyzw": matrix_to_quat_xyzw(frame[:3, :3]).tolist(),
            "fixed": True}


def read_urdf_index(path: str | Path) -> dict:
    """Load a ``scene_urdf.json`` (InputError naming the file and field on problems)."""
    from phiscene.schemas import read_json

    index = read_json(path)
    if not isinstance(index, dict) or index.get("format") != URDF_SCENE_FORMAT:
        raise InputError(path, "format", f"expected {URDF_SCENE_FORMAT!r}")
    for key in ("gravity", "physics", "dynamics", "ground", "objects"):
        if key not in index:
            raise InputError(path, key, "missing")
    for i, o in enumerate(index["objects"]):
        for key in ("id", "urdf", "position", "orientation_xyzw"):
            if key not in o:
                raise InputError(path, f"objects[{i}].{key}", "missing")
        if not (Path(path).parent / o["urdf"]).is_file():
            raise InputError(path, f"objects[{i}].urdf", f"file not found: {o['urdf']}")
    return index


def load_urdf_scene(index_path: str | Path, client) -> dict[str, int]:
    """Load an exported URDF scene into a fresh pybullet client (:func:`phiscene.sim.bullet.open_client`).

    Sets gravity, the time step and solver iterations, loads the ground (fixed)
    and every object URDF at its index pose with ``URDF_USE_INERTIA_FROM_FILE`` (an attached object, ``fixed`` in
    the index, with a fixed base),
    and applies the index's damping and collision margin.

    Returns
    -------
    ``{id: body unique id}``, the ground under ``"ground"``, each wall or ceiling under its plane id.
    """
    from phiscene.sim.bullet import configure_engine

    index_path = Path(index_path)
    index = read_urdf_index(index_path)
    root = index_path.parent
    ph = index["physics"]
    configure_engine(client, ph["time_step"], ph["solver_iterations"], index["gravity"])
    g = index["ground"]
    uids = {"ground": client.loadURDF(str(root / g["urdf"]), g["position"], g["orientation_xyzw"],
                                      useFixedBase=True)}
    for q in index.get("structure", []):  # walls and ceiling: the ground slab, posed
        uids[q["id"]] = client.loadURDF(str(root / q["urdf"]), q["position"], q["orientation_xyzw"],
                                        useFixedBase=True)
    dyn = index["dynamics"]
    for i, o in enumerate(index["objects"]):
        try:
            uid = client.loadURDF(str(root / o["urdf"]), o["position"], o["orientation_xyzw"],
                                  useFixedBase=bool(o.get("fixed", False)), flags=client.URDF_USE_INERTIA_FROM_FILE)
        except client.error as exc:
            raise InputError(index_path, f"objects[{i}].urdf", f"pybullet cannot load it ({exc})") from None
        client.changeDynamics(uid, -1, linearDamping=dyn["linear_damping"], angularDamping=dyn["angular_damping"],
                              collisionMargin=dyn["collision_margin"])
        uids[o["id"]] = uid
    return uids


# -- MJCF -------------------------------------------------------------------------------------
def mjcf_spec(scene: "Scene", proxies: dict[str, "Proxy"], sim: SimSettings,
              mj: "MujocoParams | None" = None) -> "mujoco.MjSpec":
    """The exported MuJoCo model: :func:`~phiscene.sim.mujoco.build_spec` plus visuals (module notes).

    Parameters
    ----------
    scene
        Objects at their poses; the ground plane at ``scene.ground_height``.
    proxies
        Convex proxies by object id.
    sim, mj
        Shared and MuJoCo-specific settings.

    Returns
    -------
    An uncompiled ``mujoco.MjSpec`` whose free joints carry no damping.
    """
    import mujoco

    from phiscene.render import GROUND_RGB
    from phiscene.sim.mujoco import GROUND_NAME, build_spec

    _check_ids(scene)
    spec = build_spec(scene, proxies, sim, float(scene.ground_height), mj)
    spec.modelname = "phiscene_scene"
    tex = spec.add_texture()
    tex.name = "floor"
    tex.type = mujoco.mjtTexture.mjTEXTURE_2D
    tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_CHECKER
    tex.rgb1 = list(GROUND_RGB)
    tex.rgb2 = [c * 0.85 for c in GROUND_RGB]
    tex.width = tex.height = 256
    mat = spec.add_material()
    mat.name = "floor"
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor"
    mat.texrepeat = [4.0, 4.0]
    mat.texuniform = True
    spec.geom(GROUND_NAME).material = "floor"
    light = spec.worldbody.add_light()
    light.name = "sun"
    light.pos = [0.0, 0.0, float(scene.ground_height) + 5.0]
    light.dir = [0.0, 0.0, -1.0]
    for o in scene.objects:
        body = spec.body(o.id)
        rgba = [c / 255.0 for c in object_rgb(o)] + [1.0]
        for joint in body.joints:
            joint.damping = np.zeros_like(np.asarray(joint.damping)) if isinstance(joint.damping, np.ndarray) else 0.0
        link_pos = link_quat = None
        for geom in body.geoms:
            geom.group = MJ_COLLISION_GROUP
            geom.rgba = rgba
            if link_pos is None:
                link_pos, link_quat = np.array(geom.pos), np.array(geom.quat)
        _, _, scale = decompose(o.pose)
        mesh = spec.add_mesh()
        mesh.name = f"{o.id}/visual"
        mesh.uservert = np.asarray(o.mesh().vertices, dtype=float).ravel()
        mesh.userface = np.asarray(o.mesh().faces, dtype=np.int32).ravel()
        mesh.scale = [scale] * 3
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # robust for open meshes; mass is explicit
        geom = body.add_geom()
        geom.name = f"{o.id}/visual"
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = mesh.name
        geom.pos, geom.quat = link_pos, link_quat  # the hulls' frame: the object's link frame
        geom.contype = geom.conaffinity = 0
        geom.group = MJ_VISUAL_GROUP
        geom.rgba = rgba
    return spec


def export_mjcf(scene: "Scene", proxies: dict[str, "Proxy"], path: str | Path, sim: SimSettings,
                mj: "MujocoParams | None" = None) -> Path:
    """Write :func:`mjcf_spec` as one self-contained MJCF file (meshes inline) atomically.

    Raises
    ------
    RuntimeError
        MuJoCo cannot compile the model (the message names the element).
    """
    from phiscene.sim.mujoco import compile_model, write_mjcf

    check_proxies(scene, proxies)
    spec = mjcf_spec(scene, proxies, sim, mj)
    compile_model(spec, sim)  # fail here, with MuJoCo's message, rather than in the user's viewer
    return write_mjcf(spec, path)


# -- support graph ----------------------------------------------------------------------------
def export_support_graph(graph: "SupportGraph", scene: "Scene", path: str | Path) -> Path:
    """Write the full support graph (all parents of every object) as ``phiscene.topology/1``.

    ``meta.urdf`` maps each object id to its URDF file (``urdf/<id>.urdf``);
    ``meta.parents`` lists each object's supporters (the URDF tree cannot hold them).

    Raises
    ------
    InputError
        The graph's objects are not the scene's.
    """
    from dataclasses import replace

    from phiscene import topology

    if set(graph.object_ids) != set(scene.ids):
        raise InputError(scene.source, "objects", f"support graph objects {sorted(graph.object_ids)} are not "
                         f"the scene's {sorted(scene.ids)}")
    meta = {**graph.meta, "urdf": {oid: f"urdf/{oid}.urdf" for oid in scene.ids},
            "parents": {oid: graph.parents(oid) for oid in scene.ids}}
    path = Path(path)
    topology.save(replace(graph, meta=meta), path)
    return path


# -- everything -------------------------------------------------------------------------------
def export_scene(scene: "Scene", proxies: dict[str, "Proxy"], out_dir: str | Path, sim: SimSettings,
                 mj: "MujocoParams | None" = None, graph: "SupportGraph | None" = None) -> dict:
    """Write GLB, URDF scene, MJCF and support graph of one scene into ``out_dir`` (module notes).

    Parameters
    ----------
    scene
        The settled scene.
    proxies
        Convex proxies by object id.
    out_dir
        Export folder (created; an existing ``urdf/`` and ``meshes/`` are replaced).
    sim, mj
        Simulation settings shared by all engines, and MuJoCo's contact/solver settings.
    graph
        Support graph; without it no ``support_graph.json`` is written.

    Returns
    -------
    The manifest written to ``export.json``: ``files`` (name -> relative path), ``objects``, ``sim``,
    ``mujoco``, ``masses`` (kg by id).
    """
    from phiscene.sim.mujoco import MujocoParams

    _check_ids(scene)
    check_proxies(scene, proxies)
    mj = mj or MujocoParams()
    out_dir = Path(out_dir)
    for sub in ("urdf", "meshes"):  # stale per-object files of an earlier export
        if (out_dir / sub).is_dir():
            shutil.rmtree(out_dir / sub)
    props = object_props(scene, proxies, sim)
    from phiscene.io.usd import export_usd

    files = {"glb": FILES["glb"], "mjcf": FILES["mjcf"], "urdf_index": FILES["urdf_index"], "usd": FILES["usd"]}
    export_glb(scene, out_dir / FILES["glb"])
    if graph is not None:
        export_support_graph(graph, scene, out_dir / FILES["support_graph"])
        files["support_graph"] = FILES["support_graph"]
    export_urdf(scene, proxies, out_dir, sim, props, files.get("support_graph"))
    export_mjcf(scene, proxies, out_dir / FILES["mjcf"], sim, mj)
    export_usd(scene, proxies, out_dir / FILES["usd"], sim, graph, props)
    manifest = {"format": EXPORT_FORMAT, "files": files, "objects": scene.ids,
                "urdf": {o.id: f"urdf/{o.id}.urdf" for o in scene.objects},
                "masses": {oid: p.mass for oid, p in props.items()}, "ground_height": float(scene.ground_height),
                "sim": sim.to_dict(), "mujoco": mj.to_dict(),
                "glb_up": "+Y (root node z_up_to_y_up rotates phiscene's +Z up to glTF's +Y up)"}
    write_json(out_dir / FILES["manifest"], manifest)
    return manifest


# -- round trip -------------------------------------------------------------------------------
@dataclass(frozen=True)
class RoundTripTolerance:
    """Largest allowed difference between an export's drift and the pipeline's.

    Attributes
    ----------
    trans
        Metres (per object).
    rot
        Degrees (per object).
    """

    trans: float = 0.002
    rot: float = 1.0


def _drift(start: dict[str, np.ndarray], end: dict[str, np.ndarray], offset: float) -> dict:
    per = {}
    for oid in start:
        com0 = start[oid][:3, 3] - [0.0, 0.0, offset]
        per[oid] = {"drift_trans": float(np.linalg.norm(end[oid][:3, 3] - com0)),
                    "drift_rot": math.degrees(rotation_angle(start[oid][:3, :3], end[oid][:3, :3]))}
    return {"drift_trans": float(np.mean([v["drift_trans"] for v in per.values()])),
            "drift_rot": float(np.mean([v["drift_rot"] for v in per.values()])), "objects": per}


def release_urdf(index_path: str | Path, seconds: float, upward_offset: float = 0.0) -> dict:
    """Drift of an exported URDF scene released in a fresh pybullet world.

    Every object is lifted by ``upward_offset``, the world runs ``seconds``
    (rounded to whole time steps), and the drift is measured as in
    :func:`phiscene.metrics.drift.drift_bullet`: centre of mass from before
    the lift, rotation angle in degrees.

    Returns
    -------
    ``{"drift_trans": mean m, "drift_rot": mean deg, "steps": int, "objects": {id: {...}}}``
    """
    from phiscene.sim.bullet import open_client

    client = open_client()
    try:
        uids = load_urdf_scene(index_path, client)
        index = read_urdf_index(index_path)
        fixed = {"ground", *(q["id"] for q in index.get("structure", [])),
                 *(o["id"] for o in index["objects"] if o.get("fixed"))}
        bodies = {k: v for k, v in uids.items() if k not in fixed}
        time_step = index["physics"]["time_step"]

        def poses() -> dict[str, np.ndarray]:
            out = {}
            for oid, uid in bodies.items():
                pos, quat = client.getBasePositionAndOrientation(uid)
                out[oid] = make_pose(quat_xyzw_to_matrix(quat), pos)
            return out

        for uid in bodies.values():
            pos, quat = client.getBasePositionAndOrientation(uid)
            client.resetBasePositionAndOrientation(uid, [pos[0], pos[1], pos[2] + upward_offset], quat)
        start = poses()
        steps = int(round(seconds / time_step))
        for _ in range(steps):
            client.stepSimulation()
        end = poses()
    finally:
        client.disconnect()
    return {**_drift(start, end, upward_offset), "steps": steps}


def release_mjcf(xml_path: str | Path, seconds: float, upward_offset: float = 0.0) -> dict:
    """Drift of an exported MJCF scene loaded with ``mujoco.MjModel.from_xml_path`` and released.

    Every free body is lifted by ``upward_offset``; the model runs ``seconds``
    (whole time steps of the file's ``timestep``); drift as in :func:`release_urdf`.

    Returns
    -------
    ``{"drift_trans": mean m, "drift_rot": mean deg, "steps": int, "objects": {body name: {...}}}``
    """
    import mujoco

    from phiscene.sim.mujoco import body_poses, check_warnings

    try:
        model = mujoco.MjModel.from_xml_path(str(xml_path))
    except ValueError as exc:
        raise InputError(xml_path, None, f"MuJoCo cannot load it ({' '.join(str(exc).split())})") from None
    data = mujoco.MjData(model)
    names = []
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            data.qpos[model.jnt_qposadr[j] + 2] += upward_offset
            names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.jnt_bodyid[j]))
    mujoco.mj_forward(model, data)
    start = body_poses(model, data, names)
    steps = int(round(seconds / model.opt.timestep))
    mujoco.mj_step(model, data, nstep=steps)
    check_warnings(data)
    end = body_poses(model, data, names)
    return {**_drift(start, end, upward_offset), "steps": steps}


def _free(drift: dict) -> dict:
    """A pipeline drift result with its attached (static) objects left out, as every export releases them fixed."""
    return {**drift, "objects": {k: v for k, v in drift["objects"].items() if "attached" not in v}}


def _compare(export: dict, pipeline: dict, tol: RoundTripTolerance) -> dict:
    """Per-object drift differences of an export against the pipeline's free objects; one the export does not
    release is listed in ``missing`` and fails the check."""
    ours = {oid: v for oid, v in pipeline["objects"].items() if oid in export["objects"]}
    dt = {oid: abs(export["objects"][oid]["drift_trans"] - v["drift_trans"]) for oid, v in ours.items()}
    dr = {oid: abs(export["objects"][oid]["drift_rot"] - v["drift_rot"]) for oid, v in ours.items()}
    missing = sorted(set(pipeline["objects"]) - set(ours))
    max_t, max_r = max(dt.values(), default=0.0), max(dr.values(), default=0.0)
    return {"export": export, "pipeline": {k: pipeline[k] for k in ("drift_trans", "drift_rot", "objects")},
            "max_diff_trans": max_t, "max_diff_rot": max_r,
            "mean_diff_trans": abs(export["drift_trans"] - pipeline["drift_trans"]),
            "mean_diff_rot": abs(export["drift_rot"] - pipeline["drift_rot"]), "missing": missing,
            "ok": bool(not missing and max_t <= tol.trans and max_r <= tol.rot)}


def roundtrip_check(export_dir: str | Path, scene: "Scene", proxies: dict[str, "Proxy"], params, sim: SimSettings,
                    cache_dir: str | Path, mj: "MujocoParams | None" = None,
                    tol: RoundTripTolerance = RoundTripTolerance()) -> dict:
    """Release the exported files in fresh worlds and compare with the pipeline's drift.

    The URDF scene goes into a fresh pybullet client (:func:`release_urdf`),
    the MJCF into MuJoCo from the file (:func:`release_mjcf`), the USD stage, read back with ``pxr``, into
    another fresh pybullet world (:func:`phiscene.io.usd.release_usd`), each for
    ``params.frames * sim.frame_dt`` seconds after a lift of
    ``params.upward_offset``; the pipeline's drifts are
    :func:`phiscene.metrics.drift.drift_bullet` and
    :func:`phiscene.metrics.drift.drift_mujoco` of the same scene and proxies.

    Parameters
    ----------
    params
        Drift protocol (``upward_offset``, ``frames``), e.g. ``PhysicalParams``.

    Returns
    -------
    ``{"seconds", "tolerance": {"trans", "rot"}, "pybullet": {...}, "mujoco": {...}, "ok"}`` where each
    engine entry has ``export``, ``pipeline``, ``max_diff_trans`` (m), ``max_diff_rot`` (deg), ``ok``.
    """
    from phiscene.io.usd import release_usd
    from phiscene.metrics.drift import drift_bullet, drift_mujoco

    export_dir = Path(export_dir)
    seconds = int(params.frames) * sim.frame_dt
    offset = float(params.upward_offset)
    pipeline = _free(drift_bullet(scene, proxies, params, sim, cache_dir))
    bullet = _compare(release_urdf(export_dir / FILES["urdf_index"], seconds, offset), pipeline, tol)
    mjc = _compare(release_mjcf(export_dir / FILES["mjcf"], seconds, offset),
                   _free(drift_mujoco(scene, proxies, params, sim, mj)), tol)
    out = {"seconds": seconds, "upward_offset": offset, "tolerance": {"trans": tol.trans, "rot": tol.rot},
           "pybullet": bullet, "mujoco": mjc}
    if (export_dir / FILES["usd"]).is_file():
        out["usd"] = _compare(release_usd(export_dir / FILES["usd"], seconds, offset, cache_dir, sim), pipeline, tol)
    out["ok"] = all(out[e]["ok"] for e in ("pybullet", "mujoco", "usd") if e in out)
    return out


# -- file level -------------------------------------------------------------------------------
def run_export(scene_path: str | Path, proxies_path: str | Path, out_dir: str | Path, sim: dict,
               mujoco: dict | None = None, topology_path: str | Path | None = None,
               physical: dict | None = None, cache_dir: str | Path | None = None) -> dict:
    """Export one ``scene.json`` (path in, files out); optionally run and record the round-trip check.

    Parameters
    ----------
    scene_path, proxies_path
        The settled scene and its proxies ``.npz``.
    out_dir
        Export folder.
    sim, mujoco
        Config mappings of :class:`SimSettings` and :class:`~phiscene.sim.mujoco.MujocoParams`.
    topology_path
        Support graph to write as ``support_graph.json``.
    physical
        Drift protocol mapping (:class:`~phiscene.metrics.physical.PhysicalParams`); when given, the
        round-trip check runs and is written to ``roundtrip.json`` and the manifest.
    cache_dir
        Cache folder for the pipeline's pybullet hull files (round-trip check only).

    Returns
    -------
    The manifest.
    """
    import logging

    from phiscene import topology
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.proxies import read_proxies
    from phiscene.scene import load_scene
    from phiscene.sim.mujoco import MujocoParams

    log = logging.getLogger(__name__)
    scene = load_scene(scene_path)
    proxies = read_proxies(proxies_path)
    simset, mj = SimSettings.from_dict(sim), MujocoParams.from_dict(mujoco)
    graph = topology.load(topology_path, scene_ids=scene.ids) if topology_path else None
    from phiscene.io.usd import validate_usd

    manifest = export_scene(scene, proxies, out_dir, simset, mj, graph)
    manifest["usd_validation_errors"] = validate_usd(Path(out_dir) / FILES["usd"])
    for message in manifest["usd_validation_errors"]:
        log.warning("USD validator: %s", message)
    write_json(Path(out_dir) / FILES["manifest"], manifest)
    log.info("exported %d objects to %s", len(scene.objects), out_dir)
    if physical is not None:
        check = roundtrip_check(out_dir, scene, proxies, PhysicalParams.from_dict(physical), simset,
                                cache_dir or Path(out_dir) / ".cache", mj)
        write_json(Path(out_dir) / "roundtrip.json", check)
        for engine in [e for e in ("pybullet", "mujoco", "usd") if e in check]:
            c = check[engine]
            log.info("round trip %s: export drift %.5f m / %.3f deg, pipeline %.5f m / %.3f deg, max diff %.5f m / "
                     "%.3f deg (%s)", engine, c["export"]["drift_trans"], c["export"]["drift_rot"],
                     c["pipeline"]["drift_trans"], c["pipeline"]["drift_rot"], c["max_diff_trans"], c["max_diff_rot"],
                     "ok" if c["ok"] else "OUTSIDE TOLERANCE")
        manifest["files"]["roundtrip"] = "roundtrip.json"
        manifest["roundtrip_ok"] = check["ok"]
        write_json(Path(out_dir) / FILES["manifest"], manifest)
    return manifest
