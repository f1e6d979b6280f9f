"""Remedy ``base``: an object at rest in the input whose bottom is round (a guess of its hidden side) is given a
flat base where it stands.

Oracles: statics (a body on a flat base stands when its centre of mass is over the base; a convex body rocks on
a round bottom when its centre of mass is above the bottom's centre of curvature); the closed-form base of a
sphere's band; MuJoCo, an independent simulator, for whether the completed base written to the scene file is
what holds the object up.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh
from scenes import convex_proxies, ground_alone
from simcheck import saved_and_released

from phiscene.assembly.ballast import flat_base
from phiscene.errors import InputError
from phiscene.meshes import save_mesh
from phiscene.proxies import with_base, with_bases
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, make_pose, transform_points

torch.set_num_threads(1)
SIM = SimSettings()

#: The egg: semi-axes (m) of the ellipsoid, and its tilt from upright (deg) in the input.
AXES, TILT = (0.05, 0.05, 0.15), 30.0


def egg() -> trimesh.Trimesh:
    """An ellipsoid, long axis along z, centred on the origin."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.apply_scale(AXES)
    return mesh


def tilted_pose(mesh: trimesh.Trimesh, tilt_deg: float, lift: float = 0.0) -> np.ndarray:
    """The egg turned ``tilt_deg`` about +y, its lowest point ``lift`` above z = 0."""
    from scipy.spatial.transform import Rotation

    pose = make_pose(Rotation.from_euler("y", tilt_deg, degrees=True).as_matrix())
    pose[2, 3] = lift - float(transform_points(pose, mesh.vertices)[:, 2].min())
    return pose


def tilt_of(pose: np.ndarray) -> float:
    """Angle (deg) between the egg's long axis and the vertical."""
    R = decompose(pose)[0]
    return math.degrees(math.acos(min(1.0, abs(float(R[2, 2])))))


def test_a_band_of_a_sphere_is_completed_into_a_flat_disc_under_it():
    # a sphere of radius r: the band of height h above its lowest point projects onto a disc of radius
    # sqrt(2 r h - h^2); the piece is flat at the lowest point and does not reach above the band
    r = 0.1
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=r)
    pose = make_pose(translation=(0.2, -0.1, 0.5))
    up = np.array([0.0, 0.0, 1.0])
    # centre of mass low (a weeble): the thinnest band holds it
    com = np.array([0.0, 0.0, -0.09])
    points, share = flat_base(pose, [sphere.vertices], com, up, 4.0)
    assert share == pytest.approx(0.01)
    world = transform_points(pose, points)
    lo = 0.5 - r
    h = share * 2 * r
    assert world[:, 2].min() == pytest.approx(lo, abs=1e-9)
    assert world[:, 2].max() <= lo + h + 1e-9
    flat = world[np.isclose(world[:, 2], lo, atol=1e-9)]
    radius = np.linalg.norm(flat[:, :2] - [0.2, -0.1], axis=1).max()
    assert radius == pytest.approx(math.sqrt(2 * r * h - h * h), rel=0.1)  # 642-vertex sphere
    # the centre of mass higher up needs a wider base: a thicker band
    high = flat_base(pose, [sphere.vertices], np.zeros(3), up, 4.0)
    assert high is not None and high[1] > share


def test_no_base_holds_a_centre_of_mass_outside_every_band():
    # a cone standing on its tip, leaning: its centre of mass is far outside anything its lowest tenth spans
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    cone = np.vstack([[0.0, 0.0, 0.0], np.c_[0.1 + 0.05 * np.cos(a), 0.05 * np.sin(a), np.full_like(a, 0.3)]])
    assert flat_base(np.eye(4), [cone], cone.mean(axis=0), np.array([0.0, 0.0, 1.0]), 4.0) is None


def test_a_tables_feet_span_no_base_but_a_solid_block_does():
    # four legs of uneven length (a reconstruction's) under a top, as convex pieces: the flat base spanning the
    # feet would be a slab between the legs (a ray up from its middle meets the top, 0.7 m up, not the band)
    legs = [trimesh.creation.box((0.05, 0.05, 0.7), make_pose(translation=(x, y, 0.35 + dz))).vertices
            for (x, y), dz in zip([(-0.4, -0.25), (-0.4, 0.25), (0.4, -0.25), (0.4, 0.25)], (0.0, 2e-3, 3e-3, 4e-3))]
    top = trimesh.creation.box((0.9, 0.6, 0.04), make_pose(translation=(0.0, 0.0, 0.72))).vertices
    up = np.array([0.0, 0.0, 1.0])
    com = np.array([0.0, 0.0, 0.6])
    assert flat_base(np.eye(4), [*legs, top], com, up, 4.0) is None
    # the same footprint as one block, its bottom a shallow pyramid 5 mm deep: covered everywhere, and the
    # thinnest band (1 % of 0.745 m) already reaches the bottom's corners
    x, y = 0.425, 0.275
    block = np.array([[sx * x, sy * y, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.005, 0.745)]
                     + [[0.0, 0.0, 0.0]])
    got = flat_base(np.eye(4), [block], com, up, 4.0)
    assert got is not None and got[1] == pytest.approx(0.01)
    np.testing.assert_allclose(np.sort(got[0][:, 2]), [0.0] * 5 + [0.005] * 4, atol=1e-12)


@pytest.fixture(scope="module")
def eggs(tmp_path_factory):
    root = tmp_path_factory.mktemp("base")
    return {"root": root, "cache": root / "cache", "mesh": save_mesh(egg(), root / "egg.obj")}


def run(eggs, base: bool):
    pose = tilted_pose(egg(), TILT, lift=0.001)
    out, rec, proxies = ground_alone("egg", eggs["mesh"], pose, "ceramic jug", eggs["cache"], {"base": base})
    return pose, out, rec, proxies


@pytest.fixture(scope="module")
def grounded(eggs):
    """The egg grounded with the remedy on: (input pose, grounded scene, assembly record, proxies)."""
    return run(eggs, base=True)


def test_an_egg_tilted_on_its_round_bottom_stands_where_it_was_on_a_completed_base(eggs, grounded):
    pose, out, rec, proxies = grounded
    obj = out.get("egg")
    cert = rec["objects"]["egg"]["certificate"]
    assert cert["remedy"] == "base" and cert["settled"] and cert["supporters_kept"]
    # the ballast alone could not hold it: its declared centre of mass is above the round bottom's centre
    # of curvature (the ballast start is in the reasons)
    assert "ballast:" in rec["objects"]["egg"]["reason"]
    assert abs(tilt_of(obj.pose) - TILT) < 5.0  # as in the input, up to the flush onto its base
    assert np.linalg.norm(decompose(obj.pose)[1][:2] - pose[:2, 3]) < 0.01
    assert obj.base is not None and obj.com is not None
    # the visible mesh still touches the ground (it is not lifted onto the piece)
    lowest = float(transform_points(obj.pose, egg().vertices)[:, 2].min())
    assert abs(lowest) < 2e-3
    # the base travels with the scene file, and an independent simulator finds the egg standing on it;
    # released without it, the same pose rolls over
    held, rolled = saved_and_released(out, eggs["root"] / "out" / "scene.json", proxies, "base", SIM)
    assert held["drift_trans"] < 2e-3 and held["drift_rot"] < 1.0
    assert rolled["drift_rot"] > 5.0


def test_without_the_remedy_the_egg_rolls_over(eggs):
    _, out, rec, _ = run(eggs, base=False)
    assert rec["objects"]["egg"]["certificate"]["remedy"] != "base"
    assert out.get("egg").base is None
    assert abs(tilt_of(out.get("egg").pose) - TILT) > 10.0


def test_with_base_adds_the_piece_once(eggs):
    scene = Scene([SceneObject("egg", eggs["mesh"], np.eye(4))])
    proxies = convex_proxies(scene, eggs["cache"])
    piece = np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]], dtype=float)
    once = with_base(proxies["egg"], piece)
    assert len(once.hulls) == len(proxies["egg"].hulls) + 1
    assert with_base(once, piece) is once  # idempotent: a consumer may get proxies already completed
    assert with_bases(scene, proxies)["egg"] is proxies["egg"]  # no base declared: unchanged


@pytest.mark.parametrize("base, problem", [
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "at least 4"),
    ([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0.01, 0.01, 0]], "coplanar"),
    ([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, float("nan")]], "finite"),
    ([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, -5.0]], "beyond the mesh"),
])
def test_a_bad_base_in_a_scene_file_is_refused_naming_the_field(eggs, tmp_path, base, problem):
    import json

    scene = Scene([SceneObject("egg", eggs["mesh"], tilted_pose(egg(), 0.0))])
    path = save_scene(scene, tmp_path / "scene.json")
    data = json.loads(path.read_text())
    data["objects"][0]["base"] = base
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=problem) as err:
        load_scene(path)
    assert "objects[0].base" in str(err.value)


def test_the_completed_base_is_a_collision_piece_of_the_mjcf_export(grounded, tmp_path):
    import mujoco

    from phiscene.io.export import export_mjcf

    _, out, _, proxies = grounded
    model = mujoco.MjModel.from_xml_path(str(export_mjcf(out, proxies, tmp_path / "scene.xml", SIM)))
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "egg")
    geoms = range(int(model.body_geomadr[b]), int(model.body_geomadr[b] + model.body_geomnum[b]))
    colliding = [g for g in geoms if model.geom_contype[g] or model.geom_conaffinity[g]]
    assert len(colliding) == len(proxies["egg"].hulls) + 1
    # and MuJoCo, loading the exported file, keeps the egg standing as it was grounded
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = data.xpos[b].copy()
    mujoco.mj_step(model, data, nstep=int(1.0 / model.opt.timestep))
    assert np.linalg.norm(data.xpos[b] - start) < 2e-3


def test_a_can_tilted_by_a_rotation_error_gets_no_base(tmp_path):
    # a can's flat bottom is a resting pose 28 deg from the tilted input: it rests there, however turned, so its
    # bottom is no round guess that the remedy completes (statics: upright, its centre of mass is over its bottom)
    can = trimesh.creation.cylinder(radius=0.04, height=0.12, sections=48)
    path = save_mesh(can, tmp_path / "can.obj")
    out, rec, _ = ground_alone("can", path, tilted_pose(can, 28.0, lift=0.001), "yellow can", tmp_path / "cache", {})
    labels = [part.split(":")[0] for part in rec["objects"]["can"]["reason"].split("; ")]
    assert any(label.startswith("stable") for label in labels)
    assert rec["objects"]["can"]["settle_remedy"] != "base" and not any(lb.startswith("base") for lb in labels)
    assert out.get("can").base is None


def test_the_completed_base_is_a_collider_of_the_usd_export(grounded, tmp_path):
    from phiscene.io.usd import export_usd, read_usd_scene

    _, out, _, proxies = grounded
    read = read_usd_scene(export_usd(out, proxies, tmp_path / "scene.usda", SIM))
    hulls = read["objects"]["egg"]["hulls"]
    assert len(hulls) == len(proxies["egg"].hulls) + 1
    # the last collider is the completed base: its vertices are the piece's (a convex hull of them)
    piece = np.asarray(out.get("egg").base)
    assert np.abs(np.sort(np.asarray(hulls[-1])[:, 2])[0] - piece[:, 2].min()) < 1e-6
