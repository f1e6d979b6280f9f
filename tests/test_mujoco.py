"""MuJoCo drift (cross-simulator check): oracles are closed-form rigid-body physics."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from scenes import scene_file
from scipy.spatial.transform import Rotation

from phiscene.errors import InputError
from phiscene.metrics.drift import drift_mujoco
from phiscene.sim import mujoco as pm
from phiscene.sim.settings import SimSettings
from phiscene.tolerances import GRAVITY
from phiscene.transforms import make_pose, rotation_z, transform_points

mujoco = pytest.importorskip("mujoco")

PROTOCOL = SimpleNamespace(upward_offset=0.002, frames=120)
SIM = SimSettings()


make_scene = scene_file  # scene file + convex proxies from [(id, trimesh, pose)]


def resting(mesh, R, xy=(0.0, 0.0), z0=0.0, scale=1.0):
    """Pose placing ``mesh`` (rotated by R, scaled) with its lowest point at height z0."""
    pose = make_pose(R, [xy[0], xy[1], 0.0], scale)
    zmin = transform_points(pose, mesh.vertices)[:, 2].min()
    return make_pose(R, [xy[0], xy[1], z0 - zmin], scale)


def run(scene, proxies, frames, sim=SIM, ground=0.0, gravity=True):
    """Build, compile and step; return (model, data, start poses, end poses)."""
    model = pm.compile_model(pm.build_spec(scene, proxies, sim, ground), sim)
    if not gravity:
        model.opt.gravity[:] = 0.0
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = pm.body_poses(model, data, scene.ids)
    pm.step_frames(model, data, frames, sim)
    return model, data, start, pm.body_poses(model, data, scene.ids)


def test_box_at_rest_has_no_drift(tmp_path):
    box = trimesh.creation.box([0.2, 0.3, 0.1])
    # scaled, turned, and far above scene.ground_height: the protocol's ground goes right below it
    scene, proxies = make_scene(tmp_path, [("box", box, resting(box, rotation_z(0.4), (0.1, 0.2), 0.5, 1.5))])
    out = drift_mujoco(scene, proxies, PROTOCOL, SIM)
    assert set(out) == {"drift_trans", "drift_rot", "ground_below", "objects"}
    assert out["ground_below"] == pytest.approx(0.5, abs=1e-9)
    assert out["objects"]["box"]["drift_trans"] < 1e-3
    assert out["objects"]["box"]["drift_rot"] < 0.5
    assert out["drift_trans"] == out["objects"]["box"]["drift_trans"]
    # a 2 cm lift: the box falls back onto the ground, and the lift is not counted as drift
    lifted = drift_mujoco(scene, proxies, SimpleNamespace(upward_offset=0.02, frames=120), SIM)
    assert lifted["drift_trans"] < 1e-3


def test_mass_properties_are_phiscene_inertia(tmp_path):
    a, b, c, s = 0.2, 0.3, 0.1, 1.5
    box = trimesh.creation.box([a, b, c])
    scene, proxies = make_scene(tmp_path, [("box", box, make_pose(rotation_z(0.7), [0, 0, 1], s))])
    model = pm.compile_model(pm.build_spec(scene, proxies, SIM, 0.0), SIM)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "box")
    mass = SIM.density * a * b * c * s**3
    assert model.body_mass[body] == pytest.approx(mass, rel=1e-9)
    A, B, C = a * s, b * s, c * s
    expected = sorted(mass / 12 * np.array([B**2 + C**2, A**2 + C**2, A**2 + B**2]))
    np.testing.assert_allclose(sorted(model.body_inertia[body]), expected, rtol=1e-9)
    # the collision hull sits where the scaled, posed mesh is
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "box/hull0")
    k = model.geom_dataid[g]
    v = model.mesh_vert[model.mesh_vertadr[k]:model.mesh_vertadr[k] + model.mesh_vertnum[k]]
    world = v @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
    ref = scene.objects[0].world_mesh().vertices
    np.testing.assert_allclose(np.sort(world, axis=0), np.sort(ref, axis=0), atol=1e-6)


def test_free_fall_matches_half_g_t_squared(tmp_path):
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    scene, proxies = make_scene(tmp_path, [("box", box, make_pose(rotation_z(0.3), [0.1, 0.2, 1.0]))])
    sim = SimSettings(linear_damping=0.0, angular_damping=0.0)
    frames = 30
    _, _, start, end = run(scene, proxies, frames, sim, ground=-100.0)
    t = frames * sim.frame_dt
    drop = start["box"][2, 3] - end["box"][2, 3]
    assert drop == pytest.approx(0.5 * GRAVITY * t**2, rel=0.01)
    np.testing.assert_allclose(end["box"][:2, 3], start["box"][:2, 3], atol=1e-9)
    np.testing.assert_allclose(end["box"][:3, :3], start["box"][:3, :3], atol=1e-9)


def test_damping_decays_like_bullet(tmp_path):
    # Bullet: v <- v * (1 - damping) ** dt per step, i.e. v(t) = v0 (1 - damping) ** t, for any mass and inertia
    box = trimesh.creation.box([0.1, 0.2, 0.4])
    scene, proxies = make_scene(tmp_path, [("box", box, make_pose(translation=[0, 0, 5.0]))])
    sim = SimSettings(linear_damping=0.5, angular_damping=0.3)
    model = pm.compile_model(pm.build_spec(scene, proxies, sim, -100.0), sim)
    model.opt.gravity[:] = 0.0
    data = mujoco.MjData(model)
    data.qvel[:] = [1.0, -2.0, 0.5, 0.0, 0.0, 3.0]  # spin about a principal axis (body frame = principal frame)
    pm.step_frames(model, data, 60, sim)
    np.testing.assert_allclose(data.qvel[:3], np.array([1.0, -2.0, 0.5]) * 0.5, rtol=0.01)
    np.testing.assert_allclose(data.qvel[5], 3.0 * 0.7, rtol=0.01)


def test_box_on_its_edge_topples(tmp_path):
    # a 0.1 x 0.1 x 0.4 box tilted 30 deg about x stands on an edge with its COM outside the support:
    # it falls onto its long side, a 60 deg rotation
    box = trimesh.creation.box([0.1, 0.1, 0.4])
    R = Rotation.from_euler("x", 30, degrees=True).as_matrix()
    scene, proxies = make_scene(tmp_path, [("box", box, resting(box, R))])
    out = drift_mujoco(scene, proxies, PROTOCOL, SIM)
    assert out["drift_rot"] > 30.0
    assert out["drift_rot"] == pytest.approx(60.0, abs=5.0)
    assert out["drift_trans"] > 0.05


def test_two_box_stack_stays(tmp_path):
    base, top = trimesh.creation.box([0.3, 0.3, 0.1]), trimesh.creation.box([0.2, 0.2, 0.1])
    scene, proxies = make_scene(tmp_path, [("base", base, make_pose(translation=[0, 0, 0.05])),
                                           ("top", top, make_pose(rotation_z(0.3), [0.02, 0.0, 0.15]))])
    out = drift_mujoco(scene, proxies, PROTOCOL, SIM)
    for name in ("base", "top"):
        assert out["objects"][name]["drift_trans"] < 1e-3
        assert out["objects"][name]["drift_rot"] < 0.5
    assert out["drift_trans"] == pytest.approx(np.mean([v["drift_trans"] for v in out["objects"].values()]))


def _cube_on_wedge(tmp_path, degrees):
    th = math.radians(degrees)
    length, height = 2.0, 2.0 * math.tan(th)
    wedge = trimesh.convex.convex_hull([[x, y, z] for x, z in [(0, 0), (length, 0), (0, height)] for y in (-0.3, 0.3)])
    cube = trimesh.creation.box([0.1, 0.1, 0.1])
    downhill = np.array([math.cos(th), 0.0, -math.sin(th)])
    normal = np.array([math.sin(th), 0.0, math.cos(th)])
    centre = np.array([0.0, 0.0, height]) + 0.3 * downhill + 0.05 * normal
    scene, proxies = make_scene(tmp_path, [("wedge", wedge, make_pose()),
                                           ("cube", cube, make_pose(Rotation.from_euler("y", th).as_matrix(), centre))])
    return scene, proxies, downhill


@pytest.mark.parametrize("degrees, frames", [(25.0, 120), (40.0, 30)])
def test_cube_on_slope_follows_coulomb(tmp_path, degrees, frames):
    # pybullet's contact friction is the product friction * friction; MuJoCo gets the same coefficient.
    # Below atan(mu) the cube sticks for the whole protocol (soft contacts would creep: MuJoCo's
    # default settings slide ~7 mm here); above it slides with a = g (sin - mu cos), s = a t^2 / 2.
    scene, proxies, downhill = _cube_on_wedge(tmp_path, degrees)
    _, _, start, end = run(scene, proxies, frames)
    slid = (end["cube"][:3, 3] - start["cube"][:3, 3]) @ downhill
    mu, th, t = SIM.friction**2, math.radians(degrees), frames * SIM.frame_dt
    accel = GRAVITY * (math.sin(th) - mu * math.cos(th))
    if accel <= 0:
        assert abs(slid) < 1e-4
    else:
        assert slid == pytest.approx(0.5 * accel * t**2, rel=0.03)
    assert np.linalg.norm(end["wedge"][:3, 3] - start["wedge"][:3, 3]) < 1e-3


def test_write_mjcf_round_trips(tmp_path):
    box = trimesh.creation.box([0.2, 0.3, 0.1])
    scene, proxies = make_scene(tmp_path, [("a", box, make_pose(rotation_z(0.4), [0.1, 0.2, 0.05])),
                                           ("b", box, make_pose(None, [0.1, 0.2, 0.15], 0.5))])
    spec = pm.build_spec(scene, proxies, SIM, 0.0)
    model = pm.compile_model(spec, SIM)
    path = pm.write_mjcf(spec, tmp_path / "out" / "scene.xml")
    assert not [p for p in path.parent.iterdir() if p != path]  # no temporary left behind
    again = mujoco.MjSpec.from_file(str(path)).compile()
    assert (again.nbody, again.ngeom, again.nmesh) == (model.nbody, model.ngeom, model.nmesh)
    np.testing.assert_allclose(again.body_mass, model.body_mass, rtol=1e-5)
    np.testing.assert_allclose(again.body_inertia, model.body_inertia, rtol=1e-5)
    np.testing.assert_allclose(again.body_pos, model.body_pos, atol=1e-6)
    assert again.opt.timestep == pytest.approx(model.opt.timestep, rel=1e-5)
    assert again.opt.cone == model.opt.cone and again.opt.integrator == model.opt.integrator


def test_bad_input_is_named(tmp_path):
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    scene, proxies = make_scene(tmp_path, [("a", box, make_pose(translation=[0, 0, 0.05]))])
    with pytest.raises(InputError, match=r"objects\[0\]\.id.*'a'"):
        pm.build_spec(scene, {}, SIM, 0.0)
    with pytest.raises(ValueError, match="unknown MuJoCo settings"):
        pm.MujocoParams.from_dict({"margn": 0.0})
    with pytest.raises(ValueError, match="cone"):
        pm.MujocoParams.from_dict({"cone": "round"})
    assert pm.MujocoParams.from_dict({"solimp": [0.9, 0.95, 0.001, 0.5, 2]}).solimp == (0.9, 0.95, 0.001, 0.5, 2.0)


def test_a_release_that_overflows_the_arena_runs_again_with_a_larger_one(tmp_path, monkeypatch):
    """Two boxes through each other, each a compound of 30 small cubes (a reconstruction's objects inside one
    another): their contacts overflow the arena MuJoCo sizes for the model. The drift is that of the same release
    with an ample arena (256 MB) from the start, to the bit; without the retries the overflow is an error."""
    import phiscene.metrics.drift as drift_mod
    from phiscene.metrics.drift import ground_below
    from phiscene.proxies import Proxy
    from tests.scenes import box_scene

    monkeypatch.chdir(tmp_path)  # MuJoCo's warnings go to the log, not to a MUJOCO_LOG.TXT written here
    cube = trimesh.creation.box((0.3, 0.3, 0.3))
    cube.export(tmp_path / "a.obj")
    scene = box_scene({"a": tmp_path / "a.obj"}, {"a": ("a", make_pose(translation=(0, 0, 0.15))),
                                                  "b": ("a", make_pose(translation=(0.02, 0.01, 0.16)))})
    rng = np.random.default_rng(0)
    pieces = {k: [trimesh.creation.box((0.06, 0.06, 0.06)).vertices + rng.uniform(-0.12, 0.12, 3) for _ in range(30)]
              for k in ("a", "b")}
    proxies = {k: Proxy(v, 1.0, 0.0) for k, v in pieces.items()}
    got = drift_mujoco(scene, proxies, PROTOCOL, SIM)
    lifted = scene.with_poses({o.id: make_pose(translation=[0, 0, PROTOCOL.upward_offset]) @ o.pose
                               for o in scene.objects})
    spec = pm.build_spec(lifted, proxies, SIM, ground_below(scene, proxies))
    spec.memory = 256 * 2**20
    model = pm.compile_model(spec, SIM)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = pm.body_poses(model, data, scene.ids)
    pm.step_frames(model, data, PROTOCOL.frames, SIM)
    end = pm.body_poses(model, data, scene.ids)
    for k in scene.ids:
        com0 = start[k][:3, 3] - [0.0, 0.0, PROTOCOL.upward_offset]
        assert got["objects"][k]["drift_trans"] == float(np.linalg.norm(end[k][:3, 3] - com0))
    monkeypatch.setattr(drift_mod, "MUJOCO_ARENA_RETRIES", 0)
    with pytest.raises((pm.ArenaFull, mujoco.FatalError)):
        drift_mujoco(scene, proxies, PROTOCOL, SIM)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
