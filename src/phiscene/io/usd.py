"""OpenUSD export of a settled scene with UsdPhysics, and reading it back (Isaac Sim, Omniverse, usdview).

:func:`export_usd` writes one ``scene.usda``::

    /World                         default prim (Xform); stage: Z up, 1 metre per unit, 1 kg per unit
    /World/PhysicsScene            UsdPhysics.Scene: gravity direction (0, 0, -1), magnitude 9.81 m/s^2
    /World/Looks/PhysicsMaterial   UsdShade.Material + UsdPhysics.MaterialAPI: static/dynamic friction,
                                   restitution (SimSettings), bound with the "physics" purpose
    /World/Ground                  UsdGeom.Plane (axis Z) at the ground height, static collider
    /World/Structure/<name>        UsdGeom.Plane per wall or ceiling of the scene (its local +z the plane's normal,
                                   into the room), static collider; customData ``phiscene:id``, ``phiscene:kind``,
                                   ``phiscene:estimated``
    /World/Objects/<name>          Xform at the object's settled pose (translate + orient: the pose's uniform
                                   scale is baked into the points below, so mass properties need no rescaling)
        visual                     UsdGeom.Mesh, the object's mesh, displayColor from its colour
        collision_<k>              UsdGeom.Mesh per convex proxy, purpose "guide", CollisionAPI +
                                   MeshCollisionAPI (approximation "convexHull")

A free object's Xform has ``RigidBodyAPI`` and ``MassAPI`` (mass, centerOfMass, diagonalInertia and
principalAxes from :func:`phiscene.inertia.rigid_props`, the values the URDF export writes). An attached object
(fixed to a wall or the ceiling, :attr:`phiscene.scene.SceneObject.attached`) has colliders and no rigid body: a
static collider, as UsdPhysics defines one. Prim names are the object ids made valid identifiers; the id itself is
in each prim's ``customData`` (``phiscene:id``), with its supporters (``phiscene:supporters``), and the full support
graph and the world settings are JSON strings in the layer's ``customLayerData`` (``phiscene:support_graph``,
``phiscene:sim``).

:func:`read_usd_scene` reads a stage back with ``pxr`` (poses, masses, inertia, hull vertices, static flags, units);
:func:`release_usd` rebuilds a fresh pybullet world from what it read and measures the drift with the protocol of
:func:`phiscene.metrics.drift.drift_bullet`; :func:`validate_usd` runs USD's own validators (``UsdValidation``,
the UsdPhysics ones included).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from phiscene.atomic import atomic_path
from phiscene.errors import InputError
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, make_pose, matrix_to_quat_wxyz, quat_wxyz_to_matrix, rotation_angle

if TYPE_CHECKING:
    from phiscene.inertia import RigidProps
    from phiscene.proxies import Proxy
    from phiscene.scene import Scene
    from phiscene.topology.graph import SupportGraph

#: Gravity magnitude written to the physics scene (m/s^2); the pipeline's worlds use the same.
GRAVITY = 9.81
#: Prim paths of the stage.
WORLD, OBJECTS, GROUND_PRIM, MATERIAL, PHYSICS_SCENE, STRUCTURE = (
    "/World", "/World/Objects", "/World/Ground", "/World/Looks/PhysicsMaterial", "/World/PhysicsScene",
    "/World/Structure")
#: Half size (m) of the ground plane's visible extent (a UsdGeom.Plane collider is infinite).
GROUND_EXTENT = 50.0


def _prim_name(oid: str) -> str:
    from pxr import Tf

    return Tf.MakeValidIdentifier(oid)


def _mesh_prim(stage, path: str, vertices: np.ndarray, faces: np.ndarray):
    from pxr import Gf, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    v = np.asarray(vertices, dtype=float)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in np.asarray(faces).ravel()]))
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, v.min(axis=0))), Gf.Vec3f(*map(float, v.max(axis=0)))]))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    return mesh


def _physics_material(stage, sim: SimSettings):
    from pxr import UsdPhysics, UsdShade

    mat = UsdShade.Material.Define(stage, MATERIAL)
    api = UsdPhysics.MaterialAPI.Apply(mat.GetPrim())
    api.CreateStaticFrictionAttr(float(sim.friction))
    api.CreateDynamicFrictionAttr(float(sim.friction))
    api.CreateRestitutionAttr(float(sim.restitution))
    return mat


def _bind(prim, mat) -> None:
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat, UsdShade.Tokens.weakerThanDescendants,
                                                  "physics")


def _collider(prim, mat, approximation: str | None = "convexHull") -> None:
    from pxr import UsdPhysics

    UsdPhysics.CollisionAPI.Apply(prim)
    if approximation is not None:
        UsdPhysics.MeshCollisionAPI.Apply(prim).CreateApproximationAttr(approximation)
    _bind(prim, mat)


def export_usd(scene: "Scene", proxies: dict[str, "Proxy"], path: str | Path, sim: SimSettings,
               graph: "SupportGraph | None" = None, props: dict[str, "RigidProps"] | None = None) -> Path:
    """Write a settled scene as a UsdPhysics stage (module docstring), atomically.

    Parameters
    ----------
    scene
        The settled scene.
    proxies
        Convex proxies by object id (collision meshes).
    path
        The ``.usda`` (text) or ``.usdc`` (binary) file to write.
    sim
        World settings (friction, restitution, density for the mass properties).
    graph
        Support graph to store as custom data (optional).
    props
        Mass properties by id (default :func:`phiscene.io.export.object_props`).

    Returns
    -------
    The written path.
    """
    from pxr import Gf, Usd, UsdGeom, UsdPhysics, Vt

    from phiscene.io.export import _check_ids, object_props, object_rgb
    from phiscene.proxies import check_proxies, with_base

    _check_ids(scene)
    check_proxies(scene, proxies)
    props = props or object_props(scene, proxies, sim)
    path = Path(path)
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, WORLD)
    stage.SetDefaultPrim(world.GetPrim())
    physics = UsdPhysics.Scene.Define(stage, PHYSICS_SCENE)
    physics.CreateGravityDirectionAttr(Gf.Vec3f(0.0, 0.0, -1.0))
    physics.CreateGravityMagnitudeAttr(GRAVITY)
    UsdGeom.Scope.Define(stage, "/World/Looks")
    mat = _physics_material(stage, sim)

    ground = _plane_prim(stage, GROUND_PRIM, mat)
    ground.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, float(scene.ground_height)))
    if scene.structure:
        _structure(stage, scene.structure, mat)

    UsdGeom.Scope.Define(stage, OBJECTS)
    names: dict[str, str] = {}
    supporters = {}
    if graph is not None:
        for e in graph.edges:
            supporters.setdefault(e.target, []).append(e.source)
    for o in scene.objects:
        name = _prim_name(o.id)
        if name in names.values():
            name = f"{name}_{len(names)}"
        names[o.id] = name
        base = f"{OBJECTS}/{name}"
        R, t, s = decompose(o.pose)
        xf = UsdGeom.Xform.Define(stage, base)
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, t)))
        w, x, y, z = matrix_to_quat_wxyz(R)
        xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(float(w), Gf.Vec3d(float(x), float(y), float(z))))
        prim = xf.GetPrim()
        prim.SetCustomDataByKey("phiscene:id", o.id)
        prim.SetCustomDataByKey("phiscene:supporters", Vt.StringArray(supporters.get(o.id, [])))
        if o.attached is not None:
            prim.SetCustomDataByKey("phiscene:attached", o.attached)
        mesh = o.mesh()
        visual = _mesh_prim(stage, f"{base}/visual", np.asarray(mesh.vertices) * s, mesh.faces)
        rgb = [c / 255.0 for c in object_rgb(o)]
        visual.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*rgb)]))
        for k, hull_vertices in enumerate(with_base(proxies[o.id], o.base).hulls):
            hull = trimesh.convex.convex_hull(np.asarray(hull_vertices, dtype=float) * s)
            col = _mesh_prim(stage, f"{base}/collision_{k}", hull.vertices, hull.faces)
            col.CreatePurposeAttr(UsdGeom.Tokens.guide)
            _collider(col.GetPrim(), mat)
        if o.attached is None:
            UsdPhysics.RigidBodyAPI.Apply(prim)
            p = props[o.id]
            mass = UsdPhysics.MassAPI.Apply(prim)
            mass.CreateMassAttr(float(p.mass))
            mass.CreateCenterOfMassAttr(Gf.Vec3f(*map(float, p.com)))
            mass.CreateDiagonalInertiaAttr(Gf.Vec3f(*map(float, p.principal_moments)))
            qw, qx, qy, qz = matrix_to_quat_wxyz(np.asarray(p.principal_axes, dtype=float))
            mass.CreatePrincipalAxesAttr(Gf.Quatf(float(qw), Gf.Vec3f(float(qx), float(qy), float(qz))))
    layer_data = {"phiscene:sim": json.dumps(sim.to_dict(), sort_keys=True),
                  "phiscene:objects": json.dumps(names, sort_keys=True)}
    if graph is not None:
        layer_data["phiscene:support_graph"] = json.dumps(
            {"edges": [{"from": e.source, "to": e.target, "relation": e.relation, "confidence": e.confidence}
                       for e in graph.edges], "order": list(graph.order)}, sort_keys=True)
    stage.GetRootLayer().customLayerData = layer_data
    with atomic_path(path) as tmp:
        tmp_usd = Path(str(tmp) + path.suffix)  # USD picks the file format from the suffix
        if not stage.GetRootLayer().Export(str(tmp_usd)):
            raise OSError(f"USD could not write {path}")
        tmp_usd.replace(tmp)
    return path


def _plane_prim(stage, path: str, mat):
    """A static UsdGeom.Plane collider (axis Z, :data:`GROUND_EXTENT` each way) at ``path``; the caller poses it."""
    from pxr import UsdGeom

    geom = UsdGeom.Plane.Define(stage, path)
    geom.CreateAxisAttr(UsdGeom.Tokens.z)
    geom.CreateWidthAttr(2 * GROUND_EXTENT)
    geom.CreateLengthAttr(2 * GROUND_EXTENT)
    _collider(geom.GetPrim(), mat, approximation=None)
    return geom


def _structure(stage, planes, mat) -> None:
    """Walls and ceiling (:class:`phiscene.scene.Plane`) as static UsdGeom.Plane colliders under :data:`STRUCTURE`,
    each posed at its plane's :meth:`~phiscene.scene.Plane.frame` (local +z the normal)."""
    from pxr import Gf, UsdGeom

    UsdGeom.Scope.Define(stage, STRUCTURE)
    for plane in planes:
        frame = plane.frame()
        geom = _plane_prim(stage, f"{STRUCTURE}/{_prim_name(plane.id)}", mat)
        geom.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, frame[:3, 3])))
        w, x, y, z = matrix_to_quat_wxyz(frame[:3, :3])
        geom.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(float(w), Gf.Vec3d(float(x), float(y),
                                                                                         float(z))))
        prim = geom.GetPrim()
        prim.SetCustomDataByKey("phiscene:id", plane.id)
        prim.SetCustomDataByKey("phiscene:kind", plane.kind)
        prim.SetCustomDataByKey("phiscene:estimated", bool(plane.estimated))


def _read_structure(stage, time) -> list:
    """The :class:`phiscene.scene.Plane` of every prim under :data:`STRUCTURE` (empty when there is none)."""
    from pxr import UsdGeom

    from phiscene.scene import Plane

    root = stage.GetPrimAtPath(STRUCTURE)
    planes = []
    for prim in (root.GetChildren() if root else []):
        T = _np(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time)).T  # USD: row vectors
        n = T[:3, 2] / np.linalg.norm(T[:3, 2])
        planes.append(Plane(prim.GetCustomDataByKey("phiscene:id") or prim.GetName(),
                            prim.GetCustomDataByKey("phiscene:kind") or "wall", tuple(float(v) for v in n),
                            -float(n @ T[:3, 3]), bool(prim.GetCustomDataByKey("phiscene:estimated"))))
    return planes


def _np(m) -> np.ndarray:
    return np.array([[m[i][j] for j in range(4)] for i in range(4)], dtype=float)


def read_usd_scene(path: str | Path) -> dict:
    """Read a stage written by :func:`export_usd` back into plain arrays.

    Returns
    -------
    ``{"up_axis": str, "meters_per_unit": float, "kilograms_per_unit": float, "gravity": (3,) m/s^2,
    "friction": float, "restitution": float, "ground_height": float, "sim": dict, "support_graph": dict | None,
    "structure": [phiscene.scene.Plane],
    "objects": {id: {"pose": (4, 4) rigid, "static": bool, "mass", "com": (3,), "inertia": (3, 3) about the
    com in the object frame, "hulls": [(v, 3) object-frame vertices], "supporters": [...]}}}``

    Raises
    ------
    InputError
        Not a USD file, or not a phiscene stage.
    """
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    path = Path(path)
    stage = Usd.Stage.Open(str(path)) if path.is_file() else None
    if stage is None:
        raise InputError(path, None, "cannot open as a USD stage")
    if not stage.GetPrimAtPath(OBJECTS):
        raise InputError(path, OBJECTS, "no objects prim: not a phiscene export")
    time = Usd.TimeCode.Default()
    physics = UsdPhysics.Scene(stage.GetPrimAtPath(PHYSICS_SCENE))
    g_dir = np.array(physics.GetGravityDirectionAttr().Get(), dtype=float)
    mat = UsdPhysics.MaterialAPI(stage.GetPrimAtPath(MATERIAL))
    data = stage.GetRootLayer().customLayerData
    out = {"up_axis": str(UsdGeom.GetStageUpAxis(stage)), "meters_per_unit": UsdGeom.GetStageMetersPerUnit(stage),
           "kilograms_per_unit": UsdPhysics.GetStageKilogramsPerUnit(stage),
           "gravity": g_dir * float(physics.GetGravityMagnitudeAttr().Get()),
           "friction": float(mat.GetDynamicFrictionAttr().Get()),
           "restitution": float(mat.GetRestitutionAttr().Get()),
           "ground_height": float(_np(UsdGeom.Xformable(stage.GetPrimAtPath(GROUND_PRIM))
                                      .ComputeLocalToWorldTransform(time))[3, 2]),
           "sim": json.loads(data["phiscene:sim"]) if "phiscene:sim" in data else None,
           "support_graph": json.loads(data["phiscene:support_graph"]) if "phiscene:support_graph" in data else None,
           "structure": _read_structure(stage, time), "objects": {}}
    for prim in stage.GetPrimAtPath(OBJECTS).GetChildren():
        oid = prim.GetCustomDataByKey("phiscene:id") or prim.GetName()
        pose = _np(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time)).T  # USD: row vectors
        hulls = []
        for child in prim.GetChildren():
            if child.HasAPI(UsdPhysics.CollisionAPI) and child.IsA(UsdGeom.Mesh):
                bound = UsdShade.MaterialBindingAPI(child).ComputeBoundMaterial("physics")[0]
                if not bound or bound.GetPath() != mat.GetPrim().GetPath():
                    raise InputError(path, str(child.GetPath()), "collider without the physics material")
                hulls.append(np.array(UsdGeom.Mesh(child).GetPointsAttr().Get(), dtype=float))
        entry = {"pose": pose, "static": not prim.HasAPI(UsdPhysics.RigidBodyAPI), "hulls": hulls,
                 "supporters": list(prim.GetCustomDataByKey("phiscene:supporters") or []),
                 "attached": prim.GetCustomDataByKey("phiscene:attached")}
        if not entry["static"]:
            m = UsdPhysics.MassAPI(prim)
            q = m.GetPrincipalAxesAttr().Get()
            axes = quat_wxyz_to_matrix([q.GetReal(), *q.GetImaginary()])
            moments = np.array(m.GetDiagonalInertiaAttr().Get(), dtype=float)
            entry.update(mass=float(m.GetMassAttr().Get()), com=np.array(m.GetCenterOfMassAttr().Get(), dtype=float),
                         principal_axes=axes, principal_moments=moments, inertia=axes @ np.diag(moments) @ axes.T)
        out["objects"][oid] = entry
    return out


def release_usd(path: str | Path, seconds: float, upward_offset: float = 0.0, cache_dir: str | Path | None = None,
                sim: SimSettings | None = None) -> dict:
    """Drift of an exported stage rebuilt in a fresh pybullet world from what :func:`read_usd_scene` reads.

    Bodies are the re-read hulls with the re-read mass, centre of mass and inertia; static objects are fixed
    colliders; the ground is the re-read ground height, the walls and ceiling the re-read planes; the world
    settings come from the stage (friction and restitution from its physics material, the rest from
    ``phiscene:sim``, or ``sim``). Every free body is lifted
    by ``upward_offset`` and the world runs ``seconds``; drift as in
    :func:`phiscene.metrics.drift.drift_bullet` (centre of mass from before the lift, rotation in degrees).

    Returns
    -------
    ``{"drift_trans": mean m, "drift_rot": mean deg, "frames": int, "objects": {id: {...}}}``
    """
    import tempfile

    from phiscene.inertia import RigidProps
    from phiscene.sim.bullet import BulletWorld

    data = read_usd_scene(path)
    base = sim.to_dict() if sim is not None else (data["sim"] or {})
    settings = SimSettings.from_dict({**base, "friction": data["friction"], "restitution": data["restitution"]})
    frames = int(round(seconds / settings.frame_dt))
    lift = make_pose(translation=[0.0, 0.0, float(upward_offset)])
    with tempfile.TemporaryDirectory() as tmp, BulletWorld(settings, cache_dir or tmp) as world:
        world.add_ground(data["ground_height"])
        world.add_structure(data["structure"])  # walls and ceiling: static planes
        for oid, o in data["objects"].items():
            if o["static"]:
                world.add_body(oid, o["hulls"], o["pose"], None)
                world.set_static(oid)
                continue
            props = RigidProps(o["mass"], o["com"], o["principal_moments"], o["principal_axes"], "usd")
            world.add_body(oid, o["hulls"], lift @ o["pose"], props)
        free = [oid for oid, o in data["objects"].items() if not o["static"]]
        start = {oid: (world.com_position(oid) - lift[:3, 3], decompose(world.pose(oid))[0]) for oid in free}
        world.step_frames(frames)
        per = {}
        for oid in free:
            com0, R0 = start[oid]
            per[oid] = {"drift_trans": float(np.linalg.norm(world.com_position(oid) - com0)),
                        "drift_rot": math.degrees(rotation_angle(R0, decompose(world.pose(oid))[0]))}
    means = {k: float(np.mean([v[k] for v in per.values()])) if per else 0.0 for k in ("drift_trans", "drift_rot")}
    return {**means, "frames": frames, "objects": per}


def validate_usd(path: str | Path) -> list[str]:
    """Messages of every error USD's validators (all registered ones: UsdGeom, UsdPhysics, UsdShade, ...) report.

    Returns
    -------
    ``"<validator> <error name>: <message>"`` per error; empty when the stage is valid.
    """
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return [f"{e.GetValidator().GetMetadata().name} {e.GetName()}: {e.GetMessage()}"
            for e in errors if not e.HasNoError()]


def validator_names() -> list[str]:
    """Names of the validators :func:`validate_usd` runs."""
    from pxr import UsdValidation

    return sorted(v.GetMetadata().name for v in UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
