"""Remedy ``ballast``: an object at rest in the input that topples as a uniform solid gets a lower centre of mass.

Oracles: the parallel-axis theorem for the declared centre's inertia; statics (a body stands when its centre of
mass is over its base) for which shapes tip and which stand; MuJoCo, an independent simulator, for whether the
declared centre of mass, written to the scene file, is the one that holds the object up.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh
from scenes import ground_alone
from simcheck import saved_and_released

from phiscene.assembly.ballast import ballast_com, hull_facets
from phiscene.assembly.faithful import FaithfulParams
from phiscene.inertia import rigid_props
from phiscene.meshes import save_mesh
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, make_pose

torch.set_num_threads(1)
SIM = SimSettings()

#: The oblique frustum: base radius, top radius, height, top centre's offset along x (m).
BASE, TOP, HEIGHT, LEAN = 0.015, 0.08, 0.2, 0.03


def frustum() -> trimesh.Trimesh:
    """A convex oblique frustum standing on its narrow base (centred on the origin, z = 0): its wide top leans
    ``LEAN`` along +x, like a bouquet in a vase. As a uniform solid its centre of mass is ``LEAN`` times its
    height share along x, outside the base (module test below): it tips over."""
    a = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    bottom = np.c_[BASE * np.cos(a), BASE * np.sin(a), np.zeros_like(a)]
    top = np.c_[LEAN + TOP * np.cos(a), TOP * np.sin(a), np.full_like(a, HEIGHT)]
    return trimesh.convex.convex_hull(np.vstack([bottom, top]))


@pytest.fixture(scope="module")
def vase(tmp_path_factory):
    root = tmp_path_factory.mktemp("ballast")
    return {"root": root, "cache": root / "cache", "mesh": save_mesh(frustum(), root / "vase.obj")}


def test_uniform_frustum_centre_of_mass_is_outside_its_base():
    # the closed form of the frustum's centroid height, and its x offset (the section centres move linearly)
    a, b = BASE, TOP
    zc = HEIGHT * (a * a + 2 * a * b + 3 * b * b) / (4 * (a * a + a * b + b * b))
    com = frustum().center_mass
    assert com[2] == pytest.approx(zc, rel=0.02)  # 32-gon sections: within 2 % of the circular frustum
    assert com[0] == pytest.approx(LEAN * zc / HEIGHT, rel=0.02)
    assert math.hypot(com[0], com[1]) > BASE  # outside the base: it cannot stand as a uniform solid


def test_declared_centre_of_mass_keeps_the_mass_and_shifts_the_inertia_by_the_parallel_axis_theorem():
    box = trimesh.creation.box((0.2, 0.1, 0.4))
    uniform = rigid_props(box, None, 500.0)
    d = np.array([0.01, -0.02, -0.1])
    moved = rigid_props(box, None, 500.0, com=d)
    assert moved.mass == pytest.approx(uniform.mass)
    np.testing.assert_allclose(moved.com, d, atol=1e-12)
    def inertia(p):
        return p.principal_axes @ np.diag(p.principal_moments) @ p.principal_axes.T

    expected = inertia(uniform) + uniform.mass * (d @ d * np.eye(3) - np.outer(d, d))
    np.testing.assert_allclose(inertia(moved), expected, rtol=1e-9, atol=1e-12)
    scaled = rigid_props(box, None, 500.0, scale=2.0, com=d)  # declared in the unscaled frame
    np.testing.assert_allclose(scaled.com, 2.0 * d, atol=1e-12)


def test_ballast_com_is_over_the_base_low_and_inside_the_hull():
    mesh = frustum()
    pose = make_pose(translation=(0.3, -0.2, 0.5))
    c = ballast_com(pose, mesh.center_mass, mesh.vertices, 0.25)
    np.testing.assert_allclose(c[:2], [0.0, 0.0], atol=1e-3)  # over the base's centre
    assert c[2] == pytest.approx(0.25 * HEIGHT, abs=1e-6)
    assert mesh.contains([c])[0]
    assert ballast_com(pose, np.array([0.0, 0.0, 0.01]), mesh.vertices, 0.25) is None  # already low


def run(vase, ballast: bool):
    pose = make_pose(translation=(0.0, 0.0, 0.001))
    out, rec, proxies = ground_alone("vase", vase["mesh"], pose, "glass vase with flowers", vase["cache"],
                                     {"ballast": ballast})
    return pose, out, rec, proxies


def test_a_vase_that_topples_as_a_uniform_solid_stands_where_it_was_with_a_ballast(vase):
    pose, out, rec, proxies = run(vase, ballast=True)
    obj = out.get("vase")
    R, t, _ = decompose(obj.pose)
    cert = rec["objects"]["vase"]["certificate"]
    assert cert["remedy"] == "ballast" and cert["settled"] and cert["supporters_kept"]
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) < 1.0  # upright
    assert np.linalg.norm(t[:2] - pose[:2, 3]) < 0.01
    assert obj.com is not None and math.hypot(obj.com[0], obj.com[1]) < BASE / 3  # over its base
    assert obj.com[2] == pytest.approx(0.25 * HEIGHT, abs=2e-3)
    # the declared centre travels with the scene file, and an independent simulator finds it standing there;
    # released as a uniform solid instead, the same pose tips over
    held, uniform = saved_and_released(out, vase["root"] / "out" / "scene.json", proxies, "com", SIM)
    assert held["drift_trans"] < 1e-3 and held["drift_rot"] < 0.5
    assert uniform["drift_rot"] > 10.0


def test_without_the_remedy_the_vase_is_left_toppled(vase):
    _, out, rec, _ = run(vase, ballast=False)
    R, _, _ = decompose(out.get("vase").pose)
    assert rec["objects"]["vase"]["certificate"]["remedy"] == "closest"
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) > 45.0  # on its side
    assert out.get("vase").com is None


def test_the_declared_centre_of_mass_is_the_one_the_mjcf_export_gives_mujoco(vase, tmp_path):
    import mujoco

    from phiscene.io.export import export_mjcf

    _, out, _, proxies = run(vase, ballast=True)
    com = out.get("vase").com
    model = mujoco.MjModel.from_xml_path(str(export_mjcf(out, proxies, tmp_path / "scene.xml", SIM)))
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "vase")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # MuJoCo's own world centre of mass of the body is the declared centre carried to the world by the pose
    R, t, s = decompose(out.get("vase").pose)
    np.testing.assert_allclose(data.xipos[b], R @ (s * com) + t, atol=1e-6)


#: The step: a prism (depth 0.2 m along y) whose profile in x-z has its bottom ``A`` (x in [-0.12, 0], z = 0), a
#: bevel ``B`` 6 cm long rising from A's edge, then a steep side up to a top (z = 0.3) overhanging towards +x (to
#: ``top_x``). (Its size keeps the simulator's rolling friction, a 3 mm lever, small beside the statics tested.)
BEVEL = 0.06


def step_body(bevel_deg: float, top_x: float) -> trimesh.Trimesh:
    b = math.radians(bevel_deg)
    profile = ((-0.12, 0.0), (0.0, 0.0), (BEVEL * math.cos(b), BEVEL * math.sin(b)), (top_x, 0.3), (-0.12, 0.3))
    return trimesh.convex.convex_hull(np.array([(x, y, z) for x, z in profile for y in (-0.1, 0.1)]))


@pytest.mark.parametrize("bevel_deg, top_x", [(15.0, 0.22), (8.0, 0.28)])
def test_a_ballast_keeps_the_orientation_of_the_photo_beyond_the_turn_bound(tmp_path, bevel_deg, top_x):
    # statics of the uniform solid: its centre of mass is beyond A's edge (it cannot stand on A, the way it was
    # put), and over the bevel B within 4 deg of B's far edge: B is its nearest resting facet, and it only
    # balances there (the tilt test tips it). At rest in the photo on A, it is no uniform solid. With a ballast it
    # stands on A, as put, when B is farther than the turn bound (10 deg): so large a flush contradicts the
    # photo; a nearer B is a correction of the input's rotation error, and it stands on B
    mesh = step_body(bevel_deg, top_x)
    c = mesh.center_mass
    beta = math.radians(bevel_deg)
    along = c[0] * math.cos(beta) + c[2] * math.sin(beta)  # along B from A's edge
    above = c[2] * math.cos(beta) - c[0] * math.sin(beta)  # above B's plane
    assert c[0] > 0.0
    assert 0.0 < math.degrees(math.atan2(BEVEL - along, above)) < 4.0
    path = save_mesh(mesh, tmp_path / "step.obj")
    pose = make_pose(translation=(0.0, 0.0, 0.001))
    out, rec, proxies = ground_alone("step", path, pose, "a wooden step", tmp_path / "cache", {"ballast": True})
    obj = out.get("step")
    cert = rec["objects"]["step"]["certificate"]
    assert cert["remedy"] == "ballast" and cert["settled"] and cert["supporters_kept"]
    R, t, _ = decompose(obj.pose)
    tilt = math.degrees(math.acos(min(1.0, R[2, 2])))  # of A from level
    on_a = bevel_deg > FaithfulParams().max_turn
    expected = 0.0 if on_a else bevel_deg  # on A, level; or on B, level
    assert tilt == pytest.approx(expected, abs=1.0)
    assert cert["rotation_change"] == pytest.approx(expected, abs=1.0)
    assert cert["flush_angle"] == pytest.approx(expected, abs=1.0)
    moved = (R @ c + t) - (pose[:3, :3] @ c + pose[:3, 3])  # the uniform solid's centre, carried by each pose
    assert np.linalg.norm(moved[:2]) < 0.01
    held, uniform = saved_and_released(out, tmp_path / "out" / "scene.json", proxies, "com", SIM)
    assert held["drift_trans"] < 1e-3 and held["drift_rot"] < 0.5  # MuJoCo, with the declared centre
    if on_a:
        assert uniform["drift_rot"] > 10.0  # a uniform solid, it falls off A (on B it balances: statics above)


def test_hull_facets_hold_the_box_and_nothing_flat():
    """The half-spaces of a box's vertices, doubled with near-duplicates (two pieces sharing a face): a point is
    inside exactly when it is within the box's bounds; points in one plane hold no point off it."""
    rng = np.random.default_rng(0)
    box = trimesh.creation.box((0.4, 0.2, 0.1)).vertices
    points = np.vstack([box, box + rng.normal(scale=1e-9, size=box.shape)])
    facets = hull_facets(points)
    probes = rng.uniform(-0.3, 0.3, size=(2000, 3))
    inside = np.all(facets[:, :3] @ probes.T + facets[:, 3:] <= 1e-12, axis=0)
    within = np.all(np.abs(probes) <= [0.2, 0.1, 0.05], axis=1)
    assert np.array_equal(inside, within) and within.any() and not within.all()
    flat = hull_facets(np.c_[rng.uniform(size=(50, 2)), np.zeros(50)])  # joggled: a sliver, or nothing
    off = np.c_[rng.uniform(0.2, 0.8, size=(100, 2)), np.full(100, 0.001)]
    assert flat is None or not np.any(np.all(flat[:, :3] @ off.T + flat[:, 3:] <= 1e-12, axis=0))
