"""Baselines: joint SDF, joint simulation, single-parent lifting, external import.

Oracles are analytic box geometry (clearances, rest heights), the exact SDF
of :mod:`phiscene.sdf`, an unpruned evaluation of the joint loss, and known
poses written into prediction files.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh
from scenes import box_meshes, box_scene, clearance, convex_proxies

from phiscene.assembly.penetration import sdf_body
from phiscene.baselines import (
    ImportParams,
    JointSdfParams,
    JointSdfSimParams,
    JointSimParams,
    LiftParams,
    depth_order,
    import_external,
    joint_sdf,
    joint_sdf_sim,
    joint_sim,
    lift_scene,
    lift_sim,
    single_parent,
)
from phiscene.baselines.joint_sdf import JointLoss
from phiscene.errors import InputError
from phiscene.meshes import load_mesh, save_mesh
from phiscene.scene import Scene, save_scene
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph
from phiscene.transforms import make_pose, random_rotation, rotation_z

torch.set_num_threads(1)
SIM = SimSettings()
EPS = JointSdfParams().eps


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A folder with box meshes (name -> path) and a shared cache."""
    root = tmp_path_factory.mktemp("baselines")
    sizes = {"big": (0.4, 0.4, 0.2), "cube": (0.1, 0.1, 0.1)}
    return {"root": root, "cache": root / "cache", "meshes": box_meshes(root, sizes)}


def make_scene(work, placements: dict[str, tuple[str, np.ndarray]]) -> Scene:
    return box_scene(work["meshes"], placements, describe=True)


def proxies(work, scene: Scene) -> dict:
    return convex_proxies(scene, work["cache"])


def bounds(scene: Scene, oid: str) -> np.ndarray:
    return np.asarray(scene.get(oid).world_mesh().bounds)


# -- joint SDF -------------------------------------------------------------------------------------------------------
def test_joint_sdf_separates_both_boxes_to_clearance_eps(work):
    # two cubes overlapping by 2 cm along x, in the air (the ground term stays inactive)
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(-0.04, 0.0, 0.2))),
                              "b": ("cube", make_pose(translation=(0.04, 0.0, 0.2)))})
    out, rec = joint_sdf(scene, JointSdfParams(), work["cache"])
    assert rec["converged"] and rec["final_loss"] == 0.0 and rec["initial_loss"] > 0
    t = {k: out.get(k).pose[:3, 3] - scene.get(k).pose[:3, 3] for k in "ab"}
    # joint: both objects move, apart along x, by opposite amounts (identical meshes and samples: the
    # gradients are exactly opposite). Adam's first steps are ~lr * sign(gradient) per coordinate, so the
    # tiny off-axis gradients of the sampled faces move y and z by up to a few steps as well.
    assert t["a"][0] < -0.005 and t["b"][0] > 0.005
    assert np.allclose(t["a"], -t["b"], atol=1e-9)
    for k in "ab":
        assert np.allclose(out.get(k).pose[:3, :3], np.eye(3))  # rotations fixed
    c = clearance(out.get("a").world_mesh(), out.get("b").world_mesh())
    assert c == pytest.approx(EPS, abs=5e-4)
    assert rec["pairs"] == [["a", "b"]]
    assert rec["objects"]["a"]["displacement"] == pytest.approx(np.linalg.norm(t["a"]))


def test_joint_sdf_ground_lifts_sunk_box(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0.0, 0.0, 0.03)))})  # 2 cm into the ground
    out, rec = joint_sdf(scene, JointSdfParams(), work["cache"])
    assert bounds(out, "a")[0, 2] == pytest.approx(EPS, abs=1e-4)
    out, _ = joint_sdf(scene, JointSdfParams(ground=False), work["cache"])
    assert np.allclose(out.get("a").pose, scene.get("a").pose)  # nothing to resolve without the ground


def test_joint_loss_pruning_is_exact(work):
    rng = np.random.default_rng(0)
    placements = {f"o{i}": ("cube", make_pose(random_rotation(rng, np.pi), rng.uniform(-0.3, 0.3, 3) * [1, 1, 0.3]
                                              + [0, 0, 0.08])) for i in range(6)}
    pp = JointSdfParams(n_samples=512).penetration_params()
    bodies = [sdf_body(k, load_mesh(work["meshes"]["cube"]), p, 512, pp, work["cache"])
              for k, (_, p) in placements.items()]
    pruned = JointLoss(bodies, 0.0, EPS, True, prune=True)
    full = JointLoss(bodies, 0.0, EPS, True, prune=False)
    skipped = 0
    for _ in range(20):
        X = torch.as_tensor(rng.normal(0.0, 0.05, (6, 3)))
        assert float(pruned(X)) == pytest.approx(float(full(X)), rel=1e-12, abs=1e-12)
        skipped += full.pair_counts[-1] - pruned.pair_counts[-1]
    assert skipped > 0  # the test exercised pruning


def test_joint_sdf_params_from_dict():
    p = JointSdfParams.from_dict({"eps": 0.01, "grid": {"resolution": 32}})
    assert p.eps == 0.01 and p.grid.resolution == 32 and p.n_samples == 2048 and p.lr == 0.005
    assert p.max_iterations == 300
    with pytest.raises(ValueError, match="nope"):
        JointSdfParams.from_dict({"nope": 1})
    with pytest.raises(ValueError, match="nope"):
        JointSdfSimParams.from_dict({"sim": {"nope": 1}})
    with pytest.raises(ValueError, match="nope"):
        LiftParams.from_dict({"nope": 1})
    assert JointSimParams.from_dict(None) == JointSimParams(15, 1e-4, 1e-4, 240)


# -- joint simulation ------------------------------------------------------------------------------------------------
def test_joint_sim_floating_box_comes_to_rest_on_the_ground(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0.1, 0.2, 0.25))),
                              "b": ("big", make_pose(translation=(1.0, 0.0, 0.1)))})  # b already at rest
    out, rec = joint_sim(scene, proxies(work, scene), SIM, JointSimParams(), work["cache"])
    assert bounds(out, "a")[0, 2] == pytest.approx(0.0, abs=1e-3)
    assert bounds(out, "b")[0, 2] == pytest.approx(0.0, abs=1e-3)
    assert np.allclose(out.get("a").pose[:2, 3], [0.1, 0.2], atol=1e-3)  # straight down
    assert rec["all_settled"] and rec["objects"]["a"]["settled"] and rec["unsettled"] == []
    assert rec["frames"] < JointSimParams().max_frames
    assert rec["objects"]["a"]["residual_translation"] < 1e-4
    assert rec["objects"]["a"]["displacement"] == pytest.approx(0.2, abs=1e-3)
    json.dumps(rec, allow_nan=False)


def test_joint_sim_reports_unsettled_at_the_cap(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0.0, 0.0, 2.0)))})  # still falling at the cap
    _, rec = joint_sim(scene, proxies(work, scene), SIM, JointSimParams(max_frames=20), work["cache"])
    assert rec["frames"] == 20 and not rec["all_settled"] and rec["unsettled"] == ["a"]


def test_joint_sim_missing_proxy_is_an_input_error(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0.0, 0.0, 0.05)))})
    with pytest.raises(InputError, match="proxies"):
        joint_sim(scene, {}, SIM, JointSimParams(), work["cache"])


def test_joint_sdf_sim_resolves_then_settles(work):
    # a cube sunk 3 cm into a big box: SDF pushes it out (jointly), simulation settles the stack
    scene = make_scene(work, {"base": ("big", make_pose(translation=(0.0, 0.0, 0.1))),
                              "top": ("cube", make_pose(translation=(0.0, 0.0, 0.22)))})
    out, rec = joint_sdf_sim(scene, proxies(work, scene), SIM, JointSdfSimParams(), work["cache"])
    assert rec["sdf"]["converged"] and rec["sim"]["all_settled"]
    assert rec["sdf"]["objects"]["base"]["displacement"] > 0.005  # joint: the base moved too
    assert bounds(out, "base")[0, 2] == pytest.approx(0.0, abs=1e-3)
    assert bounds(out, "top")[0, 2] == pytest.approx(bounds(out, "base")[1, 2], abs=1e-3)


# -- lift + simulation -----------------------------------------------------------------------------------------------
def graph_of(ids, edges) -> SupportGraph:
    return SupportGraph(objects=[GROUND] + list(ids), edges=[SupportEdge(*e) for e in edges])


def test_single_parent_keeps_the_most_confident_parent_ties_by_edge_order():
    g = graph_of(["a", "b", "c", "d"], [(GROUND, "a", "supports", 1.0), (GROUND, "c", "supports", 0.6),
                                        ("b", "c", "supports", 0.9), ("a", "c", "leans_on", 0.9),
                                        (GROUND, "b", "supports", 0.5)])
    assert single_parent(g) == {"a": GROUND, "b": GROUND, "c": "b", "d": GROUND}
    g2 = graph_of(["a", "b", "c"], [("a", "c", "supports", 0.9), ("b", "c", "supports", 0.9)])
    assert single_parent(g2)["c"] == "a"
    assert depth_order(single_parent(g)) == [("a", 1), ("b", 1), ("d", 1), ("c", 2)]
    with pytest.raises(ValueError, match="not reachable"):
        depth_order({"a": "b", "b": "a"})


def test_lift_then_sim_puts_penetrating_top_box_on_its_parent(work):
    # base 0.4 x 0.4 x 0.2 on the ground; the cube penetrates it by 3 cm
    scene = make_scene(work, {"top": ("cube", make_pose(rotation_z(0.4), (0.05, -0.03, 0.22))),
                              "base": ("big", make_pose(translation=(0.0, 0.0, 0.1)))})
    g = graph_of(scene.ids, [(GROUND, "top", "supports", 0.3), ("base", "top", "supports", 0.9),
                             (GROUND, "base", "supports", 1.0)])
    gap = LiftParams().gap
    lifted, info = lift_scene(scene, single_parent(g), gap)
    assert info["top"]["parent"] == "base" and info["top"]["depth"] == 2
    # the base (resting on the ground) is lifted by the gap first, then the cube above the lifted base
    assert info["base"]["lift"] == pytest.approx(gap, abs=1e-12)
    assert info["top"]["lift"] == pytest.approx(0.03 + 2 * gap, abs=1e-9)
    assert bounds(lifted, "top")[0, 2] == pytest.approx(bounds(lifted, "base")[1, 2] + gap, abs=1e-9)
    assert bounds(lifted, "top")[0, 2] > bounds(scene, "base")[1, 2]
    out, rec = lift_sim(scene, g, proxies(work, scene), SIM, LiftParams(), work["cache"])
    assert rec["sim"]["all_settled"]
    assert out.get("top").pose[2, 3] == pytest.approx(0.25, abs=1e-3)  # analytic rest height: 0.2 + 0.05
    assert out.get("base").pose[2, 3] == pytest.approx(0.1, abs=1e-3)
    assert np.allclose(out.get("top").pose[:2, 3], [0.05, -0.03], atol=1e-3)


def test_lift_uses_the_ground_and_lifts_only(work):
    scene = make_scene(work, {"sunk": ("cube", make_pose(translation=(0.0, 0.0, 0.03))),
                              "high": ("cube", make_pose(translation=(0.5, 0.0, 0.3)))})
    lifted, info = lift_scene(scene, {"sunk": GROUND, "high": GROUND}, 0.002)
    assert bounds(lifted, "sunk")[0, 2] == pytest.approx(0.002, abs=1e-9)
    assert info["high"]["lift"] == 0.0 and lifted.get("high").pose[2, 3] == 0.3


def test_lift_sim_rejects_graph_of_another_scene(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0.0, 0.0, 0.05)))})
    with pytest.raises(InputError, match="missing scene objects"):
        lift_sim(scene, graph_of(["z"], []), proxies(work, scene), SIM, LiftParams(), work["cache"])


# -- external import -------------------------------------------------------------------------------------------------
@pytest.fixture()
def initial(work, tmp_path):
    scene = make_scene(work, {"obj_01": ("cube", make_pose(translation=(0.0, 0.0, 0.05))),
                              "obj_02": ("big", make_pose(translation=(1.0, 0.0, 0.1)))})
    path = save_scene(scene, tmp_path / "initial" / "scene.json")
    from phiscene.scene import load_scene

    return load_scene(path)


def known_poses():
    rng = np.random.default_rng(3)
    return {"obj_01": make_pose(random_rotation(rng, np.pi), (0.3, -0.2, 0.41), scale=1.2),
            "obj_02": make_pose(random_rotation(rng, np.pi), (-0.7, 0.25, 0.13))}


def check_common(out, initial):
    assert out.ids == initial.ids and out.ground_height == initial.ground_height
    for a, b in zip(out.objects, initial.objects):
        assert (a.description, a.color) == (b.description, b.color)


def test_import_meshes_layout_keeps_file_mesh(initial, tmp_path):
    pred = tmp_path / "pred"
    poses = known_poses()
    files = {}
    for (oid, pose), suffix in zip(poses.items(), (".ply", ".glb")):
        m = initial.get(oid).mesh().copy()
        m.apply_transform(pose)
        files[oid] = save_mesh(m, pred / f"{oid}{suffix}")
    (pred / "notes.txt").write_text("ignored: not a mesh file")
    out, rec = import_external(pred, initial, tmp_path / "out" / "scene.json")
    assert rec["layout"] == "meshes" and set(rec["objects"].values()) == {"imported"}
    check_common(out, initial)
    for oid, f in files.items():
        o = out.get(oid)
        assert np.array_equal(o.pose, np.eye(4))
        assert o.mesh_path.parent == (tmp_path / "out" / "meshes").resolve()
        ref = load_mesh(f)
        w = o.world_mesh()
        assert np.array_equal(w.vertices, ref.vertices) and np.array_equal(w.faces, ref.faces)
        # and the file is the initial mesh at the known pose (up to the file format's float32)
        assert np.allclose(w.vertices, trimesh.transform_points(initial.get(oid).mesh().vertices, poses[oid]),
                           atol=1e-6)


def test_same_frame_import_keeps_the_walls(initial, tmp_path):
    from dataclasses import replace

    from phiscene.scene import Plane

    walled = replace(initial, structure=[Plane("wall_0", "wall", (1.0, 0.0, 0.0), 2.0, estimated=True)])
    pred = tmp_path / "pred"
    pred.mkdir()
    (pred / "poses.json").write_text(json.dumps({k: v.tolist() for k, v in known_poses().items()}))
    out, _ = import_external(pred, walled, tmp_path / "out" / "scene.json")
    assert out.structure == walled.structure and initial.structure == []


def test_import_poses_layout_gives_poses_back(initial, tmp_path):
    pred = tmp_path / "pred"
    pred.mkdir()
    poses = known_poses()
    (pred / "poses.json").write_text(json.dumps({k: v.tolist() for k, v in poses.items()}))
    out, rec = import_external(pred, initial.source, tmp_path / "out" / "scene.json")
    assert rec["layout"] == "poses"
    check_common(out, initial)
    for oid, pose in poses.items():
        assert np.allclose(out.get(oid).pose, pose, atol=1e-6)
        assert out.get(oid).mesh_path == initial.get(oid).mesh_path


def test_import_scene_layout_gives_node_transforms_back(initial, tmp_path):
    pred = tmp_path / "pred"
    pred.mkdir()
    poses = known_poses()
    glb = trimesh.Scene()
    for oid, pose in poses.items():
        glb.add_geometry(initial.get(oid).mesh().copy(), node_name=oid, geom_name=f"{oid}_geom", transform=pose)
    glb.add_geometry(trimesh.creation.box((0.01, 0.01, 0.01)), node_name="decor", geom_name="decor")
    (pred / "prediction.glb").write_bytes(glb.export(file_type="glb"))
    with pytest.raises(InputError, match="decor"):
        import_external(pred, initial, tmp_path / "out" / "scene.json")
    out, rec = import_external(pred, initial, tmp_path / "out" / "scene.json", ImportParams(extra="ignore"))
    assert rec["layout"] == "scene" and rec["extra"] == ["decor"]
    check_common(out, initial)
    for oid, pose in poses.items():
        o = out.get(oid)
        assert np.allclose(o.pose, pose, atol=1e-6)
        assert np.allclose(o.mesh().vertices, initial.get(oid).mesh().vertices, atol=1e-6)


def test_import_missing_objects(initial, tmp_path):
    pred = tmp_path / "pred"
    pred.mkdir()
    pose = known_poses()["obj_01"]
    (pred / "poses.json").write_text(json.dumps({"obj_01": pose.tolist()}))
    with pytest.raises(InputError, match=r"pred.*obj_02") as exc:
        import_external(pred, initial, tmp_path / "out" / "scene.json")
    assert "obj_01" not in str(exc.value)
    out, rec = import_external(pred, initial, tmp_path / "out" / "scene.json", ImportParams(missing="keep"))
    assert rec["objects"] == {"obj_01": "imported", "obj_02": "kept_initial"}
    assert np.allclose(out.get("obj_01").pose, pose) and np.allclose(out.get("obj_02").pose, initial.get("obj_02").pose)
    assert out.meta["external"]["kept_initial"] == ["obj_02"]


def test_import_bad_input(initial, tmp_path):
    pred = tmp_path / "pred"
    pred.mkdir()
    with pytest.raises(InputError, match="cannot tell"):
        import_external(pred, initial, tmp_path / "out" / "scene.json")
    bad = np.eye(4)
    bad[0, 0] = 2.0  # non-uniform scale
    (pred / "poses.json").write_text(json.dumps({"obj_01": bad.tolist(), "obj_02": np.eye(4).tolist()}))
    with pytest.raises(InputError, match="obj_01.*uniform scale"):
        import_external(pred, initial, tmp_path / "out" / "scene.json")
    with pytest.raises(InputError, match="not found"):
        import_external(tmp_path / "nothing", initial, tmp_path / "out" / "scene.json")
    with pytest.raises(ValueError, match="layout"):
        ImportParams.from_dict({"layout": "zip"})


def test_single_parent_never_takes_a_wall():
    """PAT3D-style lifting puts a child above its parent's top: a wall has no top, so a board leaning on a wall
    and on a box gets the box, and one leaning on the wall alone rests on the ground."""
    from phiscene.baselines.lift import depth_order, single_parent
    from phiscene.topology.graph import SupportEdge, SupportGraph

    graph = SupportGraph(objects=["box", "board", "plank"],
                         edges=[SupportEdge("ground", "box", "supports", 1.0, ""),
                                SupportEdge("wall_0", "board", "leans_on", 1.0, ""),
                                SupportEdge("box", "board", "leans_on", 0.9, ""),
                                SupportEdge("wall_0", "plank", "leans_on", 1.0, "")],
                         order=["box", "board", "plank"], structure=["wall_0"])
    parents = single_parent(graph)
    assert parents == {"box": "ground", "board": "box", "plank": "ground"}
    assert dict(depth_order(parents)) == {"box": 1, "plank": 1, "board": 2}
