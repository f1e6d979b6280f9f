"""Physical metrics (penetration, floating, post-simulation drift) on tiny scenes with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from phiscene.errors import InputError
from phiscene.meshes import save_mesh
from phiscene.metrics.drift import drift_bullet
from phiscene.metrics.physical import (
    PhysicalParams,
    box_gaps,
    contact_validity,
    object_seed,
    physical_metrics,
)
from phiscene.proxies import ProxyParams, scene_proxies
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import make_pose, rotation_z

RANDOM_URDFS = Path(__import__("pybullet_data").getDataPath()) / "random_urdfs"
SIM = SimSettings()
FAST = PhysicalParams(samples=1024)


def write_scene(tmp_path: Path, objects: list[tuple[str, trimesh.Trimesh, np.ndarray]], ground: float = 0.0,
                name: str = "scene") -> Scene:
    """Save meshes (GLB) and a scene.json under ``tmp_path`` and load it back through the real loader."""
    objs = []
    for oid, mesh, pose in objects:
        path = save_mesh(mesh, tmp_path / name / "meshes" / f"{oid}.glb")
        objs.append(SceneObject(id=oid, mesh_path=path, pose=pose))
    return load_scene(save_scene(Scene(objects=objs, ground_height=ground), tmp_path / name / "scene.json"))


def box(ex: float, ey: float, ez: float) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[ex, ey, ez])


def at(x: float, y: float, z: float, angle: float = 0.0) -> np.ndarray:
    return make_pose(rotation_z(angle), [x, y, z])


def proxies_of(scene: Scene, tmp_path: Path) -> dict:
    return scene_proxies(scene, ProxyParams(backend="convex"), tmp_path / "cache")


def test_box_resting_on_ground(tmp_path):
    scene = write_scene(tmp_path, [("a", box(0.2, 0.2, 0.1), at(0.0, 0.0, 0.05, 0.3))])
    out = physical_metrics(scene, proxies_of(scene, tmp_path), PhysicalParams(), SIM, tmp_path / "cache")
    obj = out["objects"]["a"]
    # GLB stores float32 vertices: the bottom face sits within ~1e-9 m of the ground
    assert out["pen_depth"] < 1e-8 and out["float_dist"] < 1e-8 and obj["closest"] == "ground"
    assert out["drift_trans"] < 1e-4 and out["drift_rot"] < 0.05
    assert out["ground_below"] == pytest.approx(0.0, abs=1e-8)
    assert set(out) >= {"pen_depth", "float_dist", "drift_trans", "drift_rot", "objects", "params"}
    assert out["params"] == PhysicalParams().to_dict()


def test_upward_offset_is_subtracted(tmp_path):
    scene = write_scene(tmp_path, [("a", box(0.2, 0.2, 0.1), at(0.0, 0.0, 0.05))])
    proxies = proxies_of(scene, tmp_path)
    lifted = drift_bullet(scene, proxies, PhysicalParams(upward_offset=0.02), SIM, tmp_path / "cache")
    # a 2 cm drop back onto the same support: the lift itself is not drift
    assert lifted["objects"]["a"]["drift_trans"] < 1e-3
    assert lifted["drift_rot"] < 0.05


def test_boxes_overlapping_10mm_both_penetrate(tmp_path):
    scene = write_scene(tmp_path, [("low", box(0.2, 0.2, 0.1), at(0.0, 0.0, 0.05)),
                                   ("top", box(0.1, 0.1, 0.1), at(0.0, 0.0, 0.1 + 0.05 - 0.010, 0.4))])
    out = contact_validity(scene, FAST)
    for oid in ("low", "top"):
        assert out["objects"][oid]["pen_depth"] == pytest.approx(0.010, abs=5e-4)
        assert out["objects"][oid]["float_dist"] == 0.0
    assert out["objects"]["top"]["closest"] == "low" and out["objects"]["low"]["closest"] == "top"
    assert out["pen_depth"] == pytest.approx(0.010, abs=5e-4)


def test_box_5mm_above_another_floats(tmp_path):
    scene = write_scene(tmp_path, [("low", box(0.2, 0.2, 0.1), at(0.0, 0.0, 0.05)),
                                   ("top", box(0.1, 0.1, 0.1), at(0.02, -0.01, 0.1 + 0.05 + 0.005, 0.7))])
    out = contact_validity(scene, FAST)
    top, low = out["objects"]["top"], out["objects"]["low"]
    assert top["float_dist"] == pytest.approx(0.005, abs=5e-4) and top["pen_depth"] == 0.0
    assert top["closest"] == "low"
    assert low["float_dist"] < 1e-8 and low["closest"] == "ground"  # rests on the ground
    assert out["float_dist"] == pytest.approx((top["float_dist"] + low["float_dist"]) / 2)


def test_floating_box_drifts_by_its_gap(tmp_path):
    # the drift ground goes right below the scene (under "low"); "top" falls its 3 cm gap onto "low"
    scene = write_scene(tmp_path, [("low", box(0.3, 0.3, 0.1), at(0.0, 0.0, 0.25)),
                                   ("top", box(0.1, 0.1, 0.1), at(0.0, 0.0, 0.3 + 0.05 + 0.03))])
    out = drift_bullet(scene, proxies_of(scene, tmp_path), PhysicalParams(), SIM, tmp_path / "cache")
    assert out["ground_below"] == pytest.approx(0.2)
    assert out["objects"]["top"]["drift_trans"] == pytest.approx(0.03, abs=1e-3)
    assert out["objects"]["low"]["drift_trans"] < 1e-3
    assert out["drift_trans"] == pytest.approx(np.mean([v["drift_trans"] for v in out["objects"].values()]))


def test_drift_ground_is_below_the_collision_proxies_not_a_mesh_tip_outside_them(tmp_path):
    """A chair leg's tip 7 mm through the floor, outside its proxy (which rests on the floor): the simulators never
    see that tip, so the drift ground stays at the floor and a box resting on it stays (a ground at the tip would
    drop every object 7 mm)."""
    from phiscene.proxies import Proxy

    leg = box(0.1, 0.1, 0.307)  # mesh from z = -0.007 ...
    scene = write_scene(tmp_path, [("leg", leg, at(0.0, 0.0, 0.1535 - 0.007)),
                                   ("box", box(0.2, 0.2, 0.2), at(0.5, 0.0, 0.1))])
    proxies = proxies_of(scene, tmp_path)
    local = np.asarray(leg.vertices, dtype=float).copy()  # ... its proxy from z = 0
    local[:, 2] = np.maximum(local[:, 2], -0.1535 + 0.007)
    proxies["leg"] = Proxy(hulls=[local], volume_ratio=1.0, max_outside=0.007)
    out = drift_bullet(scene, proxies, PhysicalParams(), SIM, tmp_path / "cache")
    assert out["ground_below"] == pytest.approx(0.0, abs=1e-8)  # GLB stores float32 vertices
    assert out["objects"]["box"]["drift_trans"] < 1e-3 and out["objects"]["leg"]["drift_trans"] < 1e-3


def test_toppling_box_rotates(tmp_path):
    # a tall board standing on one edge, tilted 30 deg from vertical (past its 9.5 deg tipping angle):
    # it falls flat onto its broad face, 60 deg further; rolling about the ground edge without slip, its
    # centre of mass goes from R_y(30) (-0.025, 0.15) to R_y(90) (-0.025, 0.15) relative to that edge
    R = trimesh.transformations.rotation_matrix(math.radians(30.0), [0, 1, 0])[:3, :3]
    mesh = box(0.05, 0.15, 0.3)
    pose = make_pose(R, [0.0, 0.0, 0.0])
    pose[2, 3] = -trimesh.transform_points(mesh.vertices, pose)[:, 2].min()
    scene = write_scene(tmp_path, [("a", mesh, pose)])
    out = drift_bullet(scene, proxies_of(scene, tmp_path), PhysicalParams(), SIM, tmp_path / "cache")
    assert out["drift_rot"] == pytest.approx(60.0, abs=2.0)
    rel = np.array([-0.025, 0.0, 0.15])
    Ry = [trimesh.transformations.rotation_matrix(math.radians(a), [0, 1, 0])[:3, :3] for a in (30.0, 90.0)]
    assert out["drift_trans"] == pytest.approx(np.linalg.norm(Ry[1] @ rel - Ry[0] @ rel), abs=0.01)


def test_free_fall_matches_kinematics(tmp_path):
    """Physics sanity check of the simulator the drift uses: no ground, no damping."""
    sim = SimSettings(linear_damping=0.0, angular_damping=0.0)
    hulls = [np.asarray(box(0.1, 0.1, 0.1).vertices)]
    from phiscene.inertia import rigid_props

    props = rigid_props(box(0.1, 0.1, 0.1), hulls, sim.density)
    frames = 60
    with BulletWorld(sim, tmp_path / "cache") as world:
        world.add_body("a", hulls, at(0.0, 0.0, 10.0), props)
        world.step_frames(frames)
        drop = 10.0 - world.com_position("a")[2]
        vz = world.velocity("a")[0][2]
    t, dt = frames * sim.frame_dt, sim.frame_dt / sim.substeps
    n = frames * sim.substeps
    # semi-implicit Euler (v += g dt; x += v dt) is exact for n steps: g dt^2 n (n + 1) / 2
    assert drop == pytest.approx(GRAVITY * dt**2 * n * (n + 1) / 2, rel=1e-6)
    assert abs(drop - 0.5 * GRAVITY * t**2) <= 0.5 * GRAVITY * t * dt * (1 + 1e-6)
    assert vz == pytest.approx(-GRAVITY * t, rel=1e-6)


def cluttered_scene(tmp_path: Path, name: str = "clutter", motion: np.ndarray | None = None, dz: float = 0.0) -> Scene:
    """Eight objects: a stack, a penetrating pair, a floating box, loose random_urdfs objects far apart."""
    urdf = trimesh.load(RANDOM_URDFS / "000" / "000.obj", force="mesh", process=False)
    urdf.apply_scale(0.01)
    urdf.apply_translation(-urdf.bounds.mean(axis=0))
    urdf2 = trimesh.load(RANDOM_URDFS / "018" / "018.obj", force="mesh", process=False)
    urdf2.apply_scale(0.01)
    urdf2.apply_translation(-urdf2.bounds.mean(axis=0))
    h0 = -urdf.bounds[0, 2]
    objs = [("base", box(0.4, 0.4, 0.1), at(0.0, 0.0, 0.05)),
            ("mid", box(0.2, 0.2, 0.1), at(0.01, 0.02, 0.15, 0.2)),
            ("top", urdf, at(0.0, 0.0, 0.2 + h0 - 0.004, 0.5)),
            ("pen_a", box(0.1, 0.1, 0.1), at(1.0, 0.0, 0.05)),
            ("pen_b", box(0.1, 0.1, 0.1), at(1.093, 0.01, 0.05)),
            ("float", box(0.1, 0.1, 0.05), at(-1.0, 0.5, 0.045)),
            ("far1", urdf2, at(2.0, 2.0, 0.3, 1.0)),
            ("far2", urdf, at(-2.0, -2.0, h0 + 0.01, 2.0))]
    if motion is not None:
        objs = [(oid, m, motion @ pose) for oid, m, pose in objs]
    return write_scene(tmp_path, objs, ground=dz, name=name)


@pytest.mark.parametrize("include_ground", [True, False])
def test_pruned_equals_dense(tmp_path, include_ground):
    scene = cluttered_scene(tmp_path)
    params = PhysicalParams(samples=512, include_ground=include_ground)
    pruned = contact_validity(scene, params, prune=True)
    dense = contact_validity(scene, params, prune=False)
    assert dense["pairs_evaluated"] == 8 * 7 // 2
    assert pruned["pairs_evaluated"] < dense["pairs_evaluated"] // 2
    n_pruned, n_dense = pruned.pop("pairs_evaluated"), dense.pop("pairs_evaluated")
    assert pruned == dense, (n_pruned, n_dense)
    obj = pruned["objects"]
    assert obj["top"]["pen_depth"] > 0.003 and obj["mid"]["pen_depth"] > 0.003
    assert obj["pen_a"]["pen_depth"] == pytest.approx(0.007, abs=5e-4)
    if include_ground:
        assert obj["float"]["float_dist"] == pytest.approx(0.02, abs=5e-4)
        assert obj["far1"]["float_dist"] > 0.1 and obj["far1"]["closest"] == "ground"
    else:
        assert obj["float"]["closest"] is not None and obj["float"]["float_dist"] > 0.5


def test_rigid_motion_leaves_static_metrics_unchanged(tmp_path):
    params = PhysicalParams(samples=512)
    motion = make_pose(rotation_z(0.83), [0.7, -1.3, 0.25])
    ref = contact_validity(cluttered_scene(tmp_path, "ref"), params)
    moved = contact_validity(cluttered_scene(tmp_path, "moved", motion=motion, dz=0.25), params)
    for oid, v in ref["objects"].items():
        assert moved["objects"][oid]["closest"] == v["closest"]
        for key in ("w", "pen_depth", "float_dist"):
            assert moved["objects"][oid][key] == pytest.approx(v[key], abs=1e-9), (oid, key)


def test_without_ground_isolated_object_has_no_floating_distance(tmp_path):
    scene = write_scene(tmp_path, [("a", box(0.2, 0.2, 0.1), at(0.0, 0.0, 0.3))])
    out = contact_validity(scene, PhysicalParams(samples=256, include_ground=False))
    assert out["objects"]["a"] == {"w": None, "closest": None, "pen_depth": 0.0, "float_dist": None}
    assert out["pen_depth"] == 0.0 and out["float_dist"] == 0.0
    with_ground = contact_validity(scene, PhysicalParams(samples=256))
    assert with_ground["float_dist"] == pytest.approx(0.25, abs=1e-9)


def test_box_gaps():
    lo = np.array([[0.0, 0, 0], [2.0, 0, 0], [0.5, 0.5, 0.5], [3.0, 4.0, 0]])
    hi = lo + 1.0
    g = box_gaps(lo, hi)
    assert g[0, 1] == 1.0 and g[0, 2] == 0.0 and g[1, 3] == pytest.approx(3.0)
    assert g[0, 3] == pytest.approx(math.hypot(2.0, 3.0))
    np.testing.assert_array_equal(g, g.T)


def test_params_and_inputs(tmp_path):
    assert PhysicalParams.from_dict(None) == PhysicalParams()
    p = PhysicalParams.from_dict({"samples": 100, "include_ground": False})
    assert p.samples == 100 and not p.include_ground and p.frames == 120 and p.upward_offset == 0.002
    with pytest.raises(ValueError, match="unknown physical metric parameters"):
        PhysicalParams.from_dict({"sample": 3})
    with pytest.raises(ValueError, match="upward_offset"):
        PhysicalParams(upward_offset=-0.1)
    assert object_seed(0, "a") == object_seed(0, "a") != object_seed(0, "b")
    scene = write_scene(tmp_path, [("a", box(0.1, 0.1, 0.1), at(0, 0, 0.05)),
                                   ("b", box(0.1, 0.1, 0.1), at(1, 0, 0.05))])
    proxies = proxies_of(scene, tmp_path)
    del proxies["b"]
    with pytest.raises(InputError, match=r"proxies.*\['b'\]"):
        drift_bullet(scene, proxies, PhysicalParams(), SIM, tmp_path / "cache")


def test_deterministic(tmp_path):
    scene = cluttered_scene(tmp_path)
    proxies = proxies_of(scene, tmp_path)
    params = PhysicalParams(samples=256, frames=30)
    a = physical_metrics(scene, proxies, params, SIM, tmp_path / "cache")
    b = physical_metrics(scene, proxies, params, SIM, tmp_path / "cache")
    assert a == b


@pytest.mark.parametrize("forget", [True, False])
def test_set_pose_answers_what_a_new_world_answers(tmp_path, monkeypatch, forget):
    """A body put back at a pose in a used world moves as the same body at that pose in a new world (the release
    of the whole scene, the drift protocol): Bullet's kept contacts of where it rested are dropped. The oracle is
    the new world itself; without :meth:`~phiscene.sim.bullet.BulletWorld.forget_contacts` the two part."""
    from phiscene.inertia import rigid_props

    if not forget:
        monkeypatch.setattr(BulletWorld, "forget_contacts", lambda self, name: None)
    sim = SimSettings()
    mesh = box(0.06, 0.06, 0.3)
    hulls = [np.asarray(mesh.vertices)]
    props = rigid_props(mesh, hulls, sim.density)
    tilt = trimesh.transformations.rotation_matrix(math.radians(6.0), [1, 0, 0])
    start = tilt @ at(0.0, 0.0, 0.0)
    start[2, 3] -= trimesh.transform_points(mesh.vertices, start)[:, 2].min() - 0.0005  # on its edge, 0.5 mm up
    with BulletWorld(sim, tmp_path / "cache") as world:
        world.add_ground(0.0)
        world.add_body("a", hulls, start, props)
        world.step_frames(120)  # at rest, upright, on its whole bottom face
        world.set_pose("a", start)
        world.step_frames(15)
        used = world.pose("a")
    with BulletWorld(sim, tmp_path / "cache") as world:
        world.add_ground(0.0)
        world.add_body("a", hulls, start, props)
        world.step_frames(15)
        new = world.pose("a")
    assert np.allclose(used, new, atol=1e-9) == forget


@pytest.mark.parametrize("frozen", [True, False])
def test_set_pose_keeps_a_frozen_body_static_for_the_broadphase(tmp_path, frozen):
    """A body frozen by :meth:`~phiscene.sim.bullet.BulletWorld.set_static` and put back by ``set_pose`` stays out
    of static-static pairs, as a body created static is (Bullet's filter: no contact points with the ground);
    released again, it touches the ground. Re-registering it with the dynamic filter made every frozen object
    that was put back collide with every other static body each step, which slowed grounding several-fold."""
    from phiscene.inertia import rigid_props

    sim = SimSettings()
    mesh = box(0.1, 0.1, 0.1)
    hulls = [np.asarray(mesh.vertices)]
    pose = at(0.0, 0.0, 0.049)  # 1 mm into the ground
    with BulletWorld(sim, tmp_path / "cache") as world:
        world.add_ground(0.0)
        world.add_body("static", hulls, at(1.0, 0.0, 0.049), None)
        world.add_body("a", hulls, pose, rigid_props(mesh, hulls, sim.density))
        if frozen:
            world.set_static("a")
        world.set_pose("a", pose)
        world.step_frames(1)
        reference = len(world.contacts("static"))  # a body created static: no pair with the ground
        assert reference == 0
        assert (len(world.contacts("a")) == 0) == frozen
        if frozen:
            world.set_dynamic("a")
            world.set_pose("a", pose)
            world.step_frames(1)
            assert len(world.contacts("a", "ground")) > 0
