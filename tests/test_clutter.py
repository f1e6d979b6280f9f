"""The clutter suite: walls as static colliders, leaning and wall-fixed objects, templates, verified ground truth."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from scenes import PLANK, leaning_pose

from phiscene.bench import clutter
from phiscene.bench.build import build_scene
from phiscene.bench.groundtruth import GTParams, ground_truth
from phiscene.bench.templates import GROUND, TEMPLATES, TemplateParams
from phiscene.inertia import rigid_props
from phiscene.meshes import save_mesh
from phiscene.metrics.drift import drift_bullet, drift_mujoco
from phiscene.metrics.physical import PhysicalParams
from phiscene.metrics.topology import edge_scores
from phiscene.proxies import ProxyParams, proxy_for_mesh
from phiscene.scene import Plane, Scene, SceneObject, load_scene
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import make_pose

SIM = SimSettings()
WALL = Plane("wall_0", "wall", (1.0, 0.0, 0.0), 0.0)  # the plane x = 0, room at x > 0


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("clutter_cache")


@pytest.fixture(scope="module")
def plank_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("plank")
    path = save_mesh(trimesh.creation.box(PLANK), root / "plank.obj")
    obj = SceneObject("plank", path.resolve(), leaning_pose(PLANK, 60.0), "wooden plank", meta={"category": "plank"})
    return Scene([obj], structure=[WALL])


def _release(scene: Scene, cache, seconds: float, walls: bool) -> float:
    """Largest displacement (m) of any free object released for ``seconds`` in pybullet (walls or not)."""
    proxies = {o.id: proxy_for_mesh(o.mesh_path, ProxyParams(backend="convex"), cache) for o in scene.objects}
    with BulletWorld(SIM, cache) as world:
        world.add_ground(0.0)
        if walls:
            world.add_structure(scene.structure)
        for o in scene.objects:
            hulls = proxies[o.id].hulls
            world.add_body(o.id, hulls, o.pose, None if o.attached else rigid_props(o.mesh(), hulls, SIM.density, 1.0))
        world.step_frames(int(round(seconds / SIM.frame_dt)))
        return max(float(np.linalg.norm(world.pose(o.id)[:3, 3] - o.pose[:3, 3])) for o in scene.objects)


def test_plank_leaning_on_a_wall_stays_with_the_wall_and_falls_without(plank_scene, cache):
    # statics of a ladder on a frictionless wall: it holds when mu_ground >= tan(30 deg) / 2 = 0.29 (pybullet
    # combines 0.8 * 0.8 = 0.64 here), so the wall plane alone must keep it within 1 mm for 2 s
    assert SIM.friction ** 2 >= np.tan(np.radians(30.0)) / 2
    assert _release(plank_scene, cache, 2.0, walls=True) < 1e-3
    assert _release(plank_scene, cache, 2.0, walls=False) > 0.05


def test_plank_leaning_on_a_wall_keeps_the_wall_as_supporter(plank_scene, cache):
    gt = ground_truth(plank_scene, SIM, ProxyParams(backend="convex"), cache, GTParams(),
                      intended={"plank": {"ground", "wall_0"}})
    assert gt.problem is None, gt.problem
    rel = {(e["from"], e["to"]): e["relation"] for e in gt.edges}
    assert rel == {("ground", "plank"): "supports", ("wall_0", "plank"): "leans_on"}
    # the topology file format takes the wall as a supporter node; a prediction without it loses recall
    graph = SupportGraph.from_dict({"format": "phiscene.topology/1", "objects": ["ground", "plank"],
                                    "edges": gt.edges, "structure": ["wall_0"]})
    assert graph.parents("plank") == ["ground", "wall_0"] and graph.object_ids == ["plank"]
    assert edge_scores(graph, gt.edges).f1 == 1.0
    assert edge_scores([("ground", "plank")], gt.edges).recall == 0.5


def test_drift_metrics_see_the_wall(plank_scene, cache):
    proxies = {"plank": proxy_for_mesh(plank_scene.objects[0].mesh_path, ProxyParams(backend="convex"), cache)}
    params = PhysicalParams()
    for drift in (lambda s: drift_bullet(s, proxies, params, SIM, cache),
                  lambda s: drift_mujoco(s, proxies, params, SIM)):
        with_wall = drift(plank_scene)["drift_trans"]
        without = drift(Scene(plank_scene.objects))["drift_trans"]
        assert with_wall < 5e-3 < 0.05 < without, (with_wall, without)


def test_attached_objects_stay_exactly_fixed(tmp_path, cache):
    shelf = save_mesh(trimesh.creation.box((0.6, 0.2, 0.02)), tmp_path / "shelf.obj").resolve()
    book = save_mesh(trimesh.creation.box((0.2, 0.14, 0.04)), tmp_path / "book.obj").resolve()
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    objs = [SceneObject("shelf", shelf, make_pose(R, (0.101, -0.5, 1.2)), "wall shelf", attached="wall_0",
                        meta={"category": "wall_shelf"}),
            SceneObject("book", book, make_pose(translation=(0.11, -0.5, 1.231)), "book", meta={"category": "book"})]
    scene = Scene(objs, structure=[WALL])
    gt = ground_truth(scene, SIM, ProxyParams(backend="convex"), cache, GTParams(),
                      intended={"shelf": {"wall_0"}, "book": {"shelf"}})
    assert gt.problem is None, gt.problem
    np.testing.assert_array_equal(gt.scene.get("shelf").pose, scene.get("shelf").pose)
    assert gt.drift_m["shelf"] == 0.0 and gt.drift_deg["shelf"] == 0.0
    rel = {(e["from"], e["to"]): e["relation"] for e in gt.edges}
    assert rel == {("wall_0", "shelf"): "attached", ("shelf", "book"): "supports"}
    proxies = {o.id: proxy_for_mesh(o.mesh_path, ProxyParams(backend="convex"), cache) for o in objs}
    drift = drift_mujoco(gt.scene, proxies, PhysicalParams(), SIM)
    assert drift["objects"]["shelf"]["attached"] == "wall_0" and drift["objects"]["book"]["drift_trans"] < 5e-3


@pytest.fixture(scope="module")
def library(cache):
    return clutter.clutter_library(0, N_ASSETS, cache)


#: A small asset library (boxes, planks, a tray, a blob, books, a wall panel: no slow pybullet_data props) keeps the
#: test fast; build_scene below reuses it.
N_ASSETS = 6
PARAMS = TemplateParams.from_dict(clutter.CLUTTER_DEFAULTS["template"])


def test_templates_fill_5_to_20_objects_inside_the_room(library):
    assert set(TEMPLATES["clutter"]) == set(clutter.CLUTTER_TEMPLATES)
    for name, template in TEMPLATES["clutter"].items():
        for seed, n in enumerate((5, 11, 20)):
            out = template(library, n, np.random.default_rng([seed, 7]), PARAMS)
            assert len(out) == n, (name, n)
            assert [p.id for p in out.structure] == ["wall_0", "wall_1"]
            for k, p in enumerate(out):
                v = np.asarray(p.asset.mesh.vertices) @ p.pose[:3, :3].T + p.pose[:3, 3]
                for wall in out.structure:  # every object on the room side of both walls, above the ground
                    assert wall.signed_distance(v).min() >= 0.0, (name, k, wall.id)
                assert v[:, 2].min() > 0.0
                for s in p.supporters:
                    assert s == GROUND or s in ("wall_0", "wall_1") or 0 <= s < n and s != k
                if p.attached is not None:
                    assert p.supporters == (p.attached,) and v[:, 2].min() >= clutter.MOUNT_HEIGHT[0]


def test_stack_of_four_is_a_chain(library, cache, tmp_path):
    from phiscene.bench.build import _write_meshes

    group = clutter.stack_group(library, np.random.default_rng(3), replace(PARAMS, stack_min=4, stack_max=4))
    assert len(group) == 4
    scene = _write_meshes(group, np.arange(4), tmp_path / "meshes")
    gt = ground_truth(scene, SIM, ProxyParams(), cache, GTParams())
    assert gt.problem is None, gt.problem
    # oracle: the geometric order of the stack; each object rests on the one right below it, the lowest on the ground
    by_height = sorted(gt.scene.objects, key=lambda o: o.world_mesh().bounds[0, 2])
    below = ["ground"] + [o.id for o in by_height[:-1]]
    assert {o.id: gt.supporters[o.id] for o in by_height} == {o.id: {b} for o, b in zip(by_height, below)}


def test_small_clutter_scenes_build_with_verified_ground_truth(library, cache, tmp_path):
    relations = set()
    # templates "leaning" (walls: leaning boards, a frame), "storage" (shelf, bowl), "dining" (table, tucked chair)
    for index in (1, 3, 4):
        out = tmp_path / f"scene_{index:03d}"
        build_scene(out, "clutter", index, {"n_objects": [5, 6], "max_attempts": 6, "n_assets": N_ASSETS}, cache)
        gt = json.loads((out / "gt" / "scene.json").read_text())
        topo = SupportGraph.from_dict(json.loads((out / "gt" / "topology.json").read_text()))
        assert 5 <= len(gt["objects"]) <= 6
        assert gt["meta"]["max_drift_m"] < 1e-3 and gt["meta"]["max_drift_deg"] < 0.5
        assert [p["id"] for p in gt["structure"]] == ["wall_0", "wall_1"] == topo.structure
        for o in gt["objects"]:
            parents = set(topo.parents(o["id"]))
            if "attached" in o:
                assert parents == {o["attached"]}
            else:  # the template's intent holds: a board meant to lean on a wall has the wall as supporter
                assert set(o["meta"]["intended_supporters"]) <= parents
        relations |= {e.relation for e in topo.edges if e.source in ("wall_0", "wall_1")}
        initial = json.loads((out / "initial" / "scene.json").read_text())
        assert initial["structure"] == gt["structure"]
        if index == 4:  # the chair's seat reaches under the table top, its back stays outside the edge
            scene = load_scene(out / "gt" / "scene.json")
            table = next(o for o in scene.objects if o.meta["category"] == "dining_table")
            chair = next(o for o in scene.objects if o.meta["category"] == "chair")
            v = chair.world_mesh().vertices @ table.pose[:3, :3] - table.pose[:3, 3] @ table.pose[:3, :3]
            assert np.abs(v[:, 1]).min() < table.mesh().extents[1] / 2 - 0.2
    assert relations == {"attached", "leans_on"}


def test_topology_files_with_walls_score_against_each_other(tmp_path):
    from phiscene.metrics.topology import file_scores
    from phiscene.topology.graph import save

    gt = SupportGraph(["ground", "a", "b"], [], structure=["wall_0"])
    gt = gt.with_edges([SupportEdge("ground", "a"), SupportEdge("ground", "b"), SupportEdge("wall_0", "b", "leans_on"),
                        SupportEdge("wall_0", "a", "attached")])
    pred = SupportGraph(["ground", "a", "b"], [SupportEdge("ground", "a"), SupportEdge("ground", "b")])
    save(gt, tmp_path / "gt.json")
    save(pred, tmp_path / "pred.json")
    # 2 of the 4 GT edges found, nothing wrong predicted: P = 1, R = 0.5, F1 = 2/3
    s = file_scores(tmp_path / "pred.json", tmp_path / "gt.json")
    assert (s.tp, s.fp, s.fn) == (2, 0, 2) and s.f1 == pytest.approx(2 / 3)
    assert file_scores(tmp_path / "gt.json", tmp_path / "gt.json").f1 == 1.0


def test_given_topology_keeps_the_walls(plank_scene, tmp_path):
    from phiscene import topology
    from phiscene.topology.graph import save

    gt = SupportGraph(["ground", "plank"], [SupportEdge("ground", "plank"), SupportEdge("wall_0", "plank", "leans_on")],
                      structure=["wall_0"])
    save(gt, tmp_path / "gt.json")
    graph = topology.infer(plank_scene, "given", given_path=tmp_path / "gt.json")
    assert graph.structure == ["wall_0"] and graph.order == ["plank"]
    assert sorted(graph.parents("plank")) == ["ground", "wall_0"]


def test_geometric_backend_finds_the_wall_a_plank_leans_on(plank_scene):
    from phiscene import topology

    graph = topology.infer(plank_scene, "geometric", {})
    assert sorted(graph.parents("plank")) == ["ground", "wall_0"] and graph.structure == ["wall_0"]
    # the same plank standing upright against the wall is held from below: no wall edge
    upright = Scene([replace(plank_scene.objects[0], pose=leaning_pose(PLANK, 90.0))], structure=[WALL])
    assert topology.infer(upright, "geometric", {}).parents("plank") == ["ground"]


def test_sdf_stage_pushes_an_object_out_of_a_wall(cache):
    from phiscene.assembly.penetration import PenetrationParams, resolve_penetration, sdf_body

    params = PenetrationParams()
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    # a box resting on the ground whose back face is 3 cm inside the wall x = 0
    body = sdf_body("box", box, make_pose(translation=(0.07, 0.0, 0.1 + params.eps)), 512, params, cache)
    x, _ = resolve_penetration(body, [], 0.0, params, planes=[WALL])
    # the hinge stops where every sample clears the wall by eps: a move of 3 cm + eps along the wall's normal
    assert x[0] == pytest.approx(0.03 + params.eps, abs=2e-3) and abs(x[1]) < 1e-3 and abs(x[2]) < 2e-3
    x0, _ = resolve_penetration(body, [], 0.0, params)
    assert np.linalg.norm(x0) < 1e-3  # without the wall there is nothing to resolve


def test_planar_sdf_stage_leaves_a_tilted_wall_horizontally(cache):
    from phiscene.assembly.penetration import PenetrationParams, resolve_penetration, sdf_body
    from phiscene.scene import Plane

    params = PenetrationParams(optimizer="steepest")
    tilt = np.radians(3.0)  # an estimated wall 3 degrees off vertical, leaning over the room
    wall = Plane(id="wall_t", kind="wall", normal=(float(np.cos(tilt)), 0.0, float(np.sin(tilt))), offset=0.0)
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    body = sdf_body("box", box, make_pose(translation=(0.07, 0.0, 0.1 + 2 * params.eps)), 512, params, cache)
    free, _ = resolve_penetration(body, [], 0.0, params, planes=[wall])
    flat, info = resolve_penetration(body, [], 0.0, params, planes=[wall], planar=True)
    # along the normal the wall lifts the box (tan 3 deg of the push); planar, only the ground may move it up
    assert free[2] > 0.05 * free[0] > 0
    assert info["final_loss"] == 0.0 and flat[2] == 0.0 and abs(flat[1]) < 1e-9
    # out of the wall horizontally until its deepest point (the back face's bottom edge, 2 eps above the
    # ground) clears it by eps: cos t (dx - 0.03) + 2 eps sin t = eps
    need = 0.03 + (params.eps - 2 * params.eps * np.sin(tilt)) / np.cos(tilt)
    assert flat[0] == pytest.approx(need, abs=1e-3)
