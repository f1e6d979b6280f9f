"""Shared builders of the small test scenes: box meshes, scenes placing them, convex proxies, exact clearance.

Test modules import these instead of keeping their own copies (``from scenes import box_meshes, box_scene``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from phiscene.meshes import sample_surface, save_mesh
from phiscene.proxies import ProxyParams, proxy_for_mesh, scene_proxies
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.transforms import make_pose


def ground_alone(oid: str, mesh_path: Path, pose: np.ndarray, description: str, cache: Path,
                 faithful: dict) -> tuple[Scene, dict, dict]:
    """One object on the ground (its only supporter), grounded with the faithful settings ``faithful`` (plus
    ``enabled``) and convex proxies: (grounded scene, assembly record, proxies)."""
    from phiscene.assembly import AssemblyParams, ground_scene
    from phiscene.sim.settings import SimSettings
    from phiscene.topology.graph import SupportEdge, SupportGraph

    scene = Scene([SceneObject(oid, mesh_path, pose, description)])
    graph = SupportGraph(objects=[oid], edges=[SupportEdge("ground", oid, "supports")], order=[oid])
    proxies = convex_proxies(scene, cache)
    params = AssemblyParams.from_dict({"faithful": {"enabled": True, **faithful}})
    out, rec = ground_scene(scene, [oid], proxies, params, SimSettings(), cache, graph=graph)
    return out, rec, proxies


def box_meshes(root: Path, sizes: dict[str, tuple[float, float, float]]) -> dict[str, Path]:
    """One box mesh file per name (``root/<name>.obj``, centred at the origin), name -> path."""
    return {name: save_mesh(trimesh.creation.box(size), Path(root) / f"{name}.obj") for name, size in sizes.items()}


def box_scene(meshes: dict[str, Path], placements: dict[str, tuple[str, np.ndarray]], describe: bool = False,
              ground_height: float = 0.0) -> Scene:
    """A scene of mesh files: object id -> (mesh name, (4, 4) pose); ``describe`` adds descriptions and colours."""
    objects = []
    for i, (oid, (name, pose)) in enumerate(placements.items()):
        extra = {"description": f"{name} {oid}", "color": (10 * i, 20, 30)} if describe else {}
        objects.append(SceneObject(oid, meshes[name], pose, **extra))
    return Scene(objects, ground_height=ground_height)


def convex_proxies(scene: Scene, cache: Path) -> dict:
    """One convex hull per object (the ``convex`` proxy backend)."""
    return scene_proxies(scene, ProxyParams(backend="convex"), cache)


def scene_file(tmp_path: Path, objects: list[tuple[str, trimesh.Trimesh, np.ndarray]],
               ground_height: float = 0.0) -> tuple[Scene, dict]:
    """A saved and reloaded scene of ``[(id, mesh, pose)]`` and its convex proxies."""
    objs = [SceneObject(name, save_mesh(mesh, tmp_path / "meshes" / f"{name}.obj"), pose)
            for name, mesh, pose in objects]
    scene = load_scene(save_scene(Scene(objs, ground_height=ground_height), tmp_path / "scene.json"))
    proxies = {o.id: proxy_for_mesh(o.mesh_path, ProxyParams(backend="convex"), tmp_path / "cache")
               for o in scene.objects}
    return scene, proxies


def clearance(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 20000) -> float:
    """Exact bidirectional clearance between two world meshes (min signed distance of dense samples)."""
    from phiscene.sdf import signed_distance

    pa = np.vstack([sample_surface(a, n, 1), a.vertices])
    pb = np.vstack([sample_surface(b, n, 2), b.vertices])
    return float(min(signed_distance(b, pa).min(), signed_distance(a, pb).min()))


def open_dense(mesh: trimesh.Trimesh, faces: int = 30000) -> trimesh.Trimesh:
    """``mesh`` subdivided to at least ``faces`` faces, with every 23rd face removed (not watertight): the size and
    the holes of a reconstruction."""
    m = mesh.copy()
    while len(m.faces) < faces:
        m = m.subdivide()
    m.update_faces(np.arange(len(m.faces)) % 23 != 5)
    m.remove_unreferenced_vertices()
    return m


def table_mesh() -> trimesh.Trimesh:
    """A table: a 1.0 x 0.6 x 0.04 m top on four 0.7 m legs, overlapping boxes (no closed manifold, not convex)."""
    T = trimesh.transformations.translation_matrix
    parts = [trimesh.creation.box([1.0, 0.6, 0.04], transform=T([0, 0, 0.72]))]
    parts += [trimesh.creation.box([0.05, 0.05, 0.7], transform=T([sx * 0.45, sy * 0.25, 0.35]))
              for sx in (-1, 1) for sy in (-1, 1)]
    return trimesh.util.concatenate(parts)


def leaning_pose(size, angle_deg: float) -> np.ndarray:
    """A box whose long axis rises at ``angle_deg`` towards -x, lowest corner on z = 0, wall-side corner on x = 0."""
    a = np.radians(angle_deg)
    u = np.array([-np.cos(a), 0.0, np.sin(a)])
    R = np.column_stack([u, [0.0, 1.0, 0.0], np.cross(u, [0.0, 1.0, 0.0])])
    v = trimesh.creation.box(size).vertices @ R.T
    return make_pose(R, (-v[:, 0].min(), 0.0, -v[:, 2].min()))


#: The ladder's plank (m): see :func:`ladder_on_wall`.
PLANK = (0.6, 0.08, 0.02)


def ladder_on_wall(tmp_path: Path, turn_deg: float = 0.0, wall: bool = True,
                   estimated: bool = True) -> tuple[Scene, dict]:
    """The ladder of tests/test_clutter.py (a plank at 60 deg against the wall x = 0: statics hold it when
    mu_ground >= tan 30 deg / 2 = 0.29), the whole turned ``turn_deg`` about z, with the wall ``wall_0`` (or
    none), and the convex proxies."""
    from phiscene.scene import Plane
    from phiscene.transforms import rotation_z

    turn = make_pose(rotation_z(np.radians(turn_deg)))
    plank = SceneObject("plank", save_mesh(trimesh.creation.box(PLANK), tmp_path / "plank.obj").resolve(),
                        turn @ leaning_pose(PLANK, 60.0), "wooden plank")
    normal = tuple(float(v) for v in turn[:3, :3] @ [1.0, 0.0, 0.0])
    planes = [Plane("wall_0", "wall", normal, 0.0, estimated=estimated)] if wall else []
    scene = Scene([plank], structure=planes)
    return scene, {"plank": proxy_for_mesh(plank.mesh_path, ProxyParams(backend="convex"), tmp_path / "cache")}
