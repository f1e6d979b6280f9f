"""pybullet, in one place: clients, engine settings, and worlds of convex-proxy bodies.

Every pybullet client of phiscene (settling, drift, ground truth, rendering, the demo, the exported-scene
checks) is opened here: :func:`bullet_client` gives a headless client as pybullet_utils' ``BulletClient``
(every call bound to its client, no ``physicsClientId`` keywords), disconnected on exit, and
:func:`configure_engine` applies the deterministic engine settings.

Bodies are built from convex proxies (a compound of convex hulls written to an
OBJ file whose name is the hash of the hull vertices: pybullet caches collision
meshes by file path). Poses in and out are phiscene poses (local-to-world
4x4 with uniform scale); the conversion to pybullet's centre-of-mass frame is
done here and nowhere else.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.atomic import write_text
from phiscene.inertia import RigidProps
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import decompose, make_pose, matrix_to_quat_xyzw, quat_xyzw_to_matrix

log = logging.getLogger(__name__)

#: Half thickness of the ground box (m); its top face is the ground plane.
GROUND_HALF_THICKNESS = 0.5
#: Half extent of the ground box in x and y (m).
GROUND_HALF_EXTENT = 50.0
#: pybullet's collision filter (group, mask) of a dynamic body, and of a static one (created with mass 0 or frozen
#: by :meth:`BulletWorld.set_static`, which pybullet's mass change re-filters): Bullet's DefaultFilter / AllFilter
#: and StaticFilter / AllFilter but StaticFilter (:meth:`BulletWorld.forget_contacts`). Static bodies never pair.
FILTER_DYNAMIC = (1, -1)
FILTER_STATIC = (2, -3)


def hulls_obj_text(hulls: list[np.ndarray]) -> str:
    """OBJ text with one ``o`` group per convex hull (pybullet makes each a convex shape).

    Parameters
    ----------
    hulls
        Each ``(v, 3)`` float vertices of one convex piece.
    """
    import trimesh

    lines = []
    offset = 0
    for k, v in enumerate(hulls):
        hull = trimesh.convex.convex_hull(np.asarray(v, dtype=float))
        lines.append(f"o hull{k}")
        lines.extend(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in hull.vertices)
        lines.extend(f"f {a + 1 + offset} {b + 1 + offset} {c + 1 + offset}" for a, b, c in hull.faces)
        offset += len(hull.vertices)
    return "\n".join(lines) + "\n"


#: Format of the cached hull OBJ files (part of their names: a change makes new files).
HULL_OBJ_VERSION = 2


def _hulls_key(hulls: list[np.ndarray]) -> str:
    """SHA-256 (20 hex digits) of the hull vertex arrays: the cache key of their OBJ file."""
    h = hashlib.sha256(f"phiscene.bullet_hulls/{HULL_OBJ_VERSION}".encode())
    for v in hulls:
        a = np.ascontiguousarray(v, dtype=np.float64)
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:20]


def _valid_hull_file(path: Path) -> bool:
    """Whether a cached hull OBJ is whole: its first line holds the SHA-256 of the rest."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    head, _, body = data.partition(b"\n")
    return head == b"# sha256 " + hashlib.sha256(body).hexdigest().encode()


def hulls_obj_file(hulls: list[np.ndarray], cache_dir: str | Path) -> Path:
    """The hulls as an OBJ file in the cache (written once, atomically); its path.

    The file is named by a hash of the hull vertices, so the convex hulls are rebuilt only when the
    file is missing; pybullet caches collision shapes by file name, so equal names must mean equal
    content. Its first line holds the SHA-256 of the rest: a damaged file is detected and rewritten.
    """
    path = Path(cache_dir) / "bullet_hulls" / f"{_hulls_key(hulls)}.obj"
    if not _valid_hull_file(path):
        if path.exists():
            log.warning("hull cache file %s is damaged; rewriting it", path)
        body = hulls_obj_text(hulls)
        write_text(path, f"# sha256 {hashlib.sha256(body.encode()).hexdigest()}\n{body}")
    return path


def open_client():
    """A new headless pybullet client: a ``pybullet_utils.bullet_client.BulletClient`` in DIRECT mode.

    Connected without BulletClient's ``options`` argument, which makes pybullet print ``argv[0]=`` on stdout
    (stdout carries the ``phiscene`` command's JSON). The caller disconnects it (``client.disconnect()``);
    :func:`bullet_client` does that for a ``with`` block.
    """
    import os

    import pybullet as p
    from pybullet_utils.bullet_client import BulletClient

    class _DirectClient(BulletClient):
        def __init__(self):  # what BulletClient.__init__ does for DIRECT, minus the options argument
            self._shapes = {}
            self._pid = os.getpid()
            self._client = p.connect(p.DIRECT)

    return _DirectClient()


@contextmanager
def bullet_client() -> Iterator:
    """A headless pybullet client for a ``with`` block, disconnected on exit (also on error)."""
    client = open_client()
    try:
        yield client
    finally:
        client.disconnect()


def configure_engine(client, time_step: float, solver_iterations: int, gravity) -> None:
    """Reset a client's world and apply phiscene's engine settings.

    Parameters
    ----------
    client
        A client of :func:`open_client`.
    time_step
        Seconds per ``stepSimulation`` call (no internal sub-stepping).
    solver_iterations
        Constraint solver iterations per step.
    gravity : (3,) float
        Gravity vector (m/s^2).
    """
    client.resetSimulation()
    client.setPhysicsEngineParameter(fixedTimeStep=time_step, numSolverIterations=solver_iterations,
                                     deterministicOverlappingPairs=1, numSubSteps=0)
    client.setGravity(*[float(g) for g in gravity])


@dataclass
class _Body:
    uid: int
    scale: float
    inertial: np.ndarray  # (4, 4) COM frame in the scaled, unscaled-rotation link frame
    dynamic: bool
    props: RigidProps | None = None  # what makes it dynamic again after set_static
    inverse: np.ndarray = field(init=False)  # (4, 4) inverse of inertial, read at every pose query

    def __post_init__(self) -> None:
        self.inverse = np.linalg.inv(self.inertial)


class BulletWorld:
    """A pybullet DIRECT world with deterministic settings.

    Use as a context manager; the client is disconnected on exit, also on error.

    Parameters
    ----------
    settings
        Physical settings (friction, damping, frame time, substeps, ...).
    cache_dir
        Folder for the content-hashed hull OBJ files.
    """

    def __init__(self, settings: SimSettings, cache_dir: str | Path):
        self.settings = settings
        self.cache_dir = Path(cache_dir)
        self.p = None  # the BulletClient while the world is open
        self.bodies: dict[str, _Body] = {}

    def __enter__(self) -> "BulletWorld":
        self.p = open_client()
        configure_engine(self.p, self.settings.frame_dt / self.settings.substeps, self.settings.solver_iterations,
                         (0.0, 0.0, -GRAVITY))
        return self

    def __exit__(self, *exc) -> None:
        if self.p is not None:
            self.p.disconnect()
            self.p = None

    # -- building -----------------------------------------------------------------
    def _surface(self, uid: int) -> None:
        s = self.settings
        self.p.changeDynamics(uid, -1, lateralFriction=s.friction, rollingFriction=s.rolling_friction,
                         spinningFriction=s.spinning_friction, restitution=s.restitution,
                         linearDamping=s.linear_damping, angularDamping=s.angular_damping)

    def add_ground(self, height: float) -> int:
        """A static box whose top face is the plane ``z = height``; returns its body id."""
        shape = self.p.createCollisionShape(self.p.GEOM_BOX, halfExtents=[GROUND_HALF_EXTENT, GROUND_HALF_EXTENT,
                                                                GROUND_HALF_THICKNESS])
        uid = self.p.createMultiBody(0.0, shape, basePosition=[0, 0, height - GROUND_HALF_THICKNESS])
        self._surface(uid)
        self.bodies["ground"] = _Body(uid, 1.0, np.eye(4), False)
        return uid

    def add_structure(self, planes) -> list[int]:
        """Walls and ceiling (:class:`phiscene.scene.Plane`) as static infinite planes (pybullet ``GEOM_PLANE``).

        Each plane is a static body named by the plane's id (so contacts and :meth:`contact_forces`
        name it like an object), with the world's friction; its solid side is the half-space behind
        the plane (``normal . p + offset < 0``), the room side is free. Returns the body ids.
        """
        uids = []
        for plane in planes:
            if plane.id in self.bodies:
                raise ValueError(f"body {plane.id!r} already in the world")
            n = np.asarray(plane.normal, dtype=float)
            shape = self.p.createCollisionShape(self.p.GEOM_PLANE, planeNormal=n.tolist())
            uid = self.p.createMultiBody(0.0, shape, basePosition=(-float(plane.offset) * n).tolist())
            self._surface(uid)
            self.bodies[plane.id] = _Body(uid, 1.0, np.eye(4), False)
            uids.append(uid)
        return uids

    def add_body(self, name: str, hulls: list[np.ndarray], pose: np.ndarray, props: RigidProps | None) -> int:
        """Add an object as a compound of convex hulls.

        Parameters
        ----------
        name
            Object id (``ground`` is reserved).
        hulls
            Convex pieces, each ``(v, 3)`` unscaled local vertices.
        pose : (4, 4) float
            Local-to-world pose, uniform scale allowed.
        props
            Mass properties at this pose's scale; ``None`` makes the body static.
        """
        if name in self.bodies:
            raise ValueError(f"body {name!r} already in the world")
        _, _, scale = decompose(pose)
        obj = hulls_obj_file(hulls, self.cache_dir)
        shape = self.p.createCollisionShape(self.p.GEOM_MESH, fileName=str(obj), meshScale=[scale] * 3)
        if shape < 0:
            raise RuntimeError(f"pybullet could not build a collision shape for {name!r} from {obj}")
        if props is None:
            inertial = np.eye(4)
            uid = self.p.createMultiBody(0.0, shape)
        else:
            inertial = make_pose(props.principal_axes, props.com)
            uid = self.p.createMultiBody(props.mass, shape, baseInertialFramePosition=props.com.tolist(),
                                    baseInertialFrameOrientation=matrix_to_quat_xyzw(props.principal_axes).tolist())
            self.p.changeDynamics(uid, -1, localInertiaDiagonal=props.principal_moments.tolist())
        self.p.changeDynamics(uid, -1, collisionMargin=self.settings.collision_margin)
        self._surface(uid)
        self.bodies[name] = _Body(uid, scale, inertial, props is not None, props)
        self.set_pose(name, pose)
        return uid

    def remove_body(self, name: str) -> None:
        """Take body ``name`` out of the world (to add it again with other mass properties)."""
        self.p.removeBody(self.bodies.pop(name).uid)

    # -- poses ----------------------------------------------------------------------
    def set_pose(self, name: str, pose: np.ndarray) -> None:
        """Place body ``name`` at phiscene pose ``pose`` (its scale must match the body's), zero its velocity and drop
        the contacts Bullet kept of it (:meth:`forget_contacts`): it starts as in a new world."""
        b = self.bodies[name]
        R, t, _ = decompose(pose)
        com_frame = make_pose(R, t) @ b.inertial
        self.p.resetBasePositionAndOrientation(b.uid, com_frame[:3, 3].tolist(),
                                          matrix_to_quat_xyzw(com_frame[:3, :3]).tolist())
        self.p.resetBaseVelocity(b.uid, [0, 0, 0], [0, 0, 0])
        self.forget_contacts(name)

    def forget_contacts(self, name: str) -> None:
        """Drop the contacts Bullet keeps of body ``name`` (its persistent manifolds and their warm-started impulses).

        Bullet builds a contact between convex shapes up one point per step and keeps it across steps and across
        :meth:`set_pose`: a body put back where it rested in a used world stands on the full contact it had,
        while the same pose in a new world (the release of the whole scene, the drift protocol) starts from one
        point and may tip before the rest are found. Grounding's tests (settling, the tilt test, carriers under
        load) must answer what a new world answers. Re-registering the body's collision filter (the defaults
        pybullet gives a body created dynamic or static) takes it out of the broadphase and back, which destroys
        its pairs and their manifolds. The filter is the one of the body's current state: a frozen body re-registered
        as dynamic would pair with every static body at each step (contacts without effect, at a cost that grew
        with every frozen object put back).
        """
        b = self.bodies[name]
        group, mask = FILTER_DYNAMIC if b.dynamic else FILTER_STATIC
        self.p.setCollisionFilterGroupMask(b.uid, -1, group, mask)

    def pose(self, name: str) -> np.ndarray:
        """Current phiscene pose (4, 4) of body ``name``, scale included."""
        b = self.bodies[name]
        pos, quat = self.p.getBasePositionAndOrientation(b.uid)
        com_frame = make_pose(quat_xyzw_to_matrix(quat), pos)
        link = com_frame @ b.inverse
        return make_pose(link[:3, :3], link[:3, 3], b.scale)

    def com_position(self, name: str) -> np.ndarray:
        """World position (3,) of the centre of mass of body ``name``."""
        pos, _ = self.p.getBasePositionAndOrientation(self.bodies[name].uid)
        return np.asarray(pos, dtype=float)

    def velocity(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Linear (3,) and angular (3,) velocity of body ``name``."""
        lin, ang = self.p.getBaseVelocity(self.bodies[name].uid)
        return np.asarray(lin), np.asarray(ang)

    def set_gravity(self, direction=(0.0, 0.0, -1.0)) -> None:
        """Point gravity (magnitude ``GRAVITY``) along the unit vector ``direction`` (3,); default straight down."""
        d = np.asarray(direction, dtype=float)
        self.p.setGravity(*(GRAVITY * d / np.linalg.norm(d)).tolist())

    def set_static(self, name: str) -> None:
        """Freeze body ``name`` in place (mass 0)."""
        b = self.bodies[name]
        self.p.changeDynamics(b.uid, -1, mass=0.0)
        self.p.resetBaseVelocity(b.uid, [0, 0, 0], [0, 0, 0])
        b.dynamic = False

    def set_dynamic(self, name: str) -> None:
        """Release body ``name`` frozen by :meth:`set_static` (its mass and inertia back, at rest).

        Raises
        ------
        ValueError
            The body was added static (no mass properties to give back).
        """
        b = self.bodies[name]
        if b.props is None:
            raise ValueError(f"body {name!r} was added static")
        self.p.changeDynamics(b.uid, -1, mass=float(b.props.mass),
                              localInertiaDiagonal=b.props.principal_moments.tolist())
        self.p.resetBaseVelocity(b.uid, [0, 0, 0], [0, 0, 0])
        b.dynamic = True

    # -- stepping -----------------------------------------------------------------
    def step_frames(self, frames: int = 1) -> None:
        """Advance ``frames`` frames of ``settings.frame_dt`` (each ``settings.substeps`` steps)."""
        for _ in range(frames * self.settings.substeps):
            self.p.stepSimulation()

    def contacts(self, name_a: str, name_b: str | None = None) -> list[dict]:
        """Contact points of body ``name_a`` (with ``name_b`` only, if given).

        Returns
        -------
        A list of dicts with ``other`` (name), ``position`` (3,) on B, ``normal`` (3,) from B to A,
        ``distance`` (negative = penetration) and ``force`` (normal force, N).
        """
        names = {b.uid: n for n, b in self.bodies.items()}
        a = self.bodies[name_a].uid
        kw = {"bodyA": a}
        if name_b is not None:
            kw["bodyB"] = self.bodies[name_b].uid
        out = []
        for c in self.p.getContactPoints(**kw):
            out.append({"other": names.get(c[2], str(c[2])), "position": np.asarray(c[6]),
                        "normal": np.asarray(c[7]), "distance": float(c[8]), "force": float(c[9])})
        return out

    def contact_forces(self) -> dict[tuple[str, str], np.ndarray]:
        """Total contact force (normal + lateral friction, N) on body A from body B, per touching pair.

        Uses the unfiltered contact query, whose (A, B) order is Bullet's own; a
        query filtered by body may swap A and B and flips the normal but not the
        friction directions, so it cannot be summed this way.

        Returns
        -------
        ``{(name_a, name_b): (3,) float}``, each touching pair once; the force on B from A is the negative.
        """
        names = {b.uid: n for n, b in self.bodies.items()}
        out: dict[tuple[str, str], np.ndarray] = {}
        for c in self.p.getContactPoints():
            f = np.asarray(c[7]) * c[9] + c[10] * np.asarray(c[11]) + c[12] * np.asarray(c[13])
            key = (names.get(c[1], str(c[1])), names.get(c[2], str(c[2])))
            out[key] = out.get(key, 0.0) + f
        return out

    # -- faithful grounding helpers ------------------------------------------------
    def set_dynamics(self, name: str, **kwargs) -> None:
        """Change pybullet dynamics of body ``name`` (``linearDamping``, ``rollingFriction``, ...)."""
        self.p.changeDynamics(self.bodies[name].uid, -1, **kwargs)

    def restore_dynamics(self, name: str) -> None:
        """Reset the friction and damping of body ``name`` to the world's settings."""
        self._surface(self.bodies[name].uid)

    def _nearest_points(self, name: str, others: list[str], max_distance: float) -> dict:
        """Per body of ``others`` within ``max_distance`` (m) of body ``name``: Bullet's closest-point record with
        the smallest signed distance (negative = overlap). Bodies farther (or not in the world) are left out."""
        out = {}
        a = self.bodies[name].uid
        for o in others:
            if o not in self.bodies:
                continue
            pts = self.p.getClosestPoints(a, self.bodies[o].uid, max_distance)
            if pts:
                out[o] = min(pts, key=lambda c: c[8])
        return out

    def distances(self, name: str, others: list[str], max_distance: float) -> dict[str, float]:
        """Smallest signed distance (m) from body ``name`` to each of ``others`` within ``max_distance``.

        Bodies farther than ``max_distance`` (or not in the world) are left out.
        """
        return {o: d for o, (d, _) in self.nearest(name, others, max_distance).items()}

    def nearest(self, name: str, others: list[str], max_distance: float) -> dict[str, tuple[float, np.ndarray]]:
        """Per body of ``others`` within ``max_distance`` (m) of body ``name``: the smallest signed distance (m;
        negative = overlap) and the unit normal (3,) there, pointing from the other body towards ``name``.

        Bodies farther (or not in the world) are left out.
        """
        return {o: (float(c[8]), np.asarray(c[7], dtype=float))
                for o, c in self._nearest_points(name, others, max_distance).items()}

    def deepest_overlaps(self, name: str, others: list[str], depth: float) -> dict[str, tuple[float, np.ndarray]]:
        """Where body ``name`` overlaps each of ``others`` deeper than ``depth`` (m): the deepest point's signed
        distance (negative) and its unit normal (3,) pointing from the other body towards ``name``.

        Bodies overlapping less (or not in the world) are left out.
        """
        return {o: v for o, v in self.nearest(name, others, 0.0).items() if v[0] < -depth}
