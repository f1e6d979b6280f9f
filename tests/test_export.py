"""Simulation-ready export (GLB, URDF, MJCF, support graph) and the perturbation demo.

Oracles: closed-form box inertia, rest (a settled scene released in a fresh
world stays put), the pipeline's own drift in pybullet and MuJoCo, trimesh's
and yourdfpy's readers, and the camera projection of the simulated ball.
"""

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from phiscene import topology
from phiscene.errors import InputError
from phiscene.io import export as ex
from phiscene.meshes import save_mesh
from phiscene.metrics.physical import PhysicalParams
from phiscene.proxies import ProxyParams, proxy_for_mesh
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import make_pose, rotation_z

SIM = SimSettings()
PLANK_SCALE = 1.2
#: (id, box extents before scaling, pose): two boxes on the ground, a scaled plank bridging them (two parents).
LAYOUT = [
    ("box_a", (0.1, 0.1, 0.1), make_pose(rotation_z(0.2), [-0.15, 0.0, 0.05])),
    ("box_b", (0.1, 0.12, 0.1), make_pose(rotation_z(-0.1), [0.15, 0.01, 0.05])),
    ("plank", (0.45 / PLANK_SCALE, 0.1 / PLANK_SCALE, 0.02 / PLANK_SCALE),
     make_pose(rotation_z(0.05), [0.0, 0.0, 0.11], PLANK_SCALE)),
]


@pytest.fixture(scope="module")
def bridge(tmp_path_factory):
    """Scene file, proxies, support graph and its export folder."""
    tmp = tmp_path_factory.mktemp("bridge")
    objs = [SceneObject(name, save_mesh(trimesh.creation.box(ext), tmp / "meshes" / f"{name}.obj"), pose,
                        color=(60 + 60 * k, 90, 200), meta={"rgb": [60 + 60 * k, 90, 200]})
            for k, (name, ext, pose) in enumerate(LAYOUT)]
    scene = load_scene(save_scene(Scene(objs), tmp / "scene.json"))
    proxies = {o.id: proxy_for_mesh(o.mesh_path, ProxyParams(backend="convex"), tmp / "cache") for o in scene.objects}
    graph = SupportGraph(objects=scene.ids, backend="given", order=["box_a", "box_b", "plank"],
                         edges=[SupportEdge("ground", "box_a"), SupportEdge("ground", "box_b"),
                                SupportEdge("box_a", "plank"), SupportEdge("box_b", "plank")])
    out = tmp / "export"
    manifest = ex.export_scene(scene, proxies, out, SIM, graph=graph)
    return {"tmp": tmp, "scene": scene, "proxies": proxies, "graph": graph, "out": out, "manifest": manifest}


def _box_inertia(ext, mass):
    a, b, c = ext
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def test_export_writes_every_file(bridge):
    out, m = bridge["out"], bridge["manifest"]
    for name in ("glb", "mjcf", "urdf_index", "support_graph"):
        assert (out / m["files"][name]).is_file()
    assert json.loads((out / "export.json").read_text())["objects"] == ["box_a", "box_b", "plank"]
    for oid in ("box_a", "box_b", "plank"):
        assert (out / "urdf" / f"{oid}.urdf").is_file()
        assert (out / "meshes" / oid / "hull_0.stl").is_file()


def test_roundtrip_release_matches_pipeline_drift(bridge):
    check = ex.roundtrip_check(bridge["out"], bridge["scene"], bridge["proxies"], PhysicalParams(), SIM,
                               bridge["tmp"] / "cache")
    assert check["seconds"] == pytest.approx(2.0)
    assert check["ok"]
    for engine in ("pybullet", "mujoco"):
        c = check[engine]
        assert c["export"]["steps"] == 960  # 2 s at 1/480 s
        assert c["max_diff_trans"] <= 0.002 and c["max_diff_rot"] <= 1.0
        # a settled scene released in a fresh world stays put: far below the 2 mm tolerance
        for v in c["export"]["objects"].values():
            assert v["drift_trans"] < 3e-4 and v["drift_rot"] < 0.2


def test_roundtrip_check_detects_a_wrong_pose(bridge, tmp_path):
    """The check can fail: a URDF index whose plank floats 2 cm high drifts by about 2 cm."""
    import shutil

    out = tmp_path / "export"
    shutil.copytree(bridge["out"], out)
    index = json.loads((out / "scene_urdf.json").read_text())
    index["objects"][2]["position"][2] += 0.02
    (out / "scene_urdf.json").write_text(json.dumps(index))
    check = ex.roundtrip_check(out, bridge["scene"], bridge["proxies"], PhysicalParams(), SIM, tmp_path / "cache")
    assert not check["pybullet"]["ok"] and check["mujoco"]["ok"] and not check["ok"]
    assert check["pybullet"]["export"]["objects"]["plank"]["drift_trans"] == pytest.approx(0.02, abs=2e-3)


def test_urdf_inertial_is_closed_form_box_inertia(bridge):
    out = bridge["out"]
    props = ex.object_props(bridge["scene"], bridge["proxies"], SIM)
    for name, _, _pose in LAYOUT:
        scale = PLANK_SCALE if name == "plank" else 1.0
        ext_scaled = bridge["scene"].get(name).mesh().extents * scale  # the box as stored (OBJ digits)
        mass = SIM.density * float(np.prod(ext_scaled))
        link = ET.parse(out / "urdf" / f"{name}.urdf").getroot().find("link")
        inertial = link.find("inertial")
        assert float(inertial.find("mass").get("value")) == props[name].mass  # rigid_props, exactly
        assert float(inertial.find("mass").get("value")) == pytest.approx(mass, rel=1e-12)
        origin = inertial.find("origin")
        np.testing.assert_allclose([float(v) for v in origin.get("xyz").split()], 0.0, atol=1e-12)
        R = Rotation.from_euler("xyz", [float(v) for v in origin.get("rpy").split()]).as_matrix()
        el = inertial.find("inertia")
        principal = np.diag([float(el.get(k)) for k in ("ixx", "iyy", "izz")])
        np.testing.assert_allclose(R @ principal @ R.T, _box_inertia(ext_scaled, mass), rtol=1e-9, atol=1e-15)
        assert len(link.findall("collision")) == len(bridge["proxies"][name].hulls)
        # the collision hull is the box at the pose's scale, in the link frame
        hull = trimesh.load(out / "meshes" / name / "hull_0.stl")
        np.testing.assert_allclose(hull.extents, ext_scaled, rtol=1e-6)


def test_urdf_scene_in_fresh_pybullet_world_has_the_scene_poses_and_mass(bridge):
    from phiscene.sim.bullet import open_client

    client = open_client()
    try:
        uids = ex.load_urdf_scene(bridge["out"] / "scene_urdf.json", client)
        assert set(uids) == {"ground", "box_a", "box_b", "plank"}
        for o in bridge["scene"].objects:
            mass, _, inertia_diag = client.getDynamicsInfo(uids[o.id], -1)[:3]
            ext = o.mesh().extents * (PLANK_SCALE if o.id == "plank" else 1.0)
            assert mass == pytest.approx(SIM.density * np.prod(ext), rel=1e-9)
            expected = np.sort(np.diag(_box_inertia(ext, mass)))
            np.testing.assert_allclose(np.sort(inertia_diag), expected, rtol=1e-6)
            pos, _ = client.getBasePositionAndOrientation(uids[o.id])
            np.testing.assert_allclose(pos, o.pose[:3, 3], atol=1e-9)  # box centre = centre of mass
            friction = client.getDynamicsInfo(uids[o.id], -1)[1]
            assert friction == pytest.approx(SIM.friction)
    finally:
        client.disconnect()


def test_glb_reloaded_with_trimesh_equals_world_meshes(bridge):
    path = bridge["out"] / "scene.glb"
    meshes = ex.read_glb_world_meshes(path)
    assert sorted(meshes) == sorted(bridge["scene"].ids)
    for o in bridge["scene"].objects:
        world = o.world_mesh()
        np.testing.assert_allclose(meshes[o.id].vertices, world.vertices, atol=1e-6)
        np.testing.assert_array_equal(meshes[o.id].faces, world.faces)
        assert list(meshes[o.id].visual.material.baseColorFactor[:3]) == o.meta["rgb"]
    # glTF is +Y up: the raw file's height axis is y, and its top is the plank's top (0.12 m)
    raw = trimesh.load(path, force="scene")
    assert raw.bounds[1, 1] == pytest.approx(0.12, abs=1e-6)
    assert raw.bounds[0, 1] == pytest.approx(0.0, abs=1e-6)


def test_mjcf_loads_in_mujoco_with_the_pipeline_settings(bridge):
    mujoco = pytest.importorskip("mujoco")
    from phiscene.sim.mujoco import contact_friction

    model = mujoco.MjModel.from_xml_path(str(bridge["out"] / "scene.xml"))
    props = ex.object_props(bridge["scene"], bridge["proxies"], SIM)
    assert model.opt.timestep == pytest.approx(SIM.frame_dt / SIM.substeps, rel=1e-5)
    assert (model.jnt_type == mujoco.mjtJoint.mjJNT_FREE).sum() == 3
    np.testing.assert_array_equal(model.dof_damping, 0.0)
    for oid, pr in props.items():
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, oid)
        assert model.body_mass[b] == pytest.approx(pr.mass, rel=1e-5)
        np.testing.assert_allclose(model.body_inertia[b], pr.principal_moments, rtol=1e-5)
        vis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{oid}/visual")
        hull = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{oid}/hull0")
        assert model.geom_contype[vis] == 0 and model.geom_conaffinity[vis] == 0
        assert model.geom_group[vis] == ex.MJ_VISUAL_GROUP and model.geom_group[hull] == ex.MJ_COLLISION_GROUP
        np.testing.assert_allclose(model.geom_friction[hull], contact_friction(SIM), rtol=1e-5)


def test_support_graph_sidecar_keeps_every_parent(bridge):
    graph = topology.load(bridge["out"] / "support_graph.json", scene_ids=bridge["scene"].ids)
    assert graph.pairs() == bridge["graph"].pairs()
    assert graph.parents("plank") == ["box_a", "box_b"]
    meta = json.loads((bridge["out"] / "support_graph.json").read_text())["meta"]
    assert meta["parents"]["plank"] == ["box_a", "box_b"] and meta["urdf"]["plank"] == "urdf/plank.urdf"


def test_urdf_loads_in_yourdfpy(bridge):
    yourdfpy = pytest.importorskip("yourdfpy")
    robot = yourdfpy.URDF.load(str(bridge["out"] / "urdf" / "plank.urdf"), load_collision_meshes=True,
                               build_collision_scene_graph=True)
    assert robot.validate()
    ext = bridge["scene"].get("plank").mesh().extents * PLANK_SCALE
    link = robot.link_map["plank"]
    assert link.inertial.mass == pytest.approx(SIM.density * ext.prod(), rel=1e-12)
    assert len(link.collisions) == 1
    visual = robot.scene.to_geometry()
    np.testing.assert_allclose(visual.extents, ext, rtol=1e-6)


def test_bad_inputs_name_file_and_field(bridge, tmp_path):
    with pytest.raises(InputError, match="proxies"):
        ex.export_scene(bridge["scene"], {"box_a": bridge["proxies"]["box_a"]}, tmp_path / "x", SIM)
    bad = tmp_path / "scene_urdf.json"
    bad.write_text(json.dumps({"format": "something/1"}))
    with pytest.raises(InputError, match=r"scene_urdf\.json: format"):
        ex.read_urdf_index(bad)
    other = SupportGraph(objects=["box_a"], edges=[SupportEdge("ground", "box_a")])
    with pytest.raises(InputError, match="support graph objects"):
        ex.export_support_graph(other, bridge["scene"], tmp_path / "g.json")


def test_demo_throws_a_visible_ball_that_moves_the_target(bridge, tmp_path):
    from PIL import Image

    from phiscene.demo import BALL_RGB, DemoParams, save_gif, throw_ball
    from phiscene.render import RenderParams, project

    params = DemoParams(seconds=1.0, fps=10.0, width=160, height=120, ball_radius=0.045, speed=3.0)
    result = throw_ball(bridge["out"] / "scene_urdf.json", params, RenderParams(shadow=False))
    assert len(result.frames) == 11 and result.frames.shape[1:] == (120, 160, 3)
    np.testing.assert_allclose(result.times, np.arange(11) * 0.1, atol=1e-9)
    assert result.target == "plank"  # the object with the highest top
    # the launch is a ballistic arc at 3 m/s horizontally that would pass through the plank's centre of mass
    v = result.launch_velocity
    assert np.hypot(v[0], v[1]) == pytest.approx(params.speed)
    T = np.linalg.norm(result.ball[0][:2]) / params.speed
    np.testing.assert_allclose(result.ball[0] + v * T + 0.5 * np.array([0, 0, -9.81]) * T * T, [0, 0, 0.11],
                               atol=1e-9)
    assert np.linalg.norm(result.ball[-1] - result.ball[0]) > 0.3
    # ... and pushes the plank: undisturbed it stays within 0.3 mm (round-trip test), here it moves over 1 cm
    assert np.linalg.norm(result.objects["plank"][-1] - result.objects["plank"][0]) > 0.01
    assert result.ball_radius == 0.045
    gif = save_gif(result.frames, tmp_path / "demo.gif", params.fps)
    with Image.open(gif) as im:
        assert im.size == (160, 120)
        n = im.n_frames  # Pillow merges identical consecutive frames, adding up their durations
        durations, pixels = [], []
        for k in range(n):
            im.seek(k)
            durations.append(im.info["duration"])
            pixels.append(np.asarray(im.convert("RGB")))
    assert 3 <= n <= 11 and sum(durations) == 11 * 100
    uv = project(result.camera, result.ball[:2])
    assert np.linalg.norm(uv[1] - uv[0]) > 3  # pixels
    for k in (0, 1):  # the ball's projected centre shows the ball's colour in the GIF
        u, v = np.round(uv[k]).astype(int)
        assert np.abs(pixels[k][v, u].astype(int) - BALL_RGB).max() < 40


def test_cli_export(bridge, tmp_path, capsys):
    from phiscene.cli import main

    # proxies file and topology file as the workflow writes them
    from phiscene.proxies import write_proxies

    write_proxies(tmp_path / "p.npz", bridge["proxies"])
    topology.save(bridge["graph"], tmp_path / "t.json")
    rc = main(["export", str(bridge["scene"].source), str(tmp_path / "out"), "--proxies", str(tmp_path / "p.npz"),
               "--topology", str(tmp_path / "t.json"), "--no-check"])
    assert rc == 0
    assert "scene.glb" in capsys.readouterr().out
    assert (tmp_path / "out" / "scene.xml").is_file() and (tmp_path / "out" / "urdf" / "plank.urdf").is_file()
    assert math.isclose(json.loads((tmp_path / "out" / "export.json").read_text())["masses"]["box_a"], 0.5)


@pytest.mark.parametrize("fmt", ["urdf", "mjcf"])
@pytest.mark.parametrize("wall", [True, False])
def test_a_plank_leaning_on_a_wall_stays_in_the_exported_urdf_and_mjcf(tmp_path, fmt, wall):
    # the ladder (tests/scenes.py) on the wall x = 0 turned 20 deg about z: each export carries the wall, and
    # released for 2 s the plank stays; exported without it, it falls
    from scenes import ladder_on_wall

    scene, proxies = ladder_on_wall(tmp_path, 20.0, wall)
    sim = SimSettings()
    if fmt == "urdf":
        drift = ex.release_urdf(ex.export_urdf(scene, proxies, tmp_path / "out", sim), 2.0)["drift_trans"]
    else:
        drift = ex.release_mjcf(ex.export_mjcf(scene, proxies, tmp_path / "scene.xml", sim), 2.0)["drift_trans"]
    assert drift < 5e-3 if wall else drift > 0.05


def test_roundtrip_of_a_scene_with_a_wall_an_attached_poster_and_a_leaning_plank(tmp_path):
    # a poster fixed to the wall x = 0 (static in every export, not released), and the ladder leaning on that wall:
    # every export releases the plank as the pipeline does (the check names no missing object and passes)
    from scenes import ladder_on_wall

    ladder, proxies = ladder_on_wall(tmp_path, estimated=False)
    poster = SceneObject("poster", save_mesh(trimesh.creation.box((0.01, 0.6, 0.8)), tmp_path / "poster.obj"),
                         make_pose(translation=(0.005, 0.8, 1.5)), "poster on the wall", attached="wall_0")
    scene = Scene([*ladder.objects, poster], structure=ladder.structure)
    proxies["poster"] = proxy_for_mesh(poster.mesh_path, ProxyParams(backend="convex"), tmp_path / "cache")
    ex.export_scene(scene, proxies, tmp_path / "out", SIM)
    check = ex.roundtrip_check(tmp_path / "out", scene, proxies, PhysicalParams(), SIM, tmp_path / "cache")
    for engine in ("pybullet", "mujoco", "usd"):
        assert check[engine]["missing"] == [] and set(check[engine]["pipeline"]["objects"]) == {"plank"}
        assert check[engine]["export"]["objects"]["plank"]["drift_trans"] < 5e-3, engine
    assert check["ok"], {e: (check[e]["max_diff_trans"], check[e]["max_diff_rot"]) for e in ("pybullet", "mujoco")}
    index = json.loads((tmp_path / "out" / "scene_urdf.json").read_text())
    assert {o["id"]: o["fixed"] for o in index["objects"]} == {"plank": False, "poster": True}


def test_cli_export_of_a_workflow_result_takes_the_proxies_and_graph_it_was_grounded_with(bridge, tmp_path, capsys,
                                                                                         monkeypatch):
    # the workflow's layout: the grounded scene and its assembly log in one folder, the proxies and the support graph
    # it was grounded with elsewhere; export names neither and is run from another folder
    from phiscene.cli import main
    from phiscene.pipeline import run_ground
    from phiscene.proxies import write_proxies

    root = tmp_path / "wf"
    proxies, graph = root / "results/proxies/s/x.npz", root / "results/topology/given/s/x.json"
    proxies.parent.mkdir(parents=True)
    write_proxies(proxies, bridge["proxies"])
    graph.parent.mkdir(parents=True)
    topology.save(bridge["graph"], graph)
    grounded = root / "results/methods/m/s/x"
    monkeypatch.chdir(root)
    run_ground(bridge["scene"].source, graph.relative_to(root), proxies.relative_to(root), grounded / "scene.json",
               grounded / "assembly.json", {}, {}, tmp_path / "cache")
    assert json.loads((grounded / "assembly.json").read_text())["proxies"] == "results/proxies/s/x.npz"
    monkeypatch.chdir(tmp_path)
    rc = main(["export", str(grounded), str(tmp_path / "out"), "--no-check", "--cache-dir", str(tmp_path / "cache")])
    out = capsys.readouterr().out
    assert rc == 0
    assert f"proxies the scene was grounded with: {proxies}" in out
    assert f"support graph the scene was grounded with: {graph}" in out
    assert not (tmp_path / "out" / "proxies.npz").exists()  # nothing computed
    exported = json.loads((tmp_path / "out" / "support_graph.json").read_text())
    assert {(e["from"], e["to"]) for e in exported["edges"]} == {(e.source, e.target) for e in bridge["graph"].edges}
