"""Unseen test scenes from the assets that ship with pybullet, settled in pybullet, degraded like a 3D foundation model.

The project's suites are built by its own generators; these six scenes are not. Each is made of the meshes in
``pybullet_data`` (the ``random_urdfs`` objects, the table, tray, jenga block, duck, teddy, bunny, soccer ball and
sphere), dropped one by one onto a plane in pybullet and settled there: that settled state is the ground truth.
A degraded copy of it is written in the layout ``phiscene import-placed`` reads, with the ground truth beside it.

Scenes (``probe_<index>_<kind>``):

* ``table_clutter``: a table (``table/table.urdf``'s geometry, scaled), a stack of 1-2 books and an object on it, and
  3-5 more objects on the table top.
* ``tray_floor``: the tray with a duck and 3-5 objects in it, one object on the floor beside it.
* ``jenga_tower``: 3-4 jenga blocks crossed at 90 deg, a soccer ball and 2-3 objects on the floor.
* ``floor_toys``: teddy, duck, bunny and soccer ball (shuffled) and 1-2 objects on the floor.
* ``table_floor``: ``table_clutter`` with 1-2 extra objects, a teddy and a ball on the floor beside the table.
* ``board_bridge``: a board across two boxes (two supporters), 2-3 objects on the board, a ball on the floor.

Physics: plane z = 0, gravity -9.81 m/s^2, 240 Hz; collision shapes are compounds of convex pieces (the assets' own
convex bodies, pybullet's V-HACD for the bunny, boxes for the table, jenga blocks, books and boxes, the tray's six
slabs). Each object is dropped 4 mm above whatever is below it, the scene settles 4 s and must then stay still for
2 s more (every object moves < 2 mm and turns < 1 deg), each object with an intended support (the table top, the
tray, the board, the block below) must still be on it and none may roll beyond 1.5 m; a scene that fails, or has
fewer than 4 or more than 12 objects, is rebuilt from the next attempt's random stream
(``numpy.random.default_rng([seed, scene_index, attempt])``).

Degradation (its own stream, ``default_rng([seed, scene_index, attempt, 1])``): a camera looks at the scene from a
random azimuth, 30-45 deg elevation and 1.5-2.5 m (plus half the scene's extent beyond 1 m), field of view 50 deg.
Per object, about its centroid:

* translation error: N(0, 3% of the object's depth) along the camera ray plus N(0, 1 cm) along each of two
  directions across it;
* rotation error: N(0, 4 deg) about each axis (xyz Euler angles);
* scale error: U(0.93, 1.05);
* ``--noise-scale k`` multiplies the three errors (scale as 1 + k (s - 1)); 0 gives the same scenes and tilt with no
  per-object error (the scene names get a suffix ``_noise<k>``).

The whole scene is then turned by a tilt of U(8, 20) deg about a horizontal axis within 30 deg of the camera's right
vector (either sign), written Y-up ((x, y, z) -> (x, z, -y)) and shifted so that the camera's eye is at the origin.

Output::

    OUT/scenes/<scene>/<object_id>.obj   vertices in the degraded, tilted, Y-up frame
    OUT/scenes/<scene>/camera.json       {"eye", "target", "fov_y_deg"} in that frame (the true camera)
    OUT/gt/<scene>.json                  ground truth and the errors applied (its 'conventions' key says how)
    OUT/summary.json                     per scene: the objects' assets, tilt, attempt, settling drift
                                         (summary_noise<k>.json with --noise-scale k other than 1)
    OUT/cache/                           collision meshes handed to pybullet, V-HACD's decomposition of the bunny

Usage::

    python benchmarks/asset_scenes.py OUT [--seed 7] [--noise-scale 0] [--only table_clutter ...]

The rest of the check, with the project's CLI, per scene::

    phiscene import-placed OUT/scenes/<scene> OUT/levelled/<scene> --up y --camera OUT/scenes/<scene>/camera.json
    phiscene ground OUT/levelled/<scene>/initial OUT/grounded/<scene>

and then the levelling against the truth (per scene: the tilt applied, the levelling rotation ``import-placed``
applied, the angle between the true up and the up it estimated, and the height in the levelled frame of the true
floor below the camera's target; scenes not imported are listed)::

    python benchmarks/asset_scenes.py OUT --report OUT/levelled [--grounded OUT/grounded]

``--grounded`` adds, per grounded scene, the mean distance of the objects' centres from the truth in the input and
after grounding (each after the best rigid motion onto the truth), the displacement from the input (mean, max) and
how many objects settled.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pybullet as p  # noqa: E402
import pybullet_data  # noqa: E402
import trimesh  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

#: pybullet's shipped assets.
DATA = Path(pybullet_data.getDataPath())
#: Scene names: ``<SCENE_PREFIX>_<index>_<kind>`` (``_noise<k>`` appended when the noise scale is not 1).
SCENE_PREFIX = "probe"
#: Simulation rate (Hz) and gravity (m/s^2, along -z).
HZ, GRAVITY = 240, 9.81
#: Friction of the ground plane and (default) of the objects; rolling and spinning friction of the objects.
GROUND_FRICTION, OBJECT_FRICTION, ROLLING_FRICTION = 0.8, 0.8, 0.002
#: Default density (kg/m^3) of an object without a set mass, and the least mass (kg).
DENSITY, MIN_MASS = 400.0, 0.02
#: Most faces of an object's visual mesh.
MAX_FACES = 20000
#: V-HACD's voxel resolution (the bunny's decomposition).
VHACD_RESOLUTION = 200000
#: Clearance (m) of a dropped object over whatever is below it; surface samples used to find what is below.
DROP_GAP, DROP_SAMPLES = 0.004, 300
#: Heights (m) between which the drop rays are cast.
RAY_TOP, RAY_BOTTOM = 5.0, -1.0
#: Settling time (s), then the time (s) over which the scene must stay still.
SETTLE_S, CHECK_S = 4.0, 2.0
#: Largest motion (m) and turn (deg) of any object over CHECK_S for a stable scene.
MAX_DRIFT_M, MAX_DRIFT_DEG = 0.002, 1.0
#: How far (m) an object may sink below its intended support; how far (m, horizontally) it may roll from the origin.
SUPPORT_TOL, ROLL_AWAY = 0.01, 1.5
#: Fewest and most objects of a scene.
MIN_OBJECTS, MAX_OBJECTS = 4, 12
#: Attempts per scene by default.
MAX_ATTEMPTS = 12
#: The camera: elevation range (deg), distance range (m), extra distance per metre of scene extent beyond 1 m,
#: the target's height as a fraction of the scene's top, vertical field of view (deg).
CAM_ELEVATION_DEG, CAM_DISTANCE_M, CAM_EXTENT_GAIN, CAM_TARGET_HEIGHT, FOV_Y_DEG = (30, 45), (1.5, 2.5), 0.5, 0.4, 50
#: Per-object errors: translation sd along the ray (fraction of depth) and across it (m), rotation sd per axis (deg),
#: scale range.
DEPTH_ERROR, SIDE_ERROR_M, ROTATION_ERROR_DEG, SCALE_ERROR = 0.03, 0.01, 4.0, (0.93, 1.05)
#: Tilt of the scene (deg, range) and the largest angle (deg) of its axis from the camera's right vector.
TILT_DEG, TILT_AXIS_SPREAD_DEG = (8, 20), 30
#: The degraded frame is Y-up: (x, y, z) -> (x, z, -y).
Z_UP_TO_Y_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
#: The duck and teddy are modelled Y-up: this turns them Z-up (y -> z).
Y_UP_ASSET = Rotation.from_euler("x", 90, degrees=True).as_matrix()
#: What ``OUT/gt/<scene>.json`` holds and in which frames.
CONVENTIONS = {
    "world": "GT world, metres, z-up, ground plane z = 0",
    "degraded_frame": "p_deg = R_g @ (R_tilt @ p_world) + t_g; R_g = (x,y,z)->(x,z,-y) (Y-up); camera eye at the "
                      "origin; world_to_degraded is that 4x4, degraded_to_world its inverse",
    "local_frame": "each object's mesh centred at its volume centroid (trimesh center_mass), asset axes (after the "
                   "y-up->z-up turn for duck/teddy and the rescale)",
    "gt_pose": "p_world = gt_rotation @ p_local + gt_centroid_world",
    "degraded_pose": "p_world_degraded = deg_rotation_world @ (scale_error * p_local) + deg_centroid_world; the OBJ "
                     "holds world_to_degraded applied to that",
    "degraded_to_gt_vertices": "4x4 similarity mapping the OBJ's vertices (degraded frame) onto the object's GT "
                               "vertices in the world frame",
    "errors": "error_translation_m = deg_centroid_world - gt_centroid_world (world frame); "
              "error_rotation_euler_xyz_deg: R_err = from_euler('xyz') and deg_rotation = R_err @ gt_rotation"}

Poses = list[tuple[np.ndarray, np.ndarray]]


# ----------------------------------------------------------------------------------------------------------- assets
def homogeneous(R: np.ndarray, t: np.ndarray | tuple = (0, 0, 0)) -> np.ndarray:
    """A 4x4 transform.

    Parameters
    ----------
    R : (3, 3) rotation (or any linear map).
    t : (3,) translation.

    Returns
    -------
    (4, 4) array ``[[R, t], [0, 1]]``.
    """
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def clean(m: trimesh.Trimesh) -> trimesh.Trimesh:
    """A processed copy of ``m`` with float vertices and no visuals (vertices (n, 3), faces (f, 3))."""
    return trimesh.Trimesh(np.asarray(m.vertices, float), np.asarray(m.faces), process=True)


def load_obj(path: Path) -> trimesh.Trimesh:
    """One mesh of an OBJ file, vertices merged regardless of texture and normals, outward-facing if watertight."""
    m = trimesh.load(str(path), force="mesh", process=True)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    m = clean(m)
    if m.is_watertight and m.volume < 0:
        m.invert()
    return m


class Asset:
    """An object: visual mesh and convex collision pieces in one local frame (metres, origin = the mesh's centroid).

    Parameters
    ----------
    name : object id (the OBJ's file name).
    mesh : visual mesh, its centroid (volume centroid when watertight, else the bounding box centre) moved to 0.
    pieces : collision pieces in the mesh's frame; each is replaced by its convex hull.
    source : where it came from (file, scale, ...), written to the ground truth.
    density : kg/m^3 when ``mass`` is not given (volume of the mesh, or its convex hull when not watertight).
    mass : kg, or None.
    friction : lateral friction.

    Attributes
    ----------
    orient : (3, 3) orientation (world <- local) of the drop, set by the builder.
    top_z, half : a table's top height (m) and its top's half extents (m, x and y); 0 for other objects.
    """

    def __init__(self, name: str, mesh: trimesh.Trimesh, pieces: list[trimesh.Trimesh], source: dict,
                 density: float = DENSITY, mass: float | None = None, friction: float = OBJECT_FRICTION) -> None:
        c = mesh.center_mass if (mesh.is_watertight and mesh.volume > 1e-9) else mesh.bounds.mean(0)
        self.mesh = clean(mesh.copy().apply_translation(-c))
        self.pieces = [clean(q.copy().apply_translation(-c)).convex_hull for q in pieces]
        self.name, self.source, self.friction = name, source, friction
        vol = abs(self.mesh.volume) if self.mesh.is_watertight else self.mesh.convex_hull.volume
        self.mass = float(mass if mass is not None else max(MIN_MASS, density * vol))
        self.orient = np.eye(3)
        self.top_z, self.half = 0.0, (0.0, 0.0)
        if len(self.mesh.faces) > MAX_FACES:
            raise ValueError(f"{name}: {len(self.mesh.faces)} faces, more than {MAX_FACES}")


def rescale(m: trimesh.Trimesh, pieces: list[trimesh.Trimesh], largest: float, R: np.ndarray | None = None
            ) -> tuple[trimesh.Trimesh, list[trimesh.Trimesh], float]:
    """``m`` and ``pieces`` turned by ``R`` (3, 3; none when None), then scaled so that m's largest extent is
    ``largest`` (m); returns copies and the scale."""
    if R is not None:
        m = m.copy().apply_transform(homogeneous(R))
        pieces = [q.copy().apply_transform(homogeneous(R)) for q in pieces]
    s = largest / float(np.max(m.extents))
    return m.copy().apply_scale(s), [q.copy().apply_scale(s) for q in pieces], s


def yaw(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    """(3, 3) rotation about z by ``angle`` (rad), or by one U(0, 2 pi) draw from ``rng`` when None."""
    a = rng.uniform(0, 2 * np.pi) if angle is None else angle
    return Rotation.from_euler("z", a).as_matrix()


def stable_orientation(a: Asset, rng: np.random.Generator) -> np.ndarray:
    """(3, 3) most probable resting orientation of the pieces' convex hull (trimesh), then a random yaw (one draw).

    The identity stands in for the resting orientation when the hull is degenerate.
    """
    try:
        hull = trimesh.util.concatenate(a.pieces).convex_hull
        T, prob = hull.compute_stable_poses(center_mass=np.zeros(3), n_samples=1)
        R = T[int(np.argmax(prob))][:3, :3]
    except (ValueError, IndexError, RuntimeError):  # a flat or degenerate hull (Qhull errors are RuntimeErrors)
        R = np.eye(3)
    return yaw(rng) @ R


def random_object(rng: np.random.Generator, name: str) -> Asset:
    """One of ``random_urdfs/000-999`` (its own convex bodies as collision), largest extent U(4, 15) cm, resting."""
    k = int(rng.integers(0, 1000))
    src = DATA / "random_urdfs" / f"{k:03d}" / f"{k:03d}.obj"
    m = load_obj(src)
    m, pieces, s = rescale(m, m.split(only_watertight=False), float(rng.uniform(0.04, 0.15)))
    a = Asset(name, m, pieces, {"file": str(src.relative_to(DATA)), "scale": s})
    a.orient = stable_orientation(a, rng)
    return a


def box_asset(name: str, size: list[float], source: str, density: float = 500.0, mass: float | None = None
              ) -> Asset:
    """A box of ``size`` (3,) metres, its own collision shape."""
    m = trimesh.creation.box(size)
    return Asset(name, m, [m], {"file": source, "size": list(map(float, size))}, density=density, mass=mass)


def table_asset(rng: np.random.Generator, name: str) -> Asset:
    """``table/table.urdf``'s geometry (top 1.5 x 1 x 0.05 m at z 0.6, legs 0.1 x 0.1 x 0.58 m), 12 kg, top scaled
    0.6-0.75 (x) and 0.65-0.8 (y), height 0.95-1.25 (0.6-0.78 m), random yaw."""
    sx, sy = rng.uniform(0.6, 0.75), rng.uniform(0.65, 0.8)
    hz = rng.uniform(0.95, 1.25)
    parts = [trimesh.creation.box([1.5 * sx, 1.0 * sy, 0.05]).apply_translation([0, 0, 0.6 * hz])]
    for x in (-0.65, 0.65):
        for y in (-0.4, 0.4):
            lh = 0.6 * hz - 0.02  # up into the top slab by 5 mm (as the URDF's legs)
            leg = trimesh.creation.box([0.1, 0.1, lh])
            parts.append(leg.apply_translation([x * sx, y * sy, lh / 2]))
    m = trimesh.util.concatenate(parts)
    a = Asset(name, m, parts, {"file": "table/table.urdf", "scale_xy": [sx, sy], "scale_z": hz}, mass=12.0)
    a.top_z = 0.6 * hz + 0.025
    a.half = (0.75 * sx, 0.5 * sy)
    a.orient = yaw(rng)
    return a


def tray_asset(rng: np.random.Generator, name: str) -> Asset:
    """``tray/tray_textured4.obj`` (its six slabs as collision), scaled 0.45-0.55, 0.6 kg, random yaw."""
    src = DATA / "tray" / "tray_textured4.obj"
    m = load_obj(src)
    pieces = m.split(only_watertight=False)
    s = rng.uniform(0.45, 0.55)
    m.apply_scale(s)
    pieces = [q.apply_scale(s) for q in pieces]
    a = Asset(name, m, pieces, {"file": "tray/tray_textured4.obj (tray.urdf)", "scale": s}, mass=0.6)
    a.orient = yaw(rng)
    return a


def vhacd_pieces(m: trimesh.Trimesh, key: str, cache: Path) -> list[trimesh.Trimesh]:
    """Convex pieces of ``m`` by pybullet's V-HACD, kept as ``cache/<key>_vhacd.obj`` and reused."""
    cache.mkdir(parents=True, exist_ok=True)
    src, dst = cache / f"{key}_in.obj", cache / f"{key}_vhacd.obj"
    if not dst.exists():
        clean(m).export(src, include_normals=False, include_texture=False)
        p.vhacd(str(src), str(dst), str(cache / f"{key}_vhacd.log"), resolution=VHACD_RESOLUTION)
    parts = trimesh.load(str(dst), force="mesh", process=True)
    parts.merge_vertices(merge_tex=True, merge_norm=True)
    return parts.split(only_watertight=False)


def named_asset(rng: np.random.Generator, name: str, kind: str, cache: Path) -> Asset:
    """A named pybullet asset, largest extent (m) drawn in a range per kind.

    ``teddy`` (``teddy2_VHACD_CHs.obj``, its own convex bodies, 0.25-0.35), ``duck`` (``duck.obj``, collision
    ``duck_vhacd.obj``, 0.09-0.14), ``bunny`` (``bunny.obj``, V-HACD pieces cached under ``cache``, 0.12-0.18,
    resting orientation), ``soccerball`` (``soccerball.obj``, 0.21-0.23), ``ball`` (``sphere_smooth.obj``,
    0.06-0.09). All but the bunny are dropped upright with a random yaw.
    """
    if kind == "teddy":
        src = DATA / "teddy2_VHACD_CHs.obj"
        m = load_obj(src)
        m, pieces, s = rescale(m, m.split(only_watertight=False), rng.uniform(0.25, 0.35), Y_UP_ASSET)
    elif kind == "duck":
        src = DATA / "duck.obj"
        m = load_obj(src)
        col = load_obj(DATA / "duck_vhacd.obj")
        m, pieces, s = rescale(m, col.split(only_watertight=False), rng.uniform(0.09, 0.14), Y_UP_ASSET)
    elif kind == "bunny":
        src = DATA / "bunny.obj"
        m = load_obj(src)
        m, _, s = rescale(m, [], rng.uniform(0.12, 0.18))
        pieces = vhacd_pieces(m, f"bunny_{s:.4f}", cache)
    elif kind == "soccerball":
        src = DATA / "soccerball.obj"
        m = load_obj(src)
        m, pieces, s = rescale(m, [m], rng.uniform(0.21, 0.23))
    elif kind == "ball":
        src = DATA / "sphere_smooth.obj"
        m = load_obj(src)
        m, pieces, s = rescale(m, [m], rng.uniform(0.06, 0.09))
    else:
        raise ValueError(f"unknown asset kind {kind!r}")
    a = Asset(name, m, pieces, {"file": src.name, "scale": float(s)})
    a.orient = yaw(rng) if kind in ("teddy", "duck", "soccerball", "ball") else stable_orientation(a, rng)
    return a


# ---------------------------------------------------------------------------------------------------------- physics
class Sim:
    """A pybullet world (DIRECT) with a ground plane at z = 0; objects are added one by one and stepped.

    Parameters
    ----------
    key : tag of the collision files this world writes (``<scene index>_<attempt>``).
    cache : folder of those files.
    """

    def __init__(self, key: str, cache: Path) -> None:
        self.cid = p.connect(p.DIRECT)
        p.setGravity(0, 0, -GRAVITY, physicsClientId=self.cid)
        p.setTimeStep(1.0 / HZ, physicsClientId=self.cid)
        plane = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.cid),
                                  physicsClientId=self.cid)
        p.changeDynamics(plane, -1, lateralFriction=GROUND_FRICTION, physicsClientId=self.cid)
        self.key, self.cache = key, cache
        self.bodies: list[int] = []
        self.assets: list[Asset] = []

    def close(self) -> None:
        """Disconnect the world."""
        p.disconnect(self.cid)

    def add(self, a: Asset, xy: np.ndarray | tuple, above: float = DROP_GAP) -> int:
        """Drop ``a`` (orientation ``a.orient``) with its centroid over ``xy`` (2,), its lowest point ``above`` (m)
        over whatever is below it (rays cast down through its footprint); returns the body id."""
        self.cache.mkdir(parents=True, exist_ok=True)
        f = self.cache / f"col_{self.key}_{len(self.bodies)}_{a.name}.obj"
        with open(f, "w") as fh:
            off = 0
            for i, q in enumerate(a.pieces):
                fh.write(f"o piece_{i}\n")
                fh.writelines(f"v {x:.7f} {y:.7f} {z:.7f}\n" for x, y, z in q.vertices)
                fh.writelines(f"f {i0} {i1} {i2}\n" for i0, i1, i2 in q.faces + 1 + off)
                off += len(q.vertices)
        cs = p.createCollisionShape(p.GEOM_MESH, fileName=str(f), physicsClientId=self.cid)
        V = a.mesh.vertices @ a.orient.T
        surf = trimesh.sample.sample_surface(a.mesh, DROP_SAMPLES, seed=0)[0] @ a.orient.T
        pts = np.vstack([np.asarray(xy) + surf[:, :2], np.asarray(xy) + V[:, :2], [xy]])
        res = p.rayTestBatch([[x, y, RAY_TOP] for x, y in pts], [[x, y, RAY_BOTTOM] for x, y in pts],
                             physicsClientId=self.cid)
        top = max([r[3][2] for r in res if r[0] >= 0] + [0.0])
        z = top - V[:, 2].min() + above
        q = Rotation.from_matrix(a.orient).as_quat()  # x, y, z, w
        b = p.createMultiBody(a.mass, cs, basePosition=[xy[0], xy[1], z], baseOrientation=q.tolist(),
                              physicsClientId=self.cid)
        p.changeDynamics(b, -1, lateralFriction=a.friction, rollingFriction=ROLLING_FRICTION,
                         spinningFriction=ROLLING_FRICTION, physicsClientId=self.cid)
        self.bodies.append(b)
        self.assets.append(a)
        return b

    def step(self, seconds: float) -> None:
        """Step the world ``seconds`` (rounded to frames)."""
        for _ in range(int(round(seconds * HZ))):
            p.stepSimulation(physicsClientId=self.cid)

    def poses(self) -> Poses:
        """Per object (in the order added): its centroid (3,) and rotation (3, 3), world frame."""
        out = []
        for b in self.bodies:
            pos, q = p.getBasePositionAndOrientation(b, physicsClientId=self.cid)
            out.append((np.array(pos), Rotation.from_quat(q).as_matrix()))
        return out

    def contacts(self) -> list[dict]:
        """The touching pairs (object ids, ``ground`` for the plane), sorted, each with its summed normal force (N)."""
        ids = {b: a.name for b, a in zip(self.bodies, self.assets)}
        ids[0] = "ground"
        pairs: dict[tuple[str, str], float] = {}
        for c in p.getContactPoints(physicsClientId=self.cid):
            if c[9] <= 0:
                continue
            k = tuple(sorted((ids[c[1]], ids[c[2]])))
            pairs[k] = pairs.get(k, 0.0) + c[9]
        return [{"a": k[0], "b": k[1], "normal_force_n": round(v, 4)} for k, v in sorted(pairs.items())]


# ----------------------------------------------------------------------------------------------------------- scenes
def free_xy(rng: np.random.Generator, placed: list[tuple[np.ndarray, float]], r: float, lo: list[float],
            hi: list[float], min_gap: float = 0.01, tries: int = 200) -> np.ndarray | None:
    """A point (2,) drawn in the box [lo, hi] (each (2,)) whose disc of radius ``r`` clears every disc of ``placed``
    (centre (2,), radius) by ``min_gap`` (m); None after ``tries`` draws."""
    for _ in range(tries):
        xy = rng.uniform(lo, hi)
        if all(np.linalg.norm(xy - q) > r + rq + min_gap for q, rq in placed):
            return xy
    return None


def drop_free(rng: np.random.Generator, sim: Sim, a: Asset, placed: list[tuple[np.ndarray, float]], r: float,
              lo: list[float], hi: list[float], seconds: float, min_gap: float = 0.01,
              turn: np.ndarray | None = None) -> bool:
    """Drop ``a`` at a spot of the box [lo, hi] (each (2,)) where its disc of radius ``r`` clears ``placed``
    (:func:`free_xy`), recorded in ``placed``, and let the scene run ``seconds``.

    Parameters
    ----------
    turn : (2, 2) float, optional
        Maps the spot (the box's frame) to world xy (a table's or tray's yaw); None: the box is in world xy.

    Returns
    -------
    False, with nothing dropped, when no spot is free.
    """
    xy = free_xy(rng, placed, r, lo, hi, min_gap)
    if xy is None:
        return False
    placed.append((xy, r))
    sim.add(a, xy if turn is None else turn @ xy)
    sim.step(seconds)
    return True


def radius(a: Asset) -> float:
    """Horizontal radius (m) of ``a`` in its drop orientation, about its centroid."""
    V = a.mesh.vertices @ a.orient.T
    return float(np.max(np.linalg.norm(V[:, :2], axis=1)))


def scene_table_clutter(rng: np.random.Generator, sim: Sim, cache: Path, n_extra: int | None = None
                        ) -> dict[str, float]:
    """A table; on it a stack of 1-2 books and an object, and ``n_extra`` (3-5 when None) objects.

    Returns
    -------
    Intended support height (m) per object id: the table top.
    """
    table = table_asset(rng, "table_0")
    sim.add(table, (0.0, 0.0))
    sim.step(1.0)
    expect = {}
    tz = table.top_z
    (hx, hy), R = table.half, table.orient
    placed = []
    books = int(rng.integers(1, 3))
    sxy = np.array([rng.uniform(-0.5, 0.5) * hx, rng.uniform(-0.4, 0.4) * hy])
    for i in range(books):
        bk = box_asset(f"book_{i + 1}", [rng.uniform(0.16, 0.24), rng.uniform(0.12, 0.17), rng.uniform(0.02, 0.045)],
                       "cube.obj (box)", density=600)
        bk.orient = yaw(rng) @ np.eye(3) if i == 0 else yaw(rng, rng.normal(0, 0.25)) @ sim.assets[-1].orient
        sim.add(bk, R[:2, :2] @ sxy + rng.normal(0, 0.01, 2))
        sim.step(0.6)
        expect[bk.name] = tz
    top = random_object(rng, f"object_{books + 1}")
    sim.add(top, R[:2, :2] @ sxy + rng.normal(0, 0.01, 2))
    sim.step(0.8)
    expect[top.name] = tz
    placed.append((sxy, 0.16))
    n = int(rng.integers(3, 6)) if n_extra is None else n_extra
    for i in range(n):
        o = random_object(rng, f"object_{books + 2 + i}")
        if drop_free(rng, sim, o, placed, radius(o), [-hx + 0.08, -hy + 0.08], [hx - 0.08, hy - 0.08], 0.6,
                     turn=R[:2, :2]):
            expect[o.name] = tz
    return expect


def scene_tray(rng: np.random.Generator, sim: Sim, cache: Path) -> dict[str, float]:
    """The tray with a duck and 3-5 objects in it, one object on the floor 0.45 m from its centre.

    Returns
    -------
    Intended support height (m) per object id in the tray: its floor (4 mm).
    """
    tray = tray_asset(rng, "tray_0")
    sim.add(tray, (0.0, 0.0))
    sim.step(0.8)
    s = tray.source["scale"]
    hx, hy, R = 0.38 * s, 0.38 * s, tray.orient
    expect: dict[str, float] = {}
    placed: list[tuple[np.ndarray, float]] = []
    kinds = ["duck"] + ["rand"] * int(rng.integers(3, 6))
    for i, k in enumerate(kinds):
        o = (named_asset(rng, f"duck_{i + 1}", "duck", cache) if k == "duck"
             else random_object(rng, f"object_{i + 1}"))
        r = radius(o)
        if drop_free(rng, sim, o, placed, r, [-hx + r, -hy + r], [hx - r, hy - r], 0.6, min_gap=0.0, turn=R[:2, :2]):
            expect[o.name] = 0.004
    o = random_object(rng, f"object_{len(kinds) + 1}")
    ang = rng.uniform(0, 2 * np.pi)
    sim.add(o, (0.45 * np.cos(ang), 0.45 * np.sin(ang)))
    sim.step(0.6)
    return expect


def scene_jenga(rng: np.random.Generator, sim: Sim, cache: Path) -> dict[str, float]:
    """A tower of 3-4 jenga blocks (0.15 x 0.05 x 0.03 m, 50 g, alternating 90 deg), a soccer ball and 2-3 objects
    on the floor within 0.45 m.

    Returns
    -------
    Intended support height (m) per block: the block below it (the floor for the first).
    """
    n = int(rng.integers(3, 5))
    base = yaw(rng)
    c = rng.normal(0, 0.02, 2)
    expect = {}
    for i in range(n):
        bl = box_asset(f"block_{i}", [0.15, 0.05, 0.03], "jenga/jenga.urdf (box 0.15 x 0.05 x 0.03)", mass=0.05)
        bl.orient = yaw(rng, np.pi / 2 * (i % 2) + rng.normal(0, 0.05)) @ base
        sim.add(bl, c + rng.normal(0, 0.004, 2))
        sim.step(0.5)
        expect[bl.name] = 0.03 * i + 0.001
    placed = [(c, 0.1)]
    loose = [named_asset(rng, f"soccerball_{n}", "soccerball", cache)]
    loose += [random_object(rng, f"object_{n + 1 + i}") for i in range(int(rng.integers(2, 4)))]
    for o in loose:
        drop_free(rng, sim, o, placed, radius(o), [-0.45, -0.45], [0.45, 0.45], 0.8, min_gap=0.03)
    return expect


def scene_floor_toys(rng: np.random.Generator, sim: Sim, cache: Path) -> dict[str, float]:
    """Teddy, duck, bunny and soccer ball (in a random order) and 1-2 objects on the floor within 0.35 m.

    Returns
    -------
    An empty dict (everything stands on the floor).
    """
    kinds = ["teddy", "duck", "bunny", "soccerball"]
    rng.shuffle(kinds)
    objs = [named_asset(rng, f"{k}_{i}", k, cache) for i, k in enumerate(kinds)]
    objs += [random_object(rng, f"object_{len(objs) + i}") for i in range(int(rng.integers(1, 3)))]
    placed: list[tuple[np.ndarray, float]] = []
    for o in objs:
        drop_free(rng, sim, o, placed, radius(o), [-0.35, -0.35], [0.35, 0.35], 0.8, min_gap=0.015)
    return {}


def scene_table_floor(rng: np.random.Generator, sim: Sim, cache: Path) -> dict[str, float]:
    """``scene_table_clutter`` with 1-2 extra objects, then a teddy and a ball on the floor beside the table.

    Returns
    -------
    Intended support height (m) per object on the table: the table top.
    """
    expect = scene_table_clutter(rng, sim, cache, n_extra=int(rng.integers(1, 3)))
    table = sim.assets[0]
    hx, hy = table.half
    R = table.orient
    for i, k in enumerate(["teddy", "ball"]):
        o = named_asset(rng, f"{k}_{len(sim.assets)}", k, cache)
        side = rng.choice([-1, 1])
        xy = np.array([side * (hx + 0.12 + 0.25 * i), rng.uniform(-0.6, 0.6) * hy])
        sim.add(o, R[:2, :2] @ xy)
        sim.step(0.8)
    return expect


def scene_bridge(rng: np.random.Generator, sim: Sim, cache: Path) -> dict[str, float]:
    """Two boxes (0.12-0.2 m high, 0.2-0.3 m apart) on the floor, a board across them (two supporters), 2-3 objects
    on the board, a ball on the floor 0.3 m to one side.

    Returns
    -------
    Intended support height (m) of the board and the objects on it: the boxes' tops.
    """
    h = rng.uniform(0.12, 0.2)
    gap = rng.uniform(0.2, 0.3)
    base = yaw(rng)
    expect = {}
    for i, sgn in enumerate((-1, 1)):
        bx = box_asset(f"box_{i}", [0.12, rng.uniform(0.18, 0.24), h], "cube.obj (box)", density=300)
        bx.orient = base @ yaw(rng, rng.normal(0, 0.05))
        sim.add(bx, base[:2, :2] @ np.array([sgn * (gap / 2 + 0.06), 0.0]))
        sim.step(0.5)
    board = box_asset("board_2", [gap + 0.24 + rng.uniform(0.0, 0.08), rng.uniform(0.16, 0.22), 0.02],
                      "cube.obj (box)", density=500)
    board.orient = base
    sim.add(board, base[:2, :2] @ np.array([0.0, 0.0]))
    sim.step(0.8)
    expect["board_2"] = h
    placed: list[tuple[np.ndarray, float]] = []
    lx = board.mesh.extents[0] / 2 - 0.04
    for i in range(int(rng.integers(2, 4))):
        o = random_object(rng, f"object_{3 + i}")
        r = min(radius(o), 0.06)
        if drop_free(rng, sim, o, placed, r, [-lx + r, -0.02], [lx - r, 0.02], 0.6, min_gap=0.0, turn=base[:2, :2]):
            expect[o.name] = h
    o = named_asset(rng, f"ball_{len(sim.assets)}", "ball", cache)
    sim.add(o, base[:2, :2] @ np.array([0.0, rng.choice([-1, 1]) * 0.3]))
    sim.step(0.8)
    return expect


#: The scene kinds in order (the index in a scene's name and random stream is the position here).
KINDS: list[tuple[str, Callable[[np.random.Generator, Sim, Path], dict[str, float]]]] = [
    ("table_clutter", scene_table_clutter), ("tray_floor", scene_tray), ("jenga_tower", scene_jenga),
    ("floor_toys", scene_floor_toys), ("table_floor", scene_table_floor), ("board_bridge", scene_bridge)]


def settle_and_check(sim: Sim, expect: dict[str, float]) -> tuple[bool, Poses, dict[str, float], list[str]]:
    """Settle ``SETTLE_S``, then check the scene over ``CHECK_S`` more.

    Parameters
    ----------
    sim : the built world.
    expect : intended support height (m) per object id.

    Returns
    -------
    Whether it is stable and every object is still on its support and near the origin; the final poses (centroid
    (3,), rotation (3, 3) per object); the largest drift over the check (``max_drift_m``, ``max_drift_deg``); the
    reasons for a rejection.
    """
    sim.step(SETTLE_S)
    before = sim.poses()
    sim.step(CHECK_S)
    after = sim.poses()
    worst_t, worst_r = 0.0, 0.0
    for (p0, R0), (p1, R1) in zip(before, after):
        worst_t = max(worst_t, float(np.linalg.norm(p1 - p0)))
        worst_r = max(worst_r, float(np.degrees(Rotation.from_matrix(R1 @ R0.T).magnitude())))
    ok = worst_t < MAX_DRIFT_M and worst_r < MAX_DRIFT_DEG
    why = [] if ok else [f"moved {worst_t * 1000:.2f} mm / {worst_r:.2f} deg in the last {CHECK_S:g} s"]
    for a, (pos, R) in zip(sim.assets, after):
        low = float((a.mesh.vertices @ R.T + pos)[:, 2].min())
        if a.name in expect and low < expect[a.name] - SUPPORT_TOL:
            ok = False
            why.append(f"{a.name} lowest point {low:.3f} m < intended support {expect[a.name]:.3f} m")
        if np.linalg.norm(pos[:2]) > ROLL_AWAY:
            ok = False
            why.append(f"{a.name} rolled away to {pos[:2].round(2).tolist()}")
    return ok, after, {"max_drift_m": worst_t, "max_drift_deg": worst_r}, why


# ---------------------------------------------------------------------------------------------------------- degrade
def degrade_and_write(out: Path, name: str, rng: np.random.Generator, sim: Sim, poses: Poses, settle: dict,
                      seed_info: dict, noise: float) -> dict:
    """Draw the camera, the tilt and the per-object errors; write the degraded scene and its ground truth.

    Parameters
    ----------
    out : output folder (``scenes/<name>/`` and ``gt/<name>.json`` are written under it).
    name : scene name.
    rng : the degradation's random stream (camera, tilt, then per object: translation, rotation, scale).
    sim : the settled world (its assets and contacts).
    poses : the settled poses, centroid (3,) and rotation (3, 3) per object.
    settle : the settling drift (``settle_and_check``).
    seed_info : the seed, scene index, attempt and stream of the scene.
    noise : scale of the per-object errors (0: none; the camera and tilt are drawn the same).

    Returns
    -------
    The ground truth as written.
    """
    assets = sim.assets
    allv = np.vstack([a.mesh.vertices @ R.T + t for a, (t, R) in zip(assets, poses)])
    lo, hi = allv.min(0), allv.max(0)
    target = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) * CAM_TARGET_HEIGHT])
    az, el = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(*CAM_ELEVATION_DEG))
    dist = rng.uniform(*CAM_DISTANCE_M) + CAM_EXTENT_GAIN * max(0.0, float(np.max(hi[:2] - lo[:2])) - 1.0)
    back = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    eye = target + dist * back
    right = np.cross(-back, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    tilt = float(rng.uniform(*TILT_DEG))
    spread = np.radians(rng.uniform(-TILT_AXIS_SPREAD_DEG, TILT_AXIS_SPREAD_DEG))
    axis = yaw(rng, spread) @ right * rng.choice([-1.0, 1.0])
    R_tilt = Rotation.from_rotvec(np.radians(tilt) * axis).as_matrix()
    Rg = Z_UP_TO_Y_UP @ R_tilt  # world (z-up) -> degraded frame rotation
    tg = -Rg @ eye  # the camera's eye at the origin
    G = homogeneous(Rg, tg)
    Ginv = np.linalg.inv(G)

    sdir = out / "scenes" / name
    sdir.mkdir(parents=True, exist_ok=True)
    for f in sdir.glob("*.obj"):
        f.unlink()
    gt = {"scene": name, "seed_info": seed_info, "settle": settle, "tilt_deg": tilt, "tilt_axis_world": axis.tolist(),
          "world_to_degraded": G.tolist(), "degraded_to_world": Ginv.tolist(),
          "camera_world": {"eye": eye.tolist(), "target": target.tolist(), "fov_y_deg": FOV_Y_DEG},
          "contacts_at_rest": sim.contacts(), "objects": {}, "conventions": CONVENTIONS}
    for a, (c, R) in zip(assets, poses):
        ray = c - eye
        depth = float(np.linalg.norm(ray))
        ray /= depth
        p1 = np.cross(ray, [0, 0, 1.0])
        p1 /= np.linalg.norm(p1)
        p2 = np.cross(ray, p1)
        dt = (ray * rng.normal(0, DEPTH_ERROR * depth) + p1 * rng.normal(0, SIDE_ERROR_M)
              + p2 * rng.normal(0, SIDE_ERROR_M))
        eul = rng.normal(0, ROTATION_ERROR_DEG, 3)
        s = float(rng.uniform(*SCALE_ERROR))
        dt, eul, s = noise * dt, noise * eul, 1.0 + noise * (s - 1.0)
        R_err = Rotation.from_euler("xyz", eul, degrees=True).as_matrix()
        Rd, td = R_err @ R, c + dt
        Vw = (s * a.mesh.vertices) @ Rd.T + td
        Vd = Vw @ Rg.T + tg
        trimesh.Trimesh(Vd, a.mesh.faces, process=False).export(sdir / f"{a.name}.obj", include_normals=False,
                                                                 include_texture=False)
        # OBJ vertex (degraded frame) -> GT vertex (world)
        M = homogeneous(R, c) @ np.diag([1 / s, 1 / s, 1 / s, 1.0]) @ np.linalg.inv(homogeneous(Rd, td)) @ Ginv
        gt["objects"][a.name] = {
            "asset": a.source, "mass_kg": a.mass, "n_faces": int(len(a.mesh.faces)),
            "volume_m3": float(a.mesh.volume), "watertight": bool(a.mesh.is_watertight),
            "extents_m": a.mesh.extents.tolist(),
            "gt_centroid_world": c.tolist(), "gt_rotation": R.tolist(),
            "deg_centroid_world": td.tolist(), "deg_rotation_world": Rd.tolist(), "scale_error": s,
            "deg_centroid_degraded_frame": (Rg @ td + tg).tolist(),
            "error_translation_m": dt.tolist(), "error_translation_norm_m": float(np.linalg.norm(dt)),
            "error_translation_along_ray_m": float(dt @ ray), "depth_m": depth,
            "error_rotation_euler_xyz_deg": eul.tolist(),
            "error_rotation_angle_deg": float(np.degrees(Rotation.from_matrix(R_err).magnitude())),
            "degraded_to_gt_vertices": M.tolist()}
    cam = {"eye": (Rg @ eye + tg).tolist(), "target": (Rg @ target + tg).tolist(), "fov_y_deg": FOV_Y_DEG}
    (sdir / "camera.json").write_text(json.dumps(cam, indent=1))
    (out / "gt").mkdir(parents=True, exist_ok=True)
    (out / "gt" / f"{name}.json").write_text(json.dumps(gt, indent=1))
    return gt


def build(out: Path, seed: int, noise: float, only: list[str] | None = None, max_attempts: int = MAX_ATTEMPTS
          ) -> dict:
    """Build, check, degrade and write every scene kind (those in ``only`` when given) and ``summary*.json``.

    Returns
    -------
    The summary: per scene, its objects' assets, tilt (deg), attempt and settling drift.
    """
    cache = out / "cache"
    summary = {}
    for idx, (kind, fn) in enumerate(KINDS):
        if only and kind not in only:
            continue
        name = f"{SCENE_PREFIX}_{idx}_{kind}" + ("" if noise == 1.0 else f"_noise{noise:g}")
        for attempt in range(max_attempts):
            rng = np.random.default_rng([seed, idx, attempt])
            sim = Sim(f"{idx}_{attempt}", cache)
            try:
                expect = fn(rng, sim, cache)
                ok, poses, settle, why = settle_and_check(sim, expect)
                if not ok:
                    print(f"{name} attempt {attempt}: rejected ({'; '.join(why)})", flush=True)
                    continue
                if not MIN_OBJECTS <= len(sim.assets) <= MAX_OBJECTS:
                    print(f"{name} attempt {attempt}: rejected ({len(sim.assets)} objects)", flush=True)
                    continue
                seed_info = {"seed": seed, "scene_index": idx, "attempt": attempt,
                             "rng": f"default_rng([{seed}, {idx}, {attempt}])"}
                gt = degrade_and_write(out, name, np.random.default_rng([seed, idx, attempt, 1]), sim, poses, settle,
                                       seed_info, noise)
                summary[name] = {"objects": {k: v["asset"] for k, v in gt["objects"].items()},
                                 "tilt_deg": gt["tilt_deg"], "attempt": attempt, "settle": gt["settle"]}
                print(f"{name}: {len(sim.assets)} objects, attempt {attempt}, tilt {gt['tilt_deg']:.2f} deg, "
                      f"drift {settle['max_drift_m'] * 1000:.3f} mm / {settle['max_drift_deg']:.3f} deg", flush=True)
                break
            finally:
                sim.close()
        else:
            print(f"{name}: FAILED after {max_attempts} attempts", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / ("summary.json" if noise == 1.0 else f"summary_noise{noise:g}.json")).write_text(json.dumps(summary,
                                                                                                      indent=1))
    return summary


# ----------------------------------------------------------------------------------------------------------- report
def levelling_report(out: Path, levelled: Path) -> list[dict]:
    """Compare ``phiscene import-placed``'s levelling with the truth, per scene of ``out/gt``; prints a table.

    Reads ``levelled/<scene>/import.json`` (``transform``: 4x4, the scene's file frame -> the levelled z-up frame;
    ``levelling_rotation_deg``). The true up in the file frame is ``world_to_degraded[:3, :3] @ z``, the estimated
    one ``transform[:3, :3].T @ z``.

    Returns
    -------
    Per imported scene: ``scene``, ``tilt_deg`` (applied), ``levelling_deg`` (the rotation import-placed applied),
    ``up_error_deg`` (angle between the true and the estimated up) and ``floor_z_m`` (height in the levelled frame of
    the true floor point below the camera's target).
    """
    gts = sorted((out / "gt").glob("*.json"))
    if not gts:
        raise SystemExit(f"no ground truth under {out / 'gt'} (build it: python benchmarks/asset_scenes.py {out})")
    rows, missing = [], []
    for path in gts:
        gt = json.loads(path.read_text())
        imp_path = levelled / gt["scene"] / "import.json"
        if not imp_path.is_file():
            missing.append(gt["scene"])
            continue
        imp = json.loads(imp_path.read_text())
        T, G = np.array(imp["transform"]), np.array(gt["world_to_degraded"])
        up_true = G[:3, :3] @ [0, 0, 1.0]
        up_est = T[:3, :3].T @ [0, 0, 1.0]
        cos = up_true @ up_est / (np.linalg.norm(up_true) * np.linalg.norm(up_est))
        target = gt["camera_world"]["target"]
        floor_z = float((T @ G @ [target[0], target[1], 0.0, 1.0])[2])
        rows.append({"scene": gt["scene"], "tilt_deg": gt["tilt_deg"], "levelling_deg": imp["levelling_rotation_deg"],
                     "up_error_deg": float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))), "floor_z_m": floor_z})
    w = max([len(r["scene"]) for r in rows] + [5])
    print(f"{'scene':{w}s} {'tilt':>6s} {'level':>6s} {'up_err':>6s} {'floor_z':>8s}  (deg, deg, deg, m)")
    for r in rows:
        print(f"{r['scene']:{w}s} {r['tilt_deg']:6.2f} {r['levelling_deg']:6.2f} {r['up_error_deg']:6.2f} "
              f"{r['floor_z_m']:8.4f}")
    if missing:
        print(f"not imported under {levelled}: {', '.join(missing)}")
    return rows


def aligned_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (n,) between points ``a`` (n, 3) and ``b`` (n, 3) after the rigid motion that best maps ``a`` onto
    ``b`` (Kabsch): the frames of a levelled scene and of its ground truth differ by the levelling's error."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return np.linalg.norm((a - ca) @ R.T + cb - b, axis=1)


def grounding_report(out: Path, levelled: Path, grounded: Path) -> list[dict]:
    """Compare grounded scenes with the truth, per scene of ``out/gt``; prints a table.

    Each object's centre (``center_mass`` of its mesh) is compared in three states: the truth (the file's mesh mapped
    by ``degraded_to_gt_vertices``), the levelled input (``levelled/<scene>/initial/scene.json``) and the grounded
    scene (``grounded/<scene>/scene.json``, with ``assembly.json``); the two last are brought onto the truth by the
    best rigid motion of their centres (:func:`aligned_distances`).

    Returns
    -------
    Per grounded scene: ``scene``, ``input_error_m`` and ``grounded_error_m`` (mean over objects),
    ``displacement_mean_m`` / ``displacement_max_m`` (grounded centre from the input's), ``settled`` and ``objects``.
    """
    from phiscene.scene import load_scene

    rows = []
    for path in sorted((out / "gt").glob("*.json")):
        gt = json.loads(path.read_text())
        name = gt["scene"]
        if not (grounded / name / "scene.json").is_file():
            continue
        initial = load_scene(levelled / name / "initial" / "scene.json")
        result = load_scene(grounded / name / "scene.json")
        ids = [o.id for o in initial.objects]
        truth = np.array([trimesh.load(out / "scenes" / name / f"{i}.obj", force="mesh").apply_transform(
            np.array(gt["objects"][i]["degraded_to_gt_vertices"])).center_mass for i in ids])
        before = np.array([initial.get(i).world_mesh().center_mass for i in ids])
        after = np.array([result.get(i).world_mesh().center_mass for i in ids])
        moved = np.linalg.norm(after - before, axis=1)
        summary = json.loads((grounded / name / "assembly.json").read_text())["summary"]
        rows.append({"scene": name, "input_error_m": float(aligned_distances(before, truth).mean()),
                     "grounded_error_m": float(aligned_distances(after, truth).mean()),
                     "displacement_mean_m": float(moved.mean()), "displacement_max_m": float(moved.max()),
                     "settled": int(summary["settled"]), "objects": int(summary["objects"])})
    w = max([len(r["scene"]) for r in rows] + [5])
    print(f"{'scene':{w}s} {'input':>6s} {'ground':>6s} {'moved':>6s} {'max':>6s} settled  (GT centre error, cm)")
    for r in rows:
        print(f"{r['scene']:{w}s} {100 * r['input_error_m']:6.2f} {100 * r['grounded_error_m']:6.2f} "
              f"{100 * r['displacement_mean_m']:6.2f} {100 * r['displacement_max_m']:6.2f} "
              f"{r['settled']}/{r['objects']}")
    return rows


def main(argv: list[str] | None = None) -> None:
    """Build the scenes into OUT, or with ``--report`` compare an import's levelling with OUT's ground truth.

    Parameters
    ----------
    argv : command-line arguments (``sys.argv[1:]`` when None).
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="output folder (scenes/, gt/, cache/, summary*.json)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--noise-scale", type=float, default=1.0,
                    help="multiply the per-object errors (0: same scenes and tilt, no per-object error; the scene "
                         "names get a suffix _noise<scale>)")
    ap.add_argument("--only", nargs="*", choices=[k for k, _ in KINDS], help="scene kinds to build (default all)")
    ap.add_argument("--max-attempts", type=int, default=MAX_ATTEMPTS)
    ap.add_argument("--report", type=Path, metavar="LEVELLED_DIR",
                    help="build nothing: compare the levelling of the scenes imported under LEVELLED_DIR/<scene> "
                         "with OUT/gt")
    ap.add_argument("--grounded", type=Path, metavar="GROUNDED_DIR",
                    help="with --report: also compare the scenes grounded under GROUNDED_DIR/<scene> with OUT/gt")
    a = ap.parse_args(argv)
    if a.report is not None:
        levelling_report(a.out, a.report)
        if a.grounded is not None:
            grounding_report(a.out, a.report, a.grounded)
        return
    build(a.out, a.seed, a.noise_scale, a.only, a.max_attempts)


if __name__ == "__main__":
    main()
