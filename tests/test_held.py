"""Remedy ``held``: an object that the fallback carries across the scene is kept where it was put, not settled.

Oracle: the statics of a ball on an incline. A sphere on a plane inclined at ``SLOPE`` rolls whatever the
friction (its weight's moment about the contact point is never zero), so no start near the top of a 2 m ramp
comes to rest before the foot of the ramp, far beyond the remedy's bound; kept, it touches the ramp from
beneath (the ramp's normal is ``SLOPE`` from vertical, well within 60 deg).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
import trimesh
from scenes import convex_proxies

from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.guarded import far_bound
from phiscene.meshes import save_mesh
from phiscene.scene import Scene, SceneObject
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import make_pose, rotation_angle

torch.set_num_threads(1)

SLOPE = 20.0  # deg
RAMP = (2.0, 0.6, 0.04)  # m
RADIUS = 0.06  # m


def ball_on_ramp(tmp_path, hold_far: float):
    """A ball 1 mm above a fixed ramp, 0.7 m up it from the ramp's centre, grounded with ``hold_far``; the input
    pose, the grounded scene and the record."""
    tilt = trimesh.transformations.rotation_matrix(np.radians(SLOPE), (0.0, 1.0, 0.0))[:3, :3]  # +x end down
    ramp_pose = make_pose(rotation=tilt, translation=(0.0, 0.0, 0.4))
    normal = tilt[:, 2]
    top = ramp_pose[:3, :3] @ np.array([-0.7, 0.0, RAMP[2] / 2]) + ramp_pose[:3, 3]
    ball_pose = make_pose(translation=top + (RADIUS + 0.001) * normal)
    scene = Scene([SceneObject("ramp", save_mesh(trimesh.creation.box(RAMP), tmp_path / "ramp.obj"), ramp_pose),
                   SceneObject("ball", save_mesh(trimesh.creation.icosphere(3, RADIUS), tmp_path / "ball.obj"),
                               ball_pose)])
    order = ["ramp", "ball"]
    graph = SupportGraph(objects=order, edges=[SupportEdge("ground", "ramp", "attached"),
                                               SupportEdge("ramp", "ball", "supports")], order=order)
    # the remedies that change its body off (base would complete a flat foot under it that holds it on the ramp)
    params = AssemblyParams.from_dict({"penetration": False, "faithful": {
        "enabled": True, "flush": False, "ballast": False, "base": False, "hold_far": hold_far}})
    out, rec = ground_scene(scene, order, convex_proxies(scene, tmp_path / "cache"), params, SimSettings(),
                            tmp_path / "cache", graph=graph, attached={"ramp": "ground"})
    return ball_pose, out, rec


def test_a_ball_every_start_rolls_down_a_ramp_is_held_where_it_was_put(tmp_path):
    assert FaithfulParams().hold_far == 1.0
    start, out, rec = ball_on_ramp(tmp_path, 1.0)
    r = rec["objects"]["ball"]
    bound = far_bound(2 * RADIUS * np.sqrt(3), FaithfulParams())
    assert bound == FaithfulParams().onto_reach  # a 12 cm ball: the larger is onto_reach
    assert r["settle_remedy"] == "held" and r["settled"] is False
    assert f"m, farther than {bound:.2f} m" in r["reason"] and "kept: the fallback" in r["reason"]
    assert r["attempts"] >= 4  # the corrected pose, resting poses, damped, shifted: every one rolled away
    assert out.get("ball").attached == "ground" and rec["summary"]["held"] == ["ball"]
    assert "ball" in rec["summary"]["unsettled"] and "ball" in rec["summary"]["attached"]
    cert = r["certificate"]
    assert cert["settled"] is False and cert["remedy"] == "held" and cert["supporters_kept"]
    assert cert["touching"] == ["ramp"]
    pose = np.asarray(out.get("ball").pose)
    # already within contact_tol / 2 of the ramp: not lowered, not turned
    assert np.linalg.norm(pose[:3, 3] - start[:3, 3]) < 1e-9 and rotation_angle(pose[:3, :3], start[:3, :3]) < 1e-9
    assert cert["displacement"] < 1e-9


def test_without_the_remedy_the_ball_takes_the_fallback_far_down_the_ramp(tmp_path):
    start, out, rec = ball_on_ramp(tmp_path, 0.0)
    r = rec["objects"]["ball"]
    assert r["settle_remedy"] == "closest" and out.get("ball").attached is None and rec["summary"]["held"] == []
    # a rolling ball ends past the ramp's foot: more than the 0.7 m it had to go along the ramp, horizontally
    moved = np.linalg.norm(np.asarray(out.get("ball").pose)[:2, 3] - start[:2, 3])
    assert moved > 0.7 * np.cos(np.radians(SLOPE)) > FaithfulParams().onto_reach
    assert rec["objects"]["ball"]["certificate"]["displacement"] == pytest.approx(
        np.linalg.norm(np.asarray(out.get("ball").pose)[:3, 3] - start[:3, 3]), abs=1e-6)


def test_thrown_objects_are_those_the_release_took_past_their_bound_and_away_from_their_input(tmp_path):
    from phiscene.assembly.assemble import _thrown

    # three 0.1 m cubes (bound: onto_reach 0.3 m, above their 0.17 m diagonal); centres of mass at their origins
    cube = save_mesh(trimesh.creation.box((0.1, 0.1, 0.1)), tmp_path / "cube.obj")
    at = lambda x: make_pose(translation=(x, 0.0, 0.05))  # noqa: E731
    scene = Scene([SceneObject(o, cube, at(0.0)) for o in ("thrown", "near", "back")])
    inputs = {"thrown": at(0.0), "near": at(0.0), "back": at(1.0)}
    sequential = {"thrown": at(0.0), "near": at(0.0), "back": at(0.0)}  # "back": its fallback took it 1 m away
    final = {"thrown": at(0.31), "near": at(0.29), "back": at(0.9)}  # regrounded near its input: not thrown
    coms = {o: np.zeros(3) for o in inputs}
    fp = FaithfulParams()
    assert _thrown(scene, inputs, sequential, final, coms, {}, fp) == {"thrown": pytest.approx(0.31)}
    assert _thrown(scene, inputs, sequential, final, coms, {"thrown": "ground"}, fp) == {}


def test_the_joint_stage_is_redone_with_what_it_threw_held_at_its_sequential_rest(tmp_path, monkeypatch):
    # the joint release stubbed: it throws "a" 1 m whenever "a" is free, and "b" 1 m whenever "a" is held (as the
    # objects pushed by a held one are); "c" never moves. The stage must hold "a", then "b", each at its sequential
    # rest with its record marked, and stop there: a third pass is not needed
    from phiscene.assembly import assemble

    cube = save_mesh(trimesh.creation.box((0.1, 0.1, 0.1)), tmp_path / "cube.obj")
    at = lambda x: make_pose(translation=(x, 0.0, 0.05))  # noqa: E731
    scene = Scene([SceneObject(o, cube, at(x)) for o, x in (("a", 0.0), ("b", 1.0), ("c", 2.0))])
    order = ["a", "b", "c"]
    sequential = {o: np.asarray(scene.get(o).pose, float) for o in order}
    passes = []

    def fake_joint(grounded, proxies, sim, cache_dir, fp, sp, objects, coms, inputs):
        fixed = {o.id for o in grounded.objects if o.attached is not None}
        passes.append(sorted(fixed))
        poses = {o.id: np.asarray(o.pose, float) for o in grounded.objects}
        thrower = "b" if "a" in fixed else "a"
        if thrower not in fixed:
            poses[thrower] = poses[thrower] @ make_pose(translation=(0.0, 1.0, 0.0))
            objects[thrower]["joint_settle"] = [1.0, 0.0]
        return poses

    monkeypatch.setattr(assemble, "_joint_settle", fake_joint)
    record = {"settled": True, "settle_remedy": "none", "certificate": {"settled": True, "remedy": "none"}}
    objects = {o: copy.deepcopy(record) for o in order}
    attached: dict = {}
    params = AssemblyParams.from_dict({"faithful": {"enabled": True, "reground": False}})
    lines = []
    out = assemble._joint_stage(scene, order, {}, params, SimSettings(), tmp_path, None, attached, dict(sequential),
                                objects, {o: np.zeros(3) for o in order}, {}, {}, lines.append)
    assert passes == [[], ["a"], ["a", "b"]]
    assert attached == {"a": "ground", "b": "ground"}
    for oid in ("a", "b"):
        assert np.allclose(out[oid], sequential[oid])
        assert objects[oid]["settled"] is False and objects[oid]["settle_remedy"] == "held"
        assert objects[oid]["joint_held"] == pytest.approx(1.0) and objects[oid]["certificate"]["remedy"] == "held"
        assert "joint_settle" not in objects[oid]  # the records of the sequential rest, marked
    assert objects["c"] == record
    assert len(lines) == 2 and "a (1.00 m)" in lines[0] and "b (1.00 m)" in lines[1]
    # off: the release's rest, whatever it threw
    attached, passes[:] = {}, []
    params = AssemblyParams.from_dict({"faithful": {"enabled": True, "reground": False, "hold_far": 0.0}})
    out = assemble._joint_stage(scene, order, {}, params, SimSettings(), tmp_path, None, attached, dict(sequential),
                                {o: {} for o in order}, {o: np.zeros(3) for o in order}, {}, {}, None)
    assert passes == [[]] and attached == {} and np.linalg.norm(out["a"][:3, 3] - sequential["a"][:3, 3]) == 1.0
