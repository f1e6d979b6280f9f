"""Abandoned settling runs (settle.settle_object's ``abandon``, FaithfulParams.abandon).

Oracles: free fall (the frame at which a dropped box passes a height), and the same grounding with abandonment
off: a start abandoned where its end still decides is settled again to its end, so the final pose is the same.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh
from scenes import box_scene, convex_proxies
from scipy.spatial.transform import Rotation

from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.assembly.settle import SettleParams, settle_object
from phiscene.inertia import rigid_props
from phiscene.meshes import save_mesh
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import make_pose

torch.set_num_threads(1)


def test_a_dropped_box_is_abandoned_at_the_frame_free_fall_passes_the_height(tmp_path):
    # no damping: from 1.0 m the box's centre passes 0.5 m after sqrt(2 * 0.5 / g) s
    sim = SimSettings(linear_damping=0.0, angular_damping=0.0)
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    with BulletWorld(sim, tmp_path) as world:
        world.add_ground(0.0)
        world.add_body("box", [np.asarray(box.vertices)], make_pose(translation=(0, 0, 1.0)),
                       rigid_props(box, [np.asarray(box.vertices)], sim.density))
        result = settle_object(world, "box", SettleParams(), abandon=lambda p: p[2, 3] < 0.5)
    frame = math.ceil(math.sqrt(2 * 0.5 / 9.81) / sim.frame_dt)
    assert result.remedy == "abandoned" and not result.settled
    assert abs(result.frames - frame) <= 1  # the integrator's steps: within one frame of the analytic one
    assert 0.5 - 9.81 * (result.frames * sim.frame_dt) * sim.frame_dt <= result.pose[2, 3] < 0.5


@pytest.fixture(scope="module")
def rolling(tmp_path_factory):
    # a fruit on a slope (a board fixed 25 deg off level, 0.6 m up): every start rolls off it, past onto_reach
    # (the remedies that change its body, ballast and base, are off: one of them might stop it)
    root = tmp_path_factory.mktemp("abandon")
    fruit = trimesh.creation.icosphere(subdivisions=2, radius=0.04)
    meshes = {"board": save_mesh(trimesh.creation.box((0.5, 0.5, 0.02)), root / "board.obj"),
              "fruit": save_mesh(fruit, root / "fruit.obj")}
    R = Rotation.from_euler("x", 25.0, degrees=True).as_matrix()
    board = make_pose(R, (0.0, 0.0, 0.6))
    top = board[:3, :3] @ [0.0, 0.0, 0.01 + 0.0405] + board[:3, 3]
    scene = box_scene(meshes, {"board": ("board", board), "fruit": ("fruit", make_pose(translation=top))})
    graph = SupportGraph(objects=scene.ids, edges=[SupportEdge("board", "fruit", "supports")], order=scene.ids)
    return scene, graph, convex_proxies(scene, root / "cache"), root / "cache"


def test_a_start_abandoned_where_its_end_decides_is_settled_to_the_same_end(rolling):
    scene, graph, proxies, cache = rolling
    runs = {}
    for abandon in (True, False):
        params = AssemblyParams.from_dict({"faithful": {"enabled": True, "abandon": abandon, "shift_directions": 2,
                                                        "ballast": False, "base": False}})
        out, rec = ground_scene(scene, graph.order, proxies, params, SimSettings(), cache, graph=graph,
                                attached={"board": "ground"})
        runs[abandon] = (out.get("fruit").pose, rec["objects"]["fruit"])
    (pose_a, rec_a), (pose_b, rec_b) = runs[True], runs[False]
    assert rec_b["settle_remedy"] == "closest" and "moved" in rec_b["reason"]  # every start failed
    assert np.linalg.norm(pose_b[:3, 3] - scene.get("fruit").pose[:3, 3]) > 0.3  # grossly: off the board
    # every start failed grossly: the abandoned ones are settled to their ends and ranked there, as without
    # abandoning: the same final pose
    assert np.allclose(pose_a, pose_b, atol=1e-6) and rec_a["settled"] == rec_b["settled"]


def test_starts_that_fall_off_are_abandoned_and_the_accepted_one_is_the_same(tmp_path):
    # a block whose centre of mass is 3 cm past the edge of a 0.6 m high pedestal: released there it falls to
    # the floor (dropping past onto_reach, a gross failure) until remedy onto puts it on the pedestal
    meshes = {"pedestal": save_mesh(trimesh.creation.box((0.4, 0.4, 0.6)), tmp_path / "pedestal.obj"),
              "block": save_mesh(trimesh.creation.box((0.2, 0.1, 0.05)), tmp_path / "block.obj")}
    scene = box_scene(meshes, {"pedestal": ("pedestal", make_pose(translation=(0.0, 0.0, 0.3))),
                               "block": ("block", make_pose(translation=(0.23, 0.0, 0.626)))})
    graph = SupportGraph(objects=scene.ids, edges=[SupportEdge("ground", "pedestal", "supports"),
                                                   SupportEdge("pedestal", "block", "supports")], order=scene.ids)
    proxies = convex_proxies(scene, tmp_path / "cache")
    runs = {}
    for abandon in (True, False):
        params = AssemblyParams.from_dict({"faithful": {"enabled": True, "abandon": abandon}})
        out, rec = ground_scene(scene, graph.order, proxies, params, SimSettings(), tmp_path / "cache", graph=graph)
        runs[abandon] = (out.get("block").pose, rec["objects"]["block"])
    (pose_a, rec_a), (pose_b, rec_b) = runs[True], runs[False]
    assert rec_b["settle_remedy"] == "onto" and rec_a["settle_remedy"] == "onto"
    assert pose_b[2, 3] > 0.6  # on the pedestal
    assert np.allclose(pose_a, pose_b, atol=1e-6)
    assert rec_a["settle_frames"] < rec_b["settle_frames"]  # the falls were given up half-way
