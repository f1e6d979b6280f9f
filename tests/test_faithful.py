"""Faithful grounding (phiscene.assembly.faithful) and pose metrics (phiscene.metrics.pose).

Oracles: box geometry (a face flush with a level table has a vertical normal),
statics (a centre of mass over the support stays on it), and closed-form
rigid motions for the pose metrics.
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
from phiscene.assembly.beneath import resting_on
from phiscene.assembly.certify import gross_failures
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.resting import closest_faces, flush_pose, resting_candidates, resting_normals, support_normal
from phiscene.assembly.starts import carried
from phiscene.meshes import save_mesh
from phiscene.metrics.pose import pose_metrics
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import decompose, make_pose

torch.set_num_threads(1)
SIM = SimSettings()
FAITHFUL = {"faithful": {"enabled": True}}
PHI_SCENE_SDF = {"optimizer": "steepest", "search_directions": 32, "rotate_over": 0.02}  # phi_scene's (config)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("faithful")
    fruit = trimesh.creation.icosphere(subdivisions=2, radius=0.04)
    fruit.apply_scale([1.0, 1.0, 0.9])
    meshes = {"table": trimesh.creation.box((0.8, 0.8, 0.1)), "box": trimesh.creation.box((0.1, 0.1, 0.1)),
              "block": trimesh.creation.box((0.2, 0.1, 0.05)), "plank": trimesh.creation.box((0.5, 0.05, 0.02)),
              "fruit": fruit, "slab": trimesh.creation.box((0.3, 0.3, 0.04)),
              "column": trimesh.creation.box((0.1, 0.1, 0.3)), "book": trimesh.creation.box((0.03, 0.15, 0.25)),
              "disc": trimesh.creation.cylinder(radius=0.08, height=0.02, sections=48)}
    return {"root": root, "cache": root / "cache",
            "meshes": {n: save_mesh(m, root / f"{n}.obj") for n, m in meshes.items()}}


def scene_of(work, placements):
    return box_scene(work["meshes"], placements)


def graph_of(scene, edges):
    es = [SupportEdge(a, b, rel) for a, b, rel in edges]
    return SupportGraph(objects=scene.ids, edges=es, order=scene.ids)


def run(work, scene, graph, params=FAITHFUL, attached=None):
    proxies = convex_proxies(scene, work["cache"])
    return ground_scene(scene, graph.order, proxies, AssemblyParams.from_dict(params), SIM, work["cache"],
                        graph=graph, attached=attached)


TABLE = make_pose(translation=(0, 0, 0.05))


def test_tilted_box_ends_flush_near_its_input(work):
    R = Rotation.from_euler("xy", [8, 3], degrees=True).as_matrix()
    half = 0.05
    lowest = half * (abs(R[2]).sum())  # lowest corner of the tilted cube touches the table top
    pose = make_pose(R, (0.1, -0.05, 0.1 + lowest))
    scene = scene_of(work, {"table": ("table", TABLE), "box": ("box", pose)})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "box", "supports")])
    out, rec = run(work, scene, g)
    Rb, tb, _ = decompose(out.get("box").pose)
    # some face normal of the cube is vertical within 0.5 deg
    tilt = min(math.degrees(math.acos(min(1.0, abs(Rb[2, k])))) for k in range(3))
    assert tilt < 0.5
    assert np.linalg.norm(tb - pose[:3, 3]) < 0.01
    cert = rec["objects"]["box"]["certificate"]
    assert cert["settled"] and cert["supporters_kept"] and "table" in cert["touching"]
    assert cert["joint_stable"]  # a flush box on a table stays put when the whole scene is released


def test_a_box_that_can_only_end_far_from_its_input_is_listed_as_a_gross_failure(work):
    """A box 1 m above the table top, nothing under it but the table: it can only drop 1 m (past onto_reach,
    0.3 m), and the summary lists it with what happened; the table, which stays, is not listed."""
    scene = scene_of(work, {"table": ("table", TABLE), "box": ("box", make_pose(translation=(0.0, 0.0, 1.15)))})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "box", "supports")])
    out, rec = run(work, scene, g)
    assert out.get("box").pose[2, 3] == pytest.approx(0.15, abs=2e-3)  # on the table top, 1 m lower
    assert set(rec["summary"]["gross"]) == {"box"}
    assert "moved 1.00 m" in rec["summary"]["gross"]["box"]


def test_gross_failure_is_past_the_stable_angle_or_the_onto_reach():
    fp = FaithfulParams(max_stable_angle=45.0, onto_reach=0.3)
    certs = {"kept": {"displacement": 0.29, "rotation_change": 44.0, "remedy": "none"},
             "flipped": {"displacement": 0.1, "rotation_change": 170.0, "remedy": "closest+joint"},
             "thrown": {"displacement": 0.31, "rotation_change": 2.0, "remedy": "closest"}}
    got = gross_failures(certs, fp)
    assert set(got) == {"flipped", "thrown"}
    assert got["flipped"] == "turned 170 deg and moved 0.10 m from its input (remedy closest+joint)"


def test_fruit_above_table_stays_and_settles(work):
    pose = make_pose(Rotation.from_euler("x", 4, degrees=True).as_matrix(), (0.2, 0.1, 0.1 + 0.036 + 0.005))
    scene = scene_of(work, {"table": ("table", TABLE), "fruit": ("fruit", pose)})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "fruit", "supports")])
    out, rec = run(work, scene, g)
    assert np.linalg.norm(out.get("fruit").pose[:3, 3] - pose[:3, 3]) < 0.01
    cert = rec["objects"]["fruit"]["certificate"]
    assert cert["settled"] and cert["supporters_kept"]


def test_block_off_the_edge_stays_on_its_parent(work):
    # block 0.2 long, its centre 2 cm inside the table edge (x = 0.4): the table carries it
    pose = make_pose(Rotation.from_euler("y", 6, degrees=True).as_matrix(), (0.38, 0.0, 0.1 + 0.025 + 0.012))
    scene = scene_of(work, {"table": ("table", TABLE), "block": ("block", pose)})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "block", "supports")])
    out, rec = run(work, scene, g)
    assert out.get("block").world_mesh().bounds[0, 2] > 0.09  # on the table top (0.1), not the floor
    cert = rec["objects"]["block"]["certificate"]
    assert cert["supporters_kept"] and cert["displacement"] < 0.03


def test_leaning_plank_keeps_both_supporters(work):
    # a plank at 14 deg: lower end on the ground, lower face resting on the box's top edge (x=-0.05, z=0.1),
    # 16.3 cm above its centre of mass along it: it leans (statics: with the edge below its centre of mass, as at
    # 30 deg, it tips onto the box top), held by the edge's push and the ground's friction (mu >= 0.33 with a
    # frictionless edge: moments about the lower end, then the forces; the world has 0.8)
    th = math.radians(14)
    L, T = 0.5, 0.02
    d = np.array([math.cos(th), 0.0, math.sin(th)])
    below = np.array([math.sin(th), 0.0, -math.cos(th)])  # lower-face normal
    edge = np.array([-0.05, 0.0, 0.1])
    s_contact = 0.1 / math.sin(th) - L / 2  # centre-to-contact distance along d for the lower corner at z = 0
    c = edge - T / 2 * below - s_contact * d + np.array([0, 0, 0.001])
    pose = make_pose(Rotation.from_euler("y", -14, degrees=True).as_matrix(), c)
    box_pose = make_pose(translation=(0.0, 0.0, 0.05))
    scene = scene_of(work, {"box": ("box", box_pose), "plank": ("plank", pose)})
    g = graph_of(scene, [("ground", "box", "supports"), ("ground", "plank", "supports"),
                         ("box", "plank", "leans_on")])
    _, rec = run(work, scene, g)
    cert = rec["objects"]["plank"]["certificate"]
    assert {"ground", "box"} <= set(cert["touching"]) and cert["supporters_kept"]
    assert cert["displacement"] < 0.03


def test_two_books_leaning_on_each_other_stand(work):
    """Two 25 cm books stand 20 deg off vertical, their tops against each other (an A-frame). Statics: each leans on
    the other's push, held by the floor's friction (mu >= tan(20 deg) / 2 = 0.18; the world has 0.8), so both stand
    where they are. The support graph cannot hold the cycle: one `leans_on` edge is dropped and the first book is
    placed alone. With what it leans on standing in at its input pose it rests there, leaning (not turned flush onto
    its base); without (the dropped edge forgotten) it is stood upright, 20 deg from the photo."""
    a = math.radians(20)
    corners = np.array([[x, y, z] for x in (-0.015, 0.015) for y in (-0.075, 0.075) for z in (-0.125, 0.125)])
    placements = {}
    for name, sign in (("left", 1.0), ("right", -1.0)):
        R = Rotation.from_euler("y", sign * a).as_matrix()
        c = corners @ R.T
        x = -c[:, 0].max() if sign > 0 else -c[:, 0].min()  # the top edge on the plane x = 0
        placements[name] = ("book", make_pose(R, (x, 0.0, -c[:, 2].min() + 0.001)))
    scene = scene_of(work, placements)
    edges = [("ground", "left", "supports"), ("ground", "right", "supports"), ("left", "right", "leans_on")]
    graph = SupportGraph(objects=scene.ids, edges=[SupportEdge(*e) for e in edges], order=["left", "right"],
                         dropped_edges=[SupportEdge("right", "left", "leans_on")])
    out, rec = run(work, scene, graph)
    assert rec["objects"]["left"]["stand_ins"] == ["right"]
    for name in ("left", "right"):
        cert = rec["objects"][name]["certificate"]
        assert cert["settled"] and cert["joint_stable"], name
        assert cert["displacement"] < 0.01 and cert["rotation_change"] < 2.0, (name, cert)
    forgotten = SupportGraph(objects=scene.ids, edges=graph.edges, order=graph.order)
    _, alone = run(work, scene, forgotten)
    assert alone["objects"]["left"]["certificate"]["rotation_change"] == pytest.approx(20.0, abs=1.0)


@pytest.mark.parametrize("lean", [True, False])
def test_book_short_of_its_wall_is_moved_onto_it_not_turned(work, lean):
    # a 25 cm book standing on the floor at 20 deg off vertical, its top towards the wall x = 0.5 and 5 cm short of
    # it (a depth error). Leaning as put, it stands (statics: friction mu >= tan(20 deg) / 2 = 0.18 at the floor;
    # the world has 0.8). Released where put, it turns about its bottom edge until its top reaches the wall, to
    # asin((0.25 sin 20 deg + 0.05) / 0.25) = 32.8 deg off vertical, 12.8 deg more than the input (> max_turn, 10).
    # Moved 5 cm onto the wall (remedy lean) it keeps the input's orientation.
    from phiscene.scene import Plane

    R = Rotation.from_euler("y", 20, degrees=True).as_matrix()
    corners = np.array([[x, y, z] for x in (-0.015, 0.015) for y in (-0.075, 0.075) for z in (-0.125, 0.125)]) @ R.T
    pose = make_pose(R, (0.5 - corners[:, 0].max() - 0.05, 0.0, -corners[:, 2].min() + 0.001))
    scene = scene_of(work, {"book": ("book", pose)})
    scene.structure.append(Plane("wall_0", "wall", (-1.0, 0.0, 0.0), 0.5))
    g = graph_of(scene, [("ground", "book", "supports"), ("wall_0", "book", "leans_on")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "lean": lean}})
    cert = rec["objects"]["book"]["certificate"]
    assert "none: moved" in cert["reason"]  # released where put, it turned past max_turn
    if not lean:  # no other start keeps it on the wall in the input's orientation
        assert not (cert["supporters_kept"] and cert["rotation_change"] < 1.0)
        return
    assert cert["settled"] and {"ground", "wall_0"} <= set(cert["touching"])
    assert cert["remedy"].startswith("lean") and cert["supporters_kept"]
    assert cert["rotation_change"] < 1.0
    assert rec["objects"]["book"]["lean_shift"][0] == pytest.approx(0.05, abs=0.005)  # the gap, towards the wall


@pytest.mark.parametrize("max_shift", [0.09, 0.0])
def test_column_straddling_a_step_is_shifted_to_stand(work, max_shift):
    # a 0.3 m column whose base (0.1 wide) straddles the edge of a 4 cm slab (edge at x = 0.15), its centre of mass
    # 1 cm beyond the edge: it tips over off the step. Shifted 3 cm back it stands on the slab: its centre of mass
    # 2 cm inside the edge, 15 cm up, so it holds up to atan(2/15) = 7.6 deg of tilt (> the 4 deg tilt test).
    slab = make_pose(translation=(0.0, 0.0, 0.02))
    pose = make_pose(translation=(0.16, 0.0, 0.04 + 0.15 + 0.001))
    scene = scene_of(work, {"slab": ("slab", slab), "column": ("column", pose)})
    g = graph_of(scene, [("ground", "slab", "supports"), ("slab", "column", "supports"),
                         ("ground", "column", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "max_shift": max_shift, "onto_reach": 0}})
    R, t, _ = decompose(out.get("column").pose)
    upright = math.degrees(math.acos(min(1.0, R[2, 2])))
    cert = rec["objects"]["column"]["certificate"]
    if max_shift == 0:  # without the remedy it topples: the guarded settling alone cannot keep it standing
        assert upright > 45
        return
    assert cert["remedy"].startswith("shifted") and cert["settled"] and cert["supporters_kept"]
    assert upright < 1.0
    assert np.linalg.norm(t[:2] - pose[:2, 3]) <= max_shift + 1e-6
    assert t[0] < 0.15  # its centre of mass over the slab it stands on
    assert cert["joint_stable"]


@pytest.mark.parametrize("max_shift", [0.09, 0.0])
def test_block_tipping_off_an_edge_without_going_far_is_shifted_back_flat(work, max_shift):
    # the 0.2 m block lies on the 0.1 m box (top at z = 0.1, edge at x = 0.05) with its centre of mass 2 cm beyond
    # the edge: it tips over the edge and comes to rest leaning from it to the floor, turned well past max_turn but
    # its centre of mass moved less than max_shift. Shifted back by the slide bound (3 cm) its centre of mass lies
    # 1 cm inside the edge, 2.5 cm up: it lies flat and holds up to atan(1/2.5) = 22 deg of tilt.
    pose = make_pose(translation=(0.07, 0.0, 0.1 + 0.025 + 0.001))
    scene = scene_of(work, {"box": ("box", make_pose(translation=(0.0, 0.0, 0.05))), "block": ("block", pose)})
    g = graph_of(scene, [("ground", "box", "supports"), ("box", "block", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "max_shift": max_shift, "onto_reach": 0}})
    R, t, _ = decompose(out.get("block").pose)
    tilt = math.degrees(math.acos(min(1.0, R[2, 2])))
    cert = rec["objects"]["block"]["certificate"]
    if max_shift == 0:  # without the remedy: it tips, yet moves less than a shift, so it is kept as the closest
        assert cert["remedy"] == "closest" and tilt > 10.0
        assert np.linalg.norm(t - pose[:3, 3]) < 0.09
        return
    assert cert["remedy"].startswith("shifted") and cert["settled"] and cert["supporters_kept"]
    assert tilt < 1.0
    assert out.get("block").world_mesh().bounds[0, 2] == pytest.approx(0.1, abs=0.003)  # flat on the box
    assert t[0] < 0.05 and np.linalg.norm(t[:2] - pose[:2, 3]) <= max_shift + 1e-6


def joint_settle_then(assemble, edit):
    """The real ``_joint_settle``, then ``edit(records)`` on the records it updated (a stand-in for what the release
    did: an object it knocked over)."""
    real = assemble._joint_settle

    def released(scene_, proxies, sim, cache_dir, fp, sp, objects_, coms, inputs):
        poses = real(scene_, proxies, sim, cache_dir, fp, sp, objects_, coms, inputs)
        edit(objects_)
        return poses

    return released


def toppled_box(work):
    """A box put on the table 2 mm above its top, that releasing the whole scene left on its side on the floor
    beside the table (its record says so): its input pose, the scene, graph, faithful params, the toppled pose and
    the records."""
    pose = make_pose(translation=(0.1, -0.05, 0.1 + 0.05 + 0.002))
    scene = scene_of(work, {"table": ("table", TABLE), "box": ("box", pose)})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "box", "supports")])
    toppled = make_pose(Rotation.from_euler("y", 90, degrees=True).as_matrix(), (0.5, -0.05, 0.05))
    objects = {"table": {"joint_settle": [0.0, 0.0]},
               "box": {"joint_settle": [0.4, 90.0], "certificate": {"remedy": "none", "touching": ["ground"]}}}
    return pose, scene, g, AssemblyParams.from_dict(FAITHFUL), toppled, objects


def test_an_object_the_joint_release_toppled_is_grounded_again_on_its_supporter(work):
    # the box stood on the table; releasing the whole scene left it on its side on the floor beside the table (its
    # record says so). Grounded again from its input on the table as it rests, it stands flush on the table top
    # within 1 cm of where it was put, and that pose replaces the toppled one
    from phiscene.assembly.assemble import _collapsed, _reground_collapsed

    pose, scene, g, params, toppled, objects = toppled_box(work)
    assert _collapsed(objects["box"], params.faithful) and not _collapsed(objects["table"], params.faithful)
    poses = _reground_collapsed(scene, g.order, convex_proxies(scene, work["cache"]), params, SIM, work["cache"], g,
                                {}, {"table": TABLE, "box": toppled}, objects,
                                {"table": np.zeros(3), "box": np.zeros(3)}, {}, {}, None)
    R, t, _ = decompose(poses["box"])
    assert objects["box"]["reground"]["kept"] and objects["box"]["certificate"]["remedy"] == "none+reground"
    assert min(math.degrees(math.acos(min(1.0, abs(R[2, k])))) for k in range(3)) < 0.5
    assert np.linalg.norm(t - pose[:3, 3]) < 0.01
    assert objects["box"]["joint_settle"][0] < 1e-3  # at rest when the scene is released again
    np.testing.assert_allclose(poses["table"], TABLE, atol=1e-4)


@pytest.mark.parametrize("extensions", [2, 0])
def test_joint_settling_cut_off_while_an_object_falls_goes_on(work, monkeypatch, extensions):
    # joint settling capped at 20 frames (1/3 s) releases a box 1 m above the table top: it has fallen
    # g t^2 / 2 = 54.5 cm when the cap is reached, still falling; released on, it lands on the table top and the
    # settling ends at rest there. Without the extensions it is left in mid-air
    from phiscene.assembly import assemble

    monkeypatch.setattr(assemble, "JOINT_EXTENSIONS", extensions)
    pose = make_pose(translation=(0.1, -0.05, 0.1 + 0.05 + 1.0))
    scene = scene_of(work, {"table": ("table", TABLE), "box": ("box", pose)})
    fp = AssemblyParams.from_dict({"faithful": {"enabled": True, "joint_settle_frames": 20}})
    objects = {"table": {}, "box": {"certificate": {"remedy": "none"}}}
    poses = assemble._joint_settle(scene, convex_proxies(scene, work["cache"]), SIM, work["cache"], fp.faithful,
                                   fp.settle_params, objects, {"table": np.zeros(3), "box": np.zeros(3)},
                                   {"table": TABLE, "box": pose})
    fallen = pose[2, 3] - poses["box"][2, 3]
    if extensions == 0:
        assert fallen == pytest.approx(0.5 * 9.81 * (20 / 60) ** 2, abs=0.01)
        return
    assert fallen == pytest.approx(1.0, abs=3e-3)  # on the table top
    assert objects["box"]["joint_settle"][0] == pytest.approx(np.linalg.norm(poses["box"][:3, 3] - pose[:3, 3]),
                                                              abs=1e-6)  # from where it was released first
    assert objects["box"]["certificate"]["remedy"] == "none+joint"
    np.testing.assert_allclose(poses["table"], TABLE, atol=1e-4)


def test_regrounding_that_brings_the_scene_down_when_released_together_is_undone(work, monkeypatch):
    # the same toppled box, grounded again on the table (kept: closer to its input); this time the last joint
    # release of the scene knocks the table over (stood in for: the release reports it turned 90 deg). The
    # regrounded pose is undone: the poses, records, centres of mass and bases are those of the first joint rest
    # again, and the box's reground record says it was not kept and what collapsed
    import copy

    from phiscene.assembly import assemble

    pose, scene, g, params, toppled, objects = toppled_box(work)
    first = {"table": TABLE, "box": toppled}
    masses, bases = {"table": np.array([0.0, 0.0, 0.01])}, {}
    before = copy.deepcopy((objects, masses, bases))
    real = assemble._joint_settle
    released = []

    def knocked_over(scene_, proxies, sim, cache_dir, fp, sp, objects_, coms, inputs):
        poses = real(scene_, proxies, sim, cache_dir, fp, sp, objects_, coms, inputs)
        released.append(poses["box"])
        objects_["table"]["joint_settle"] = [0.3, 90.0]
        return poses

    monkeypatch.setattr(assemble, "_joint_settle", knocked_over)
    poses = assemble._reground_collapsed(scene, g.order, convex_proxies(scene, work["cache"]), params, SIM,
                                         work["cache"], g, {}, dict(first), objects,
                                         {"table": np.zeros(3), "box": np.zeros(3)}, masses, bases, None)
    assert len(released) == 1  # the box was grounded again and kept, and the scene released with it
    assert np.linalg.norm(released[0][:3, 3] - pose[:3, 3]) < 0.01
    assert set(poses) == set(first) and all(np.array_equal(poses[k], first[k]) for k in first)
    reground = objects["box"].pop("reground")
    assert not reground["kept"] and reground["undone"] == ["table"] and reground["remedy"]
    assert objects == before[0] and masses.keys() == before[1].keys() and bases == before[2]
    np.testing.assert_array_equal(masses["table"], before[1]["table"])


@pytest.mark.parametrize("first_far", [0.4, 0.0])
def test_regrounding_kept_when_only_what_fell_before_falls_again_nearer_its_input(work, monkeypatch, first_far):
    # the toppled box (first fell 0.4 m from its input) is grounded again on the table; the last release is made to
    # report that the box itself moved again (stood in for: 0.1 m, 50 deg), nothing else. Nothing that had held
    # broke, and the box lies nearer its input than where it first fell: the regrounded rest is kept. Had it first
    # fallen nowhere (0 m), the regrounded rest would not be nearer, and it is undone as before
    from phiscene.assembly import assemble

    pose, scene, g, params, toppled, objects = toppled_box(work)
    objects["box"]["displacement"] = first_far
    monkeypatch.setattr(assemble, "_joint_settle",
                        joint_settle_then(assemble, lambda recs: recs["box"].update(joint_settle=[0.1, 50.0])))
    poses = assemble._reground_collapsed(scene, g.order, convex_proxies(scene, work["cache"]), params, SIM,
                                         work["cache"], g, {}, {"table": TABLE, "box": toppled}, objects,
                                         {"table": np.zeros(3), "box": np.zeros(3)}, {}, {}, None)
    if first_far == 0.0:
        assert not objects["box"]["reground"]["kept"] and objects["box"]["reground"]["undone"] == ["box"]
        np.testing.assert_array_equal(poses["box"], toppled)
        return
    assert objects["box"]["reground"]["kept"] and "undone" not in objects["box"]["reground"]
    assert objects["box"]["displacement"] < first_far
    assert np.linalg.norm(poses["box"][:3, 3] - pose[:3, 3]) < 0.01  # on the table top where it was put


def test_an_object_the_joint_release_pushed_through_the_floor_is_grounded_again(work, monkeypatch):
    # the first joint release left the box upright beside the table, 3 cm into the floor: it neither toppled nor
    # moved past reground_move, but its collision shape reaches below the ground deeper than contact_tol (and would
    # drop every object of the drift test with it). It is grounded again from its input, on the table top. Then the
    # last release is made to report the table knocked over (stood in for): that would undo the regrounding, but not
    # back to a rest with the box through the floor; the regrounded rest is kept
    from phiscene.assembly import assemble

    pose, scene, g, params, _, objects = toppled_box(work)
    sunk = make_pose(translation=(0.4, -0.05, 0.05 - 0.03))
    objects["box"]["joint_settle"] = [0.05, 0.0]
    proxies = convex_proxies(scene, work["cache"])
    free = ["table", "box"]
    assert not assemble._collapsed(objects["box"], params.faithful)
    first = {"table": TABLE, "box": sunk}
    assert assemble._sunk(scene, first, proxies, {}, free, params.faithful.contact_tol) == {"box"}
    assert assemble._sunk(scene, first, proxies, {}, free, 0.031) == set()
    monkeypatch.setattr(assemble, "_joint_settle",
                        joint_settle_then(assemble, lambda recs: recs["table"].update(joint_settle=[0.3, 90.0])))
    poses = assemble._reground_collapsed(scene, g.order, proxies, params, SIM, work["cache"], g, {},
                                         {"table": TABLE, "box": sunk}, objects,
                                         {"table": np.zeros(3), "box": np.zeros(3)}, {}, {}, None)
    assert objects["box"]["reground"]["kept"] and "undone" not in objects["box"]["reground"]
    assert np.linalg.norm(poses["box"][:3, 3] - pose[:3, 3]) < 0.01  # on the table top where it was put
    assert assemble._sunk(scene, poses, proxies, {}, free, params.faithful.contact_tol) == set()


@pytest.mark.parametrize("onto_reach", [0.3, 0.0])
def test_column_balanced_on_an_edge_is_moved_inside_it(work, onto_reach):
    # the 0.3 m column stands on the slab with its centre of mass 4 mm inside the edge (x = 0.15): it settles, but
    # it would topple at a tilt of atan(4/150) = 1.5 deg, less than the 4 deg tilt test (marginal). With the remedy
    # onto it is moved inside the edge and stands with a margin of more than 150 tan(4 deg) = 10.5 mm.
    slab = make_pose(translation=(0.0, 0.0, 0.02))
    pose = make_pose(translation=(0.146, 0.0, 0.04 + 0.15 + 0.001))
    scene = scene_of(work, {"slab": ("slab", slab), "column": ("column", pose)})
    g = graph_of(scene, [("ground", "slab", "supports"), ("slab", "column", "supports")])
    params = {"faithful": {"enabled": True, "max_shift": 0.0, "onto_reach": onto_reach}}
    out, rec = run(work, scene, g, params=params)
    R, t, _ = decompose(out.get("column").pose)
    cert = rec["objects"]["column"]["certificate"]
    if onto_reach == 0:  # nothing else moves it: the closest result, which only balances there
        assert cert["remedy"] == "closest" and "marginal" in cert["reason"]
        return
    assert cert["remedy"].startswith("onto") and cert["settled"] and cert["supporters_kept"]
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) < 1.0  # standing
    assert t[0] < 0.15 - 0.15 * math.tan(math.radians(4.0))  # inside the edge by the tilt test's margin
    assert out.get("column").world_mesh().bounds[0, 2] == pytest.approx(0.04, abs=0.003)  # on the slab
    assert np.linalg.norm(t[:2] - pose[:2, 3]) <= onto_reach


@pytest.mark.parametrize("reach", [0.1, 0.0])
def test_post_under_a_table_top_edge_is_pushed_out_sideways_and_stands(work, reach):
    # a table (a slab 30-34 cm up on a pedestal); a 30 cm post standing on the floor 2 cm up (a depth error) reaches
    # 2 cm up into the slab and 2 cm in under its edge (x = 0.15): the graph puts it on the floor alone
    scene = scene_of(work, {"pedestal": ("column", make_pose(translation=(0.0, 0.0, 0.15))),
                            "slab": ("slab", make_pose(translation=(0.0, 0.0, 0.32))),
                            "post": ("column", make_pose(translation=(0.18, 0.0, 0.02 + 0.15)))})
    g = graph_of(scene, [("ground", "pedestal", "supports"), ("pedestal", "slab", "supports"),
                         ("ground", "post", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "planar_floor": reach},
                                           "penetration_params": {"optimizer": "steepest"}})  # as phi_scene
    post = rec["objects"]["post"]
    # planar when its bottom (2 cm) is within reach of the floor; the table, on the pedestal, never is
    assert post["sdf_planar"] is (reach > 0) and rec["objects"]["slab"]["sdf_planar"] is False
    if reach == 0:
        return
    assert post["sdf_translation"][2] == 0.0 and post["sdf_final_loss"] == 0.0
    # out from under the slab's edge (where the slab rests) by eps, within a solver step; then lowered onto the
    # floor: upright, beside the slab
    eps, lr = AssemblyParams().penetration_params.eps, AssemblyParams().penetration_params.lr
    edge = out.get("slab").world_mesh().bounds[1, 0]
    assert edge + eps - 1e-3 <= 0.13 + post["sdf_translation"][0] <= edge + eps + lr
    R, t, _ = decompose(out.get("post").pose)
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) < 1.0
    assert out.get("post").world_mesh().bounds[0, 2] == pytest.approx(0.0, abs=0.003)
    assert out.get("post").world_mesh().bounds[0, 0] >= edge - 1e-3  # beside the slab, not under it
    assert post["certificate"]["joint_stable"] and rec["objects"]["slab"]["certificate"]["joint_stable"]


@pytest.mark.parametrize(("bottom", "lift", "lifted"), [(0.04, 0.5, True), (0.04, 0.0, False), (0.0, 0.5, False)])
def test_a_box_sunk_into_a_plinth_near_the_floor_is_lifted_onto_it_not_slid_out(work, bottom, lift, lifted):
    # a plinth (80 x 80 x 10 cm) on the floor; a 10 cm box sunk into it, its bottom `bottom` above the floor, 10 cm
    # from the plinth's centre (a depth error), which the graph puts on the floor alone: out sideways is 35 cm, up
    # onto the plinth 10 cm - bottom + eps; a lift longer than max_shift (9 cm) is not taken
    scene = scene_of(work, {"plinth": ("table", TABLE),
                            "box": ("box", make_pose(translation=(0.1, 0.0, bottom + 0.05)))})
    g = graph_of(scene, [("ground", "plinth", "supports"), ("ground", "box", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "floor_lift": lift},
                                           "penetration_params": PHI_SCENE_SDF})
    box = rec["objects"]["box"]
    assert box["certificate"]["settled"]
    lo, hi = out.get("box").world_mesh().bounds
    if not lifted:  # pushed across the floor out of the plinth's side (x = 0.4), by eps within a solver step
        assert box["sdf_planar"] and "sdf_lifted" not in box and lo[2] == pytest.approx(0.0, abs=0.003)
        assert lo[0] >= 0.4 - 1e-3
        return
    assert not box["sdf_planar"] and box["sdf_lifted"]["onto"] == ["plinth"]
    eps = AssemblyParams().penetration_params.eps
    assert box["sdf_translation"][2] == pytest.approx(0.1 - bottom + eps, abs=0.002)  # straight up, clear by eps
    assert box["certificate"]["supporters"] == ["plinth"]
    assert box["certificate"]["supporters_kept"] and box["certificate"]["remedy"] == "none"
    assert lo[2] == pytest.approx(0.1, abs=0.003)  # on the plinth's top
    assert np.linalg.norm((lo + hi)[:2] / 2 - [0.1, 0.0]) < 0.01  # where it was put


def test_a_box_through_a_coarse_grid_shelf_board_is_lifted_onto_the_board(tmp_path):
    """A floor shelf (1 m wide, 60 cm tall, 1.5 cm boards; its bottom board's top 5.75 cm above the floor) whose SDF
    grid is coarse (16 points along its width: error up to 4 cm, more than eps + contact_tol); a 10 cm box read as
    on the floor alone, sunk 2.75 cm through the bottom board (its bottom under the board's underside). Out
    sideways along the floor is 20 cm; up onto the board 2.75 cm + eps. The lift stops where the coarse grid reads
    it clear, and the box is taken as resting on the board within the grid's error: it ends on the board where it
    was put."""
    from phiscene.proxies import Proxy

    t = 0.015
    parts = [trimesh.creation.box((1.0, 0.3, t)).apply_translation((0, 0, 0.05)),
             trimesh.creation.box((t, 0.3, 0.6)).apply_translation((-0.5, 0, 0.3)),
             trimesh.creation.box((t, 0.3, 0.6)).apply_translation((0.5, 0, 0.3)),
             trimesh.creation.box((1.0, 0.3, t)).apply_translation((0, 0, 0.6 - t / 2))]
    meshes = {"shelf": save_mesh(trimesh.util.concatenate(parts), tmp_path / "shelf.obj"),
              "box": save_mesh(trimesh.creation.box((0.1, 0.1, 0.1)), tmp_path / "box.obj")}
    top = 0.05 + t / 2
    scene = box_scene(meshes, {"shelf": ("shelf", make_pose()),
                               "box": ("box", make_pose(translation=(0.1, 0.0, top - 0.0275 + 0.05)))})
    g = graph_of(scene, [("ground", "shelf", "supports"), ("ground", "box", "supports")])
    proxies = convex_proxies(scene, tmp_path / "cache")
    proxies["shelf"] = Proxy(hulls=[np.asarray(p.vertices) for p in parts], volume_ratio=1.0, max_outside=0.0)
    params = AssemblyParams.from_dict({"faithful": {"enabled": True},
                                       "penetration_params": {**PHI_SCENE_SDF, "grid": {"resolution": 16}}})
    out, rec = ground_scene(scene, g.order, proxies, params, SIM, tmp_path / "cache", graph=g)
    box, shelf = rec["objects"]["box"], rec["objects"]["shelf"]
    assert shelf["sdf_grid_error"] > params.penetration_params.eps + params.faithful.contact_tol
    assert box["sdf_lifted"]["onto"] == ["shelf"] and box["certificate"]["supporters"] == ["shelf"]
    lo, hi = out.get("box").world_mesh().bounds
    assert lo[2] == pytest.approx(top, abs=0.003) and np.linalg.norm((lo + hi)[:2] / 2 - [0.1, 0.0]) < 0.01
    assert box["certificate"]["settled"] and box["certificate"]["remedy"] == "none"


def test_a_block_sunk_into_a_round_plate_is_lifted_onto_it_though_its_corners_overhang(work):
    # a round plate (16 cm across, 2 cm high) on the floor; a 20 x 10 x 5 cm block sunk into it down to the floor,
    # centred on it, which the graph puts on the floor alone. Its corners (11.2 cm from the centre) overhang the
    # plate: only its bottom's middle rests on it. Out sideways is 13 cm, up onto the plate 2 cm + eps
    scene = scene_of(work, {"plate": ("disc", make_pose(translation=(0.0, 0.0, 0.01))),
                            "block": ("block", make_pose(translation=(0.0, 0.0, 0.025)))})
    g = graph_of(scene, [("ground", "plate", "supports"), ("ground", "block", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True}, "penetration_params": PHI_SCENE_SDF})
    block = rec["objects"]["block"]
    assert block["sdf_lifted"]["onto"] == ["plate"]
    eps = AssemblyParams().penetration_params.eps
    assert block["sdf_translation"][2] == pytest.approx(0.02 + eps, abs=0.002)  # straight up, clear by eps
    assert block["certificate"]["supporters"] == ["plate"] and block["certificate"]["settled"]
    lo, hi = out.get("block").world_mesh().bounds
    assert lo[2] == pytest.approx(0.02, abs=0.003)  # on the plate's top
    assert np.linalg.norm((lo + hi)[:2] / 2) < 0.01  # where it was put


@pytest.mark.parametrize(("height", "x", "found"), [(0.105, 0.0, ["plinth"]), (0.12, 0.0, []), (0.105, 0.44, [])])
def test_resting_on_is_the_surface_within_tol_under_the_lowest_points_and_the_centre(height, x, found):
    # a plinth's top at z = 0.1, from x = -0.4 to 0.4; a 10 cm square of points `height` up, centred at `x`
    plinth = trimesh.creation.box((0.8, 0.8, 0.1))
    plinth.apply_translation((0.0, 0.0, 0.05))
    g = np.linspace(-0.05, 0.05, 5)
    pts = np.array([(x + a, b, height) for a in g for b in g] + [(x, 0.0, height + 0.1)])
    com = np.array([x, 0.0, height + 0.05])
    # 5 mm above the top is within 9 mm; 2 cm is not; half over the edge with the centre beyond it does not rest
    assert resting_on(pts, com, {"plinth": plinth}, 0.0, 0.009) == found


def test_paper_loop_unchanged_without_faithful(work):
    pose = make_pose(translation=(0.0, 0.0, 0.2))
    scene = scene_of(work, {"box": ("box", pose)})
    g = graph_of(scene, [("ground", "box", "supports")])
    out, rec = run(work, scene, g, params={})
    assert "certificate" not in rec["objects"]["box"]
    assert abs(out.get("box").world_mesh().bounds[0, 2]) < 0.01  # fell to the ground


def test_flush_pose_is_the_smallest_rotation():
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    normals = resting_normals(box.vertices)
    assert len(normals) == 6
    R = Rotation.from_euler("xz", [7, 30], degrees=True).as_matrix()
    pose = make_pose(R, (1.0, 2.0, 3.0))
    out, angle = flush_pose(pose, normals, np.zeros(3), np.array([0.0, 0.0, 1.0]), 20.0)
    assert angle == pytest.approx(7.0, abs=1e-6)
    Ro, to, _ = decompose(out)
    assert abs(Ro[2, 2]) == pytest.approx(1.0, abs=1e-9)  # bottom face level
    assert np.allclose(to, pose[:3, 3])  # rotated about the centre
    # yaw kept: the x axis stays at 30 deg azimuth
    assert math.degrees(math.atan2(Ro[1, 0], Ro[0, 0])) == pytest.approx(30.0, abs=1e-6)
    same, a = flush_pose(pose, normals, np.zeros(3), np.array([0.0, 0.0, 1.0]), 5.0)
    assert a == 0.0 and np.array_equal(same, pose)


def test_resting_candidates_are_every_facet_within_the_angle_nearest_first():
    # a 1 x 2 x 3 box tilted 30 deg about x rests on its -z face (30 deg away) or its -y face (60 deg away)
    normals = resting_normals(trimesh.creation.box((1.0, 2.0, 3.0)).vertices)
    pose = make_pose(Rotation.from_euler("x", 30, degrees=True).as_matrix(), (0.0, 0.0, 1.0))
    up = np.array([0.0, 0.0, 1.0])
    found = resting_candidates(pose, normals, np.zeros(3), up, 70.0)
    assert [round(a, 6) for _, a in found] == [30.0, 60.0]
    for out, _ in found:
        R, t, _ = decompose(out)
        assert min(abs(abs(R[2, k]) - 1.0) for k in range(3)) < 1e-9  # a face is level
        assert np.allclose(t, pose[:3, 3])
    assert len(resting_candidates(pose, normals, np.zeros(3), up, 45.0)) == 1


def test_resting_facets_are_those_the_centre_of_mass_projects_into():
    # a prism over the obtuse triangle A (0, 0), B (1, 0), C (0.9, 0.1), 0.5 long along z: the centroid
    # (0.633, 0.033) projects inside AB and AC but beyond B on BC, so it rests on AB, AC and both ends, never on BC
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.9, 0.1]])
    points = np.vstack([np.c_[tri, np.zeros(3)], np.c_[tri, np.full(3, 0.5)]])
    normals = {tuple(np.round(n, 6)) for n in resting_normals(points)}
    ac = np.array([-0.1, 0.9, 0.0]) / np.hypot(0.1, 0.9)  # outward normals (away from the third corner)
    bc = np.array([0.1, 0.1, 0.0]) / np.hypot(0.1, 0.1)
    want = {tuple(np.round(n, 6)) for n in ([0.0, -1.0, 0.0], ac, [0.0, 0.0, 1.0], [0.0, 0.0, -1.0])}
    assert normals == want and tuple(np.round(bc, 6)) not in normals
    # a declared centre of mass moved near C makes BC a resting face too (its projection is now inside BC)
    with_c = {tuple(np.round(n, 6)) for n in resting_normals(points, np.array([0.93, 0.05, 0.25]))}
    assert tuple(np.round(bc, 6)) in with_c


def test_resting_facets_match_trimesh_stable_poses():
    # the reference: trimesh's stable poses (threshold 0: every pose it can rest in) of a random hull, which
    # resting_normals finds without its toppling graph
    rng = np.random.default_rng(3)
    points = rng.normal(size=(60, 3)) * [0.3, 0.2, 0.1]
    hull = trimesh.convex.convex_hull(points)
    transforms, _ = trimesh.poses.compute_stable_poses(hull, n_samples=1, threshold=0.0)
    ref = {tuple(np.around(T[:3, :3].T @ [0.0, 0.0, -1.0], 3)) for T in transforms}
    assert len(ref) >= 3
    assert {tuple(np.around(n, 3)) for n in resting_normals(points)} == ref


def test_carried_follows_the_supporter_point_beneath_without_turning():
    # the supporter turns 90 deg about z around its centre (0, 0, 0.5) and moves 0.1 m along x;
    # the object's centre of mass sits 0.2 m along x from that centre
    before = make_pose(translation=(0.0, 0.0, 0.5))
    after = make_pose(Rotation.from_euler("z", 90, degrees=True).as_matrix(), (0.1, 0.0, 0.5))
    R = Rotation.from_euler("y", 5, degrees=True).as_matrix()
    pose = make_pose(R, (0.2, 0.0, 1.0))
    out = carried(pose, np.zeros(3), before, after)
    assert np.allclose(out[:3, 3], (0.1, 0.2, 1.0))  # (0.2, 0, 0.5) turned to (0, 0.2, 0.5), then + (0.1, 0, 0)
    assert np.allclose(out[:3, :3], R)


@pytest.mark.parametrize("inside, holds", [(0.03, True), (0.001, False)])
def test_tilt_test_tells_a_resting_box_from_one_balanced_on_the_edge(tmp_path, inside, holds):
    """Statics: a box resting on a table edge stays under gravity tilted by d when its centre of mass is more
    than h tan d inside the edge (h = 0.1 m, d = 4 deg: 7 mm, less Bullet's rolling friction of 3 mm); at 1 mm
    inside it has settled too, but tips. Ended early (at rest, or past the tolerance), the test gives the same
    answer in fewer frames."""
    from phiscene.assembly.settle import SettleParams, holds_when_tilted, settle_object
    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld

    box = trimesh.creation.box((0.1, 0.1, 0.2))
    table = trimesh.creation.box((0.4, 0.4, 0.1))
    with BulletWorld(SIM, tmp_path) as world:
        world.add_ground(0.0)
        world.add_body("table", [np.asarray(table.vertices)], make_pose(translation=(0, 0, 0.05)), None)
        world.set_static("table")
        hulls = [np.asarray(box.vertices)]
        world.add_body("box", hulls, make_pose(translation=(0.2 - inside, 0, 0.2005)),
                       rigid_props(box, hulls, SIM.density, 1.0))
        assert settle_object(world, "box", SettleParams()).settled
        before = world.pose("box")
        held, frames = holds_when_tilted(world, "box", 4.0, 60, 0.005, 1.0)
        assert held is holds
        assert np.allclose(world.pose("box"), before)  # put back
        early, fewer = holds_when_tilted(world, "box", 4.0, 60, 0.005, 1.0, SettleParams())
        assert early is holds
        assert np.allclose(world.pose("box"), before)
        assert fewer < frames
        assert frames == (4 * 60 if holds else 60)


@pytest.mark.parametrize("load_x, gives", [(0.05, True), (-0.05, False)])
def test_a_carrier_over_a_shelf_edge_gives_way_under_a_load_beyond_the_edge(tmp_path, load_x, gives):
    """Statics: a 0.2 m plank lies on a static shelf with its centre 2 cm inside the edge (x = 0), so alone it
    stays; a box of three times its mass rests on it 5 cm beyond the edge: the pair's centre of mass is
    (3 * 0.05 - 0.02) / 4 = 3.3 cm beyond the edge, and the plank tips when released under the box. The same box
    5 cm inside the edge: the pair's centre is 4.3 cm inside, it holds. Frozen, the plank holds the box either way."""
    from phiscene.assembly.settle import SettleParams, gives_way, settle_object
    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld

    shelf, plank, load = (trimesh.creation.box(e) for e in ((0.4, 0.4, 0.1), (0.2, 0.1, 0.02), (0.1, 0.1, 0.12)))
    with BulletWorld(SIM, tmp_path) as world:
        world.add_ground(-1.0)
        world.add_body("shelf", [np.asarray(shelf.vertices)], make_pose(translation=(-0.2, 0, 0.05)), None)
        hulls = {"plank": [np.asarray(plank.vertices)], "load": [np.asarray(load.vertices)]}
        props = {k: rigid_props(m, hulls[k], SIM.density, 1.0) for k, m in (("plank", plank), ("load", load))}
        assert props["load"].mass == pytest.approx(3 * props["plank"].mass, rel=0.01)
        world.add_body("plank", hulls["plank"], make_pose(translation=(-0.02, 0, 0.1105)), props["plank"])
        assert settle_object(world, "plank", SettleParams()).settled
        world.set_static("plank")
        world.add_body("load", hulls["load"], make_pose(translation=(load_x, 0, 0.121 + 0.06 + 0.0005)),
                       props["load"])
        assert settle_object(world, "load", SettleParams()).settled  # on the frozen plank it rests
        before = {b: world.pose(b) for b in ("plank", "load")}
        moved, frames = gives_way(world, "load", ["plank"], 60, 0.005, 1.0)
        assert bool(moved) is gives and (not gives or "plank" in moved) and frames == 60
        for b, pose in before.items():  # put back, the plank frozen again
            np.testing.assert_allclose(world.pose(b), pose, atol=1e-9)
        assert not world.bodies["plank"].dynamic
        # ended once everything is at rest: the same answer; a pair that holds comes to rest well before 60 frames
        early, fewer = gives_way(world, "load", ["plank"], 60, 0.005, 1.0, SettleParams())
        assert early == moved and (fewer < 60 if not gives else fewer <= 60)


@pytest.mark.parametrize("depth, gives", [(1, False), (2, True)])
def test_a_stack_that_tips_at_its_base_is_seen_two_levels_down(tmp_path, depth, gives):
    """Statics, per unit density and depth 0.1 m: a plank P (0.2 x 0.02, mass 4) lies on a static shelf whose edge
    is x = 0, its centre at x = -0.02; a board B (0.12 x 0.02, mass 2.4) on it at x = 0.01 (P and B: centre
    (-0.08 + 0.024) / 6.4 = -0.9 cm, inside: they stay); a box L (0.06 x 0.06, mass 3.6) on B at x = 0.05. On a
    frozen P, B and L hold (their centre, 3.4 cm, lies over P, which reaches 8 cm); released together the three
    have their centre at (-0.08 + 0.024 + 0.18) / 10 = +1.24 cm, beyond the edge: P tips. The load test sees it
    only when it releases B's supporter P too (depth 2); the carriers are B, then P, never the static shelf."""
    from phiscene.assembly.settle import SettleParams, gives_way, load_carriers, settle_object
    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld

    sizes = {"P": (0.2, 0.1, 0.02), "B": (0.12, 0.1, 0.02), "L": (0.06, 0.1, 0.06)}
    centres = {"P": (-0.02, 0, 0.11), "B": (0.01, 0, 0.13), "L": (0.05, 0, 0.17)}
    with BulletWorld(SIM, tmp_path) as world:
        world.add_ground(-1.0)
        shelf = trimesh.creation.box((0.4, 0.4, 0.1))
        world.add_body("shelf", [np.asarray(shelf.vertices)], make_pose(translation=(-0.2, 0, 0.05)), None)
        for name in ("P", "B", "L"):
            m = trimesh.creation.box(sizes[name])
            hulls = [np.asarray(m.vertices)]
            x, y, z = centres[name]
            world.add_body(name, hulls, make_pose(translation=(x, y, z + 0.0005)),
                           rigid_props(m, hulls, SIM.density, 1.0))
            assert settle_object(world, name, SettleParams()).settled  # each rests on the frozen ones below
            if name != "L":
                world.set_static(name)
        near = sorted(world.distances("L", ["shelf", "P", "B"], 0.004))
        assert near == ["B"]
        carriers = load_carriers(world, "L", near, set(), 0.004, depth)
        assert carriers == ["B", "P"][:depth]
        moved, _ = gives_way(world, "L", carriers, 60, 0.005, 1.0)
        assert bool(moved) is gives and (not gives or "P" in moved)
        assert gives_way(world, "L", carriers, 60, 0.005, 1.0, SettleParams())[0] == moved


@pytest.mark.parametrize("centre_load", [True, False])
def test_a_load_that_tips_its_carrier_is_moved_over_the_carriers_centre(work, centre_load):
    """Statics: a plank (0.5 x 0.05 x 0.02 m, mass m) lies on the table with its centre at x = 0.33, 7 cm inside
    the table's edge (x = 0.4): alone it stays. A cube of 0.1 m (mass 2 m) is put on it at x = 0.47. On the frozen
    plank the cube rests and holds when tilted, but the pair's centre of mass, (0.33 + 2 * 0.47) / 3 = 0.423, lies
    beyond the edge: released together, the plank tips and the cube falls. Half of the way to the plank's centre
    (x = 0.40) the pair's centre is (0.33 + 0.8) / 3 = 0.377, over the table: remedy ``centred`` stops there and
    the scene holds when released. Without it the cube takes the fallback on the frozen plank, and the joint
    release tips both."""
    plank = make_pose(translation=(0.33, 0.0, 0.1 + 0.01 + 0.0005))
    cube = make_pose(translation=(0.47, 0.0, 0.12 + 0.05 + 0.001))
    scene = scene_of(work, {"table": ("table", TABLE), "plank": ("plank", plank), "cube": ("box", cube)})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "plank", "supports"),
                         ("plank", "cube", "supports")])
    out, rec = run(work, scene, g, {"faithful": {"enabled": True, "centre_load": centre_load}})
    cert = rec["objects"]["cube"]["certificate"]
    x_cube, x_plank = out.get("cube").pose[0, 3], out.get("plank").pose[0, 3]
    if centre_load:
        assert cert["remedy"] == "centred" and cert["supporters_kept"] and cert["joint_stable"]
        assert x_plank == pytest.approx(0.33, abs=0.005) and x_cube == pytest.approx((0.47 + x_plank) / 2, abs=0.01)
        assert out.get("cube").pose[2, 3] == pytest.approx(0.17, abs=0.002)  # on the plank, not the table
    else:
        assert cert["remedy"].startswith("closest") and "gives way when released" in cert["reason"]
        assert "+joint" in cert["remedy"] and abs(x_plank - 0.33) > 0.01  # the plank tipped under it


def test_centred_starts_move_over_the_carriers_below_not_a_taller_neighbour(tmp_path):
    """A cube (0.1 m) rests on a plank whose centre is 0.12 m to its -x, and touches a column (0.3 m tall) on its
    +x side, whose centre of mass lies higher than the cube's: only the plank carries it. The starts move the
    cube's centre of mass half and all of the way to the plank's (0.06 m, 0.12 m), the second capped at the reach
    (0.09 m); both stay on the plank (no overlap, so not raised). Touching only the column: no start."""
    from phiscene.assembly.guarded import _centred_starts
    from phiscene.assembly.settle import SettleResult
    from phiscene.inertia import rigid_props
    from phiscene.sim.bullet import BulletWorld

    shapes = {"plank": (0.5, 0.1, 0.02), "cube": (0.1, 0.1, 0.1), "column": (0.1, 0.1, 0.3)}
    poses = {"plank": make_pose(translation=(0.0, 0, 0.01)), "cube": make_pose(translation=(0.12, 0, 0.0701)),
             "column": make_pose(translation=(0.2202, 0, 0.15))}
    with BulletWorld(SIM, tmp_path) as world:
        world.add_ground(0.0)
        for name, extents in shapes.items():
            m = trimesh.creation.box(extents)
            hulls = [np.asarray(m.vertices)]
            world.add_body(name, hulls, poses[name], rigid_props(m, hulls, SIM.density, 1.0))
            if name != "cube":
                world.set_static(name)
        rest = SettleResult(pose=poses["cube"], frames=0, settled=True, remedy="none", residual_translation=0.0,
                            residual_rotation=0.0)
        for touching, expected in ((["column", "plank"], [0.06, 0.03]), (["column"], [])):
            starts = _centred_starts(world, "cube", {"result": rest, "touching": touching}, set(),
                                     ["plank", "column"], 0.002, 0.09)
            assert [round(float(s[0, 3]), 6) for s in starts] == expected
            assert all(s[2, 3] == poses["cube"][2, 3] for s in starts)


@pytest.mark.parametrize("optimizer", ["adam", "steepest"])
def test_penetration_solve_pushes_along_the_normal_with_steepest(tmp_path, optimizer):
    """A cube sunk 2 cm into a tilted wall: the smallest translation clearing it is (2 cm + eps) along the normal."""
    from phiscene.assembly.penetration import PenetrationParams, resolve_penetration, sdf_body
    from phiscene.scene import Plane

    n = np.array([0.6, 0.0, 0.8])
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    pp = PenetrationParams(optimizer=optimizer)
    # the corner of the cube nearest the plane reaches 2 cm past it
    depth = 0.02
    reach = 0.05 * np.abs(n).sum()
    pose = make_pose(translation=n * (reach - depth))
    active = sdf_body("cube", cube, pose, pp.n_active, pp, tmp_path)
    x, info = resolve_penetration(active, [], None, pp, [Plane("wall_0", "wall", tuple(n), 0.0)])
    assert info["final_loss"] == 0.0
    along = float(x @ n)
    sideways = float(np.linalg.norm(x - along * n))
    assert depth <= along <= depth + pp.eps + 2 * pp.lr
    if optimizer == "steepest":
        assert sideways < 1e-6  # every point's gradient is the normal: no sideways push
    else:
        # Adam normalises each coordinate: equal steps along x and z, (1, 0, 1) s with 1.4 s = along,
        # whose part off the normal is 0.14 of the push
        assert sideways == pytest.approx(along / 1.4 * math.hypot(1 - 0.6 * 1.4, 1 - 0.8 * 1.4), rel=0.05)



def test_direction_search_replaces_a_longer_gradient_solve(tmp_path):
    """A cube 2 cm into a wall whose normal is 16 deg off the x axis: the smallest clearing translation is
    (2 cm + eps) along the normal. Adam moves x and z by equal steps, 58 deg off the normal, so it clears the
    wall only after a longer move; the direction search finds a ray within the Fibonacci lattice's spacing of
    the normal, and its shorter translation replaces Adam's."""
    from phiscene.assembly.penetration import PenetrationParams, resolve_penetration, sdf_body
    from phiscene.scene import Plane

    n = np.array([0.96, 0.0, 0.28])
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    depth = 0.02
    pose = make_pose(translation=n * (0.05 * np.abs(n).sum() - depth))
    lengths = {}
    for k in (0, 32):
        pp = PenetrationParams(optimizer="adam", search_directions=k)
        active = sdf_body("cube", cube, pose, pp.n_active, pp, tmp_path)
        x, info = resolve_penetration(active, [], None, pp, [Plane("wall_0", "wall", tuple(n), 0.0)])
        assert info["final_loss"] == 0.0 and x @ n >= depth
        lengths[k] = float(np.linalg.norm(x))
    shortest = depth + PenetrationParams().eps
    assert lengths[0] > 1.1 * shortest  # Adam: the long way
    # 32 lattice directions leave no direction farther than 25 deg from some ray: 1 / cos(25 deg) = 1.10
    assert lengths[32] <= shortest / math.cos(math.radians(25.0)) + 1e-4 < lengths[0]

# -- pose metrics -------------------------------------------------------------------------------------------
def test_pose_metrics_analytic(work):
    a = make_pose(translation=(0.0, 0.0, 0.05))
    b = make_pose(translation=(1.0, 0.0, 0.05))
    initial = scene_of(work, {"a": ("box", a), "b": ("box", b)})
    Rz = Rotation.from_euler("z", 10, degrees=True).as_matrix()
    moved = scene_of(work, {"a": ("box", make_pose(Rz, (0.03, 0.04, 0.05))), "b": ("box", b)})
    m = pose_metrics(moved, initial)
    assert m["displacement_mean"] == pytest.approx(0.025, abs=1e-6)
    assert m["displacement_max"] == pytest.approx(0.05, abs=1e-6)
    assert m["rotation_mean"] == pytest.approx(5.0, abs=1e-6)
    assert m["rotation_max"] == pytest.approx(10.0, abs=1e-6)


def test_pose_metrics_alignment_removes_a_rigid_motion(work):
    poses = {"a": make_pose(translation=(0.0, 0.0, 0.05)), "b": make_pose(translation=(1.0, 0.0, 0.05)),
             "c": make_pose(translation=(0.0, 0.7, 0.3))}
    initial = scene_of(work, {k: ("box", p) for k, p in poses.items()})
    G = make_pose(Rotation.from_euler("zx", [40, 15], degrees=True).as_matrix(), (2.0, -1.0, 0.5))
    other = scene_of(work, {k: ("box", G @ p) for k, p in poses.items()})
    raw = pose_metrics(other, initial)
    assert raw["displacement_mean"] > 0.5
    al = pose_metrics(other, initial, align=True)
    assert al["displacement_max"] < 1e-9 and al["rotation_max"] < 1e-6


def test_pose_metrics_gt_add_s(work):
    a = make_pose(translation=(0.0, 0.0, 0.05))
    gt = scene_of(work, {"a": ("box", a)})
    # a cube turned 90 deg about z is the same shape: ADD-S 0, rotation error 90
    turned = scene_of(work, {"a": ("box", make_pose(Rotation.from_euler("z", 90, degrees=True).as_matrix(),
                                                     (0.0, 0.0, 0.05)))})
    m = pose_metrics(turned, gt, gt=gt)
    assert m["gt_rotation_mean"] == pytest.approx(90.0, abs=1e-6)
    assert m["gt_adds_mean"] < 0.01  # only sampling density remains
    shifted = scene_of(work, {"a": ("box", make_pose(translation=(0.0, 0.0, 0.08)))})
    m = pose_metrics(shifted, gt, gt=gt)
    assert m["gt_translation_max"] == pytest.approx(0.03, abs=1e-9)
    assert 0.0 < m["gt_adds_mean"] <= 0.03 + 1e-9  # symmetric distance never exceeds the shift


def test_lowering_onto_a_supporter_that_is_not_beneath_stops_at_the_ground(tmp_path):
    """A carried object whose supporter moved away is lowered until the ground stops it, never through it."""
    from phiscene.assembly.guarded import lowered_start
    from phiscene.sim.bullet import BulletWorld

    box = trimesh.creation.box((0.1, 0.1, 0.1))
    hulls = [np.asarray(box.vertices)]
    with BulletWorld(SIM, tmp_path) as world:
        world.add_ground(0.0)
        world.add_body("table", hulls, make_pose(translation=(1.0, 0.0, 0.05)), None)  # 1 m to the side
        world.add_body("cup", hulls, make_pose(translation=(0.0, 0.0, 0.6)), None)
        out = lowered_start(world, "cup", make_pose(translation=(0.0, 0.0, 0.6)), ["table"], 0.002)
    bottom = out[2, 3] - 0.05
    assert 0.0 <= bottom <= 0.002 + 1e-9


@pytest.mark.parametrize("faithful", [True, False])
def test_box_beside_a_wall_shelf_is_moved_onto_it(work, faithful):
    # a wall shelf board (0.3 m square, 4 cm thick, top at z = 1.02) fixed in place; a 10 cm box the graph puts on
    # it, but placed 1 cm beside its edge (x = 0.15), as a depth error does: released, it falls 1 m to the floor.
    # Faithful grounding moves it onto the board: bottom on the board's top, centre over the board inside its edge.
    board = make_pose(translation=(0.0, 0.0, 1.0))
    pose = make_pose(translation=(0.21, 0.0, 1.02 + 0.05 + 0.001))
    scene = scene_of(work, {"slab": ("slab", board), "box": ("box", pose)})
    g = graph_of(scene, [("slab", "box", "supports")])
    params = {"faithful": {"enabled": faithful}}
    out, rec = run(work, scene, g, params=params, attached={"slab": "wall_0"})
    lo, hi = out.get("box").world_mesh().bounds
    if not faithful:  # the paper's loop: it falls to the floor
        assert lo[2] < 0.01
        return
    cert = rec["objects"]["box"]["certificate"]
    assert cert["remedy"].startswith("onto") and cert["settled"] and cert["supporters_kept"]
    assert abs(lo[2] - 1.02) < 0.005  # resting on the board's top
    assert hi[0] <= 0.15 + 1e-3  # wholly over the board (its footprint pulled inside the edge)
    assert np.linalg.norm(out.get("box").pose[:2, 3] - pose[:2, 3]) < 0.15  # moved across, not far


def test_onto_start_centres_the_footprint_inside_the_edge_clear_of_walls():
    from phiscene.assembly.starts import onto_start
    from phiscene.scene import Plane

    # a level 0.3 m square surface at z = 1.02 (a regular grid of samples); a 10 cm cube whose centre is 6 cm beyond
    # its edge (x = 0.15), its bottom 1 mm above the surface's height
    g = np.linspace(-0.15, 0.15, 61)
    surface = np.array([(x, y, 1.02) for x in g for y in g])
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    pose = make_pose(translation=(0.21, 0.0, 1.071))
    pts = trimesh.transform_points(cube.vertices, pose)
    out, shift = onto_start(pose, np.zeros(3), pts, surface, reach=0.3, clearance=0.002)
    moved = trimesh.transform_points(cube.vertices, out)
    assert moved[:, 2].min() == pytest.approx(1.022, abs=1e-9)  # just above the surface
    # the whole footprint over it by the smallest motion: just inside the edge (within two sample spacings)
    assert 0.15 - 0.01 <= moved[:, 0].max() <= 0.15
    assert abs(out[1, 3]) < 0.005 and shift == pytest.approx(0.21 - out[0, 3], abs=1e-6)  # straight inwards
    # a wall at y = 0.03 (room on y < 0.03): the cube ends at least its footprint radius from it
    wall = Plane(id="wall_0", kind="wall", normal=(0.0, -1.0, 0.0), offset=0.03)
    out, _ = onto_start(pose, np.zeros(3), pts, surface, 0.3, 0.002, planes=[wall])
    assert trimesh.transform_points(cube.vertices, out)[:, 1].max() <= 0.03
    # nothing within reach: no start
    high = make_pose(translation=(0.21, 0.0, 1.6))
    assert onto_start(high, np.zeros(3), trimesh.transform_points(cube.vertices, high), surface, 0.3, 0.002) is None


def test_flush_attached_makes_a_tilted_wall_shelf_level_and_puts_its_back_on_the_wall():
    from phiscene.assembly.resting import flush_attached

    # a shelf board 0.6 x 0.18 x 0.03 m fixed to the wall y = 0 (room on y < 0), input tilted 8 deg about x and
    # 3 deg about y and pushed 2 cm into the wall, as a rotation and depth error of the input do
    board = trimesh.creation.box((0.6, 0.18, 0.03))
    R = Rotation.from_euler("xy", [8.0, 3.0], degrees=True).as_matrix()
    pose = make_pose(R, (0.0, -0.09 + 0.02, 1.0))
    wall = np.array([0.0, -1.0, 0.0])
    out, angle, shift = flush_attached(pose, resting_normals(board.vertices), np.zeros(3), board.vertices,
                                       wall, 0.0, True, 20.0)
    Rout = decompose(out)[0]
    assert np.allclose(np.abs(Rout), np.eye(3), atol=1e-9)  # every face axis-aligned: top level, back on the wall
    assert trimesh.transform_points(board.vertices, out)[:, 1].max() == pytest.approx(0.0, abs=1e-9)
    # the rotation undone is the input's (8 and 3 deg about two axes), about the centre, which was 2 cm too deep:
    # the board moved 2 cm out of the wall, along the wall's normal
    assert angle == pytest.approx(math.degrees(Rotation.from_matrix(R).magnitude()), abs=1e-6)
    assert shift == pytest.approx(0.02, abs=1e-9)
    assert np.allclose(out[:3, 3], (0.0, -0.09, 1.0), atol=1e-9)
    # 25 cm into the wall, beyond the reach that bounds a move towards the wall: nothing fixed to a wall is inside
    # it, so it comes out all the same, by exactly its depth
    deep = make_pose(np.eye(3), (0.0, -0.09 + 0.25, 1.0))
    out, _, shift = flush_attached(deep, resting_normals(board.vertices), np.zeros(3), board.vertices, wall, 0.0,
                                   True, 20.0)
    assert shift == pytest.approx(0.25, abs=1e-9) and np.allclose(out[:3, 3], (0.0, -0.09, 1.0), atol=1e-9)


def test_flush_attached_on_a_ceiling_keeps_the_heading_and_leaves_large_errors():
    from phiscene.assembly.resting import flush_attached

    # a 0.3 x 0.3 x 0.05 m panel fixed to the ceiling z = 2.5 (normal -z, room below), tilted 6 deg, turned 30 deg
    # about the vertical, its top 3 cm below the ceiling
    panel = trimesh.creation.box((0.3, 0.3, 0.05))
    yaw = Rotation.from_euler("z", 30.0, degrees=True)
    R = (Rotation.from_euler("x", 6.0, degrees=True) * yaw).as_matrix()
    pose = make_pose(R, (1.0, 1.0, 2.445))
    ceiling = np.array([0.0, 0.0, -1.0])
    normals = resting_normals(panel.vertices)
    out, angle, shift = flush_attached(pose, normals, np.zeros(3), panel.vertices, ceiling, 2.5, False, 20.0)
    Rout = decompose(out)[0]
    assert Rout[:, 2] @ [0, 0, 1] == pytest.approx(1.0, abs=1e-12)  # top flush with the ceiling
    assert angle == pytest.approx(6.0, abs=1e-6)  # the smallest rotation: the tilt only, the heading kept
    assert trimesh.transform_points(panel.vertices, out)[:, 2].max() == pytest.approx(2.5, abs=1e-9)
    # tilted 30 deg (more than max_flush_angle) and 20 cm below (more than the reach): left as it is
    far = make_pose(Rotation.from_euler("x", 30.0, degrees=True).as_matrix(), (1.0, 1.0, 2.2))
    out, angle, shift = flush_attached(far, normals, np.zeros(3), panel.vertices, ceiling, 2.5, False, 20.0)
    assert np.allclose(out, far) and angle == 0.0 and shift == 0.0


@pytest.mark.parametrize("faithful", [True, False])
def test_a_tilted_wall_shelf_is_made_flush_and_what_stands_on_it_level(work, faithful):
    from phiscene.scene import Plane

    # a board fixed to the wall x = -0.15 (room on x > -0.15), its input tilted 12 deg so that its top slopes down
    # away from the wall, a box resting on it tilted with it: faithful grounding levels the board against its wall
    # and the box ends level on it; the paper's loop keeps the attached board exactly where the input put it
    tilt = Rotation.from_euler("y", 12.0, degrees=True).as_matrix()
    board = make_pose(tilt, (0.0, 0.0, 1.0))
    top = trimesh.transform_points([[0.0, 0.0, 0.02]], board)[0]
    box = make_pose(tilt, top + tilt @ [0.0, 0.0, 0.051])
    scene = scene_of(work, {"slab": ("slab", board), "box": ("box", box)})
    scene.structure = [Plane("wall_0", "wall", (1.0, 0.0, 0.0), 0.15)]
    g = graph_of(scene, [("slab", "box", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": faithful}}, attached={"slab": "wall_0"})
    if not faithful:
        assert np.allclose(out.get("slab").pose, board)
        return
    R = decompose(out.get("slab").pose)[0]
    assert math.degrees(math.acos(min(1.0, R[:, 2] @ [0, 0, 1]))) < 1e-6  # the board's top is level
    assert rec["objects"]["slab"]["flush_angle"] == pytest.approx(12.0, abs=1e-6)
    assert out.get("slab").world_mesh().bounds[0, 0] == pytest.approx(-0.15, abs=1e-9)  # back on the wall
    Rb = decompose(out.get("box").pose)[0]
    assert math.degrees(math.acos(min(1.0, Rb[:, 2] @ [0, 0, 1]))) < 0.5  # the box stands level on it
    lo, _ = out.get("box").world_mesh().bounds
    cert = rec["objects"]["box"]["certificate"]
    assert cert["settled"] and cert["supporters_kept"] and lo[2] > 1.0  # on the board, not on the floor


def test_onto_start_fits_a_long_object_along_a_narrow_shelf_by_the_smallest_motion():
    from phiscene.assembly.starts import fitting_point, onto_start

    # a shelf top 0.6 m long (x) and 0.1 m deep (y) at z = 1.0, sampled every 5 mm; a plank 0.3 x 0.04 m lying
    # along it but 8 cm in front of it (a depth error): it fits along the shelf, so it moves straight back by
    # 5 cm, to the front edge, not to the shelf's middle and not along it
    xs, ys = np.linspace(-0.3, 0.3, 121), np.linspace(-0.05, 0.05, 21)
    shelf = np.array([(x, y, 1.0) for x in xs for y in ys])
    plank = trimesh.creation.box((0.3, 0.04, 0.02))
    pose = make_pose(translation=(0.0, -0.08, 1.012))
    pts = trimesh.transform_points(plank.vertices, pose)
    out, shift = onto_start(pose, np.zeros(3), pts, shelf, reach=0.3, clearance=0.002)
    moved = trimesh.transform_points(plank.vertices, out)
    assert out[0, 3] == pytest.approx(0.0, abs=1e-9)  # not along the shelf
    assert -0.05 <= moved[:, 1].min() <= -0.05 + 0.01  # at the front edge, within two sample spacings
    assert shift == pytest.approx(-0.03 - (-0.08), abs=0.01)
    # turned across the shelf (0.3 m deep footprint on a 0.1 m shelf) it fits nowhere
    across = np.array([[-0.02, -0.15], [0.02, -0.15], [0.02, 0.15], [-0.02, 0.15]])
    assert fitting_point(shelf[:, :2], across, np.array([0.0, -0.08])) is None
    # a footprint with no area (a rod's points on one line: no Delaunay triangulation) is fitted by its box
    rod = np.array([[-0.1, 0.0], [0.0, 0.0], [0.1, 0.0]])
    p = fitting_point(shelf[:, :2], rod, np.array([0.0, -0.08]))
    assert p is not None and p[0] == pytest.approx(0.0, abs=1e-9) and -0.05 < p[1] <= -0.05 + 0.01


def test_fitting_point_stays_bounded_on_a_large_densely_sampled_surface():
    import time

    from phiscene.assembly.starts import fitting_point

    # a 2 x 2 m surface sampled every 5 mm with every sample doubled (zero spacing between twins), a 0.6 m square
    # footprint 1 m off its edge: the raster is capped, so this takes well under a second, and the footprint ends
    # wholly inside the surface, within a few cells of its edge
    g = np.arange(-1.0, 1.0 + 1e-9, 0.005)
    xy = np.array([(x, y) for x in g for y in g])
    xy = np.vstack([xy, xy])
    square = np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]])
    t0 = time.perf_counter()
    p = fitting_point(xy, square, np.array([2.0, 0.0]))
    assert time.perf_counter() - t0 < 2.0
    assert p is not None and 1.0 - 0.3 - 0.1 <= p[0] <= 1.0 - 0.3 and abs(p[1]) < 0.05


@pytest.mark.parametrize("through, lifted", [(0.04, True), (0.15, False)])
def test_an_attached_object_through_the_floor_is_lifted_onto_it_within_reach(work, through, lifted):
    # a tall thin panel fixed to an unknown wall (holder: the ground), its bottom `through` below the floor: a
    # floor-length curtain a depth error pushed through the floor rests on it after grounding, unless it reaches
    # deeper than the attachment reach (then it is left as the input has it)
    pose = make_pose(translation=(0.0, 0.0, 0.15 - through))  # the column is 0.3 tall: bottom at -through
    scene = scene_of(work, {"column": ("column", pose)})
    g = graph_of(scene, [("ground", "column", "attached")])
    out, rec = run(work, scene, g, attached={"column": "ground"})
    lo, _ = out.get("column").world_mesh().bounds
    assert lo[2] == pytest.approx(0.0 if lifted else -through, abs=1e-9)
    assert np.allclose(out.get("column").pose[:3, :2], pose[:3, :2])  # never turned
    assert np.allclose(out.get("column").pose[:2, 3], pose[:2, 3])  # nor moved sideways
    assert rec["objects"]["column"]["attach_lift"] == pytest.approx(through if lifted else 0.0, abs=1e-9)


@pytest.mark.parametrize("onto_reach", [0.3, 0.0])
def test_an_object_over_nothing_goes_onto_a_surface_nearer_than_the_floor(work, onto_reach):
    # a box 1 m up, beside a shelf fixed in place (top at 0.72 m, its edge 21 cm away horizontally): the shelf top
    # is 31 cm from the box's bottom, beyond onto_reach, but the floor it would fall to is 95 cm away; the nearer
    # surface wins. With the onto remedy off it falls to the floor.
    shelf = make_pose(translation=(0.0, 0.0, 0.7))
    box = make_pose(translation=(0.36, 0.0, 1.0))
    scene = scene_of(work, {"slab": ("slab", shelf), "box": ("box", box)})
    g = graph_of(scene, [("ground", "slab", "attached"), ("ground", "box", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "onto_reach": onto_reach}},
                   attached={"slab": "ground"})
    lo, hi = out.get("box").world_mesh().bounds
    if onto_reach == 0:
        assert lo[2] == pytest.approx(0.0, abs=2e-3)
        return
    assert lo[2] == pytest.approx(0.72, abs=5e-3)  # on the shelf
    assert hi[0] <= 0.15 + 1e-3  # wholly over it
    assert rec["objects"]["box"]["certificate"]["settled"]


@pytest.mark.parametrize("case", ["beside", "on_top", "between", "too_far"])
def test_clear_overlaps_moves_out_of_a_side_overlap_by_its_depth(tmp_path, case):
    """Geometry: a 0.2 m cube overlapping a 1 m block's side by 3 cm is moved 3 cm out along the side's normal;
    an overlap from below (it rests on the block) is left alone, as is one it cannot leave (held 3 cm deep by
    blocks on both sides) or one deeper than the move allowed."""
    from phiscene.assembly.settle import clear_overlaps
    from phiscene.sim.bullet import BulletWorld

    block = [np.asarray(trimesh.creation.box((1.0, 1.0, 1.0)).vertices)]
    cube = [np.asarray(trimesh.creation.box((0.2, 0.2, 0.2)).vertices)]
    at = {"beside": (0.6 - 0.03, 0.0, 0.1), "on_top": (0.0, 0.0, 1.09), "between": (0.6 - 0.03, 0.0, 0.1),
          "too_far": (0.6 - 0.03, 0.0, 0.1)}[case]
    with BulletWorld(SIM, tmp_path) as world:
        world.add_body("block", block, make_pose(translation=(0, 0, 0.5)), None)
        others = ["block"]
        if case == "between":  # a second block whose side is 3 cm into the cube's other side
            world.add_body("other", block, make_pose(translation=(1.14, 0, 0.5)), None)
            others.append("other")
        world.add_body("cube", cube, make_pose(translation=at), None)
        before = world.pose("cube")
        shift = clear_overlaps(world, "cube", others, 0.002, 0.01 if case == "too_far" else 0.09)
        assert np.allclose(world.pose("cube"), before)  # put back
    if case == "beside":
        np.testing.assert_allclose(shift, [0.03, 0.0, 0.0], atol=1e-3)
    else:
        assert shift is None


def test_a_plant_whose_hull_overlaps_a_curtain_is_moved_out_and_stands(work, tmp_path):
    # a "plant": a 20 cm pot, a 2 cm stem and a 60 cm canopy 1 m up; its one convex hull (the proxy) widens from the
    # pot's bottom edge (x = 0.1 at z = 0) to the canopy's (x = 0.3 at z = 0.98). A fixed panel (a curtain) with its
    # face at x = 0.16, 40-50 cm up, clears the mesh (the stem) by 15 cm but lies inside the hull's side, which
    # reaches x = 0.1 + 0.2 z / 0.98 there: 0.202 at its top, 4.2 cm beyond the panel's face. Knocked over from
    # where it was put, it is moved out of that overlap, away from the panel (-x) by its depth, and stands there
    pot = trimesh.creation.box((0.2, 0.2, 0.2)).apply_translation((0, 0, 0.1))
    stem = trimesh.creation.box((0.02, 0.02, 0.8)).apply_translation((0, 0, 0.6))
    canopy = trimesh.creation.box((0.6, 0.6, 0.04)).apply_translation((0, 0, 1.0))
    plant = save_mesh(trimesh.util.concatenate([pot, stem, canopy]), tmp_path / "plant.obj")
    panel = save_mesh(trimesh.creation.box((0.02, 0.3, 0.1)), tmp_path / "panel.obj")
    from phiscene.scene import Scene, SceneObject

    scene = Scene([SceneObject("curtain", panel, make_pose(translation=(0.17, 0.0, 0.45))),
                   SceneObject("plant", plant, make_pose(translation=(0.0, 0.0, 0.0)))])
    g = graph_of(scene, [("ground", "curtain", "attached"), ("ground", "plant", "supports")])
    params = {"faithful": {"enabled": True}, "penetration_params": {"optimizer": "steepest"}}
    out, rec = run(work, scene, g, params=params, attached={"curtain": "ground"})
    plant_rec = rec["objects"]["plant"]
    assert np.allclose(plant_rec["sdf_translation"][:2], 0.0)  # the meshes are apart: no sideways push
    shift = np.asarray(plant_rec["proxy_clear"])
    depth = 0.1 + 0.2 * 0.5 / 0.98 - 0.16
    assert -shift[0] == pytest.approx(depth, abs=0.006) and abs(shift[1]) < 1e-3 and shift[2] == 0.0
    R, t, _ = decompose(out.get("plant").pose)
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) < 1.0  # upright
    np.testing.assert_allclose(t[:2], shift[:2], atol=0.005)  # where it was put, but for the move
    assert plant_rec["certificate"]["remedy"] == "clear" and plant_rec["certificate"]["joint_stable"]
    first = plant_rec["certificate"]["reason"].split(";")[0]  # "none: moved 0.939 m / 79.3 deg"
    assert first.startswith("none: moved") and float(first.split("/")[1].split()[0]) > 45.0  # knocked over
    # without the remedy no start is taken out of the overlap: every start nearby is knocked over, and a shifted one
    # that stands ends farther
    out0, rec0 = run(work, scene, g, params={**params, "faithful": {"enabled": True, "clear": False}},
                     attached={"curtain": "ground"})
    assert "proxy_clear" not in rec0["objects"]["plant"]
    assert rec0["objects"]["plant"]["certificate"]["remedy"] != "clear"
    assert rec0["objects"]["plant"]["certificate"]["displacement"] > plant_rec["certificate"]["displacement"]


def test_closest_faces_distances_are_trimesh_s_and_a_rim_point_takes_the_top_face():
    """Distances against trimesh's closest-point query (the oracle); ties at an edge or a vertex go to the most
    upward face (the top of a table, not its side), wherever the query lands on it."""
    top = trimesh.creation.box([1.0, 0.6, 0.1])  # top face at z = 0.05, rim at x = 0.5
    top = top.subdivide().subdivide()  # edges and vertices inside the top face, not only on the rim
    rng = np.random.default_rng(3)
    pts = rng.uniform([-0.8, -0.5, -0.3], [0.8, 0.5, 0.4], size=(400, 3))
    dist, face = closest_faces(top, pts)
    _, ref, _ = trimesh.proximity.closest_point(top, pts)
    np.testing.assert_allclose(dist, ref, atol=1e-12)
    # the face found contains the closest point: its distance is the same
    np.testing.assert_allclose(trimesh.triangles.closest_point(top.triangles[face], pts) - pts,
                               trimesh.proximity.closest_point(top, pts)[0] - pts, atol=1e-9)
    # points above the rim edge (x > 0.5, z > 0.05 + (x - 0.5)) are nearest the edge: top and side tie
    rim = np.array([[0.5 + d, y, 0.05 + 2 * d] for d in (0.01, 0.03) for y in (-0.2, 0.0, 0.13)])
    # points over a vertex of the subdivided top (its corner at x = y = 0.5 / 0.3 included)
    corner = np.array([[0.52, 0.32, 0.1], [0.0, 0.0, 0.2]])
    d2, f2 = closest_faces(top, np.vstack([rim, corner]))
    assert np.all(top.face_normals[f2][:, 2] > 0.999), top.face_normals[f2]
    np.testing.assert_allclose(d2[:6], [math.hypot(d, 2 * d) for d in (0.01, 0.03) for _ in range(3)], atol=1e-12)


def test_support_normal_of_a_tilted_table_top_under_an_object_at_its_rim():
    """The supporter's normal under an object is its top's normal, also where the object's lowest points hang
    over the rim (every face they are nearest ties between the top and the side)."""
    tilt = Rotation.from_euler("x", 7, degrees=True).as_matrix()
    table = trimesh.creation.box([1.0, 1.0, 0.1]).subdivide()
    table.apply_transform(make_pose(tilt, np.zeros(3)))
    expected = tilt @ np.array([0.0, 0.0, 1.0])
    for x in (0.0, 0.48):  # in the middle; half over the rim
        block = trimesh.creation.box([0.1, 0.1, 0.1])
        block.apply_transform(make_pose(tilt, tilt @ np.array([x, 0.0, 0.1 + 1e-3])))
        n = support_normal(block, {"table": table})
        assert math.degrees(math.acos(min(1.0, float(n @ expected)))) < 1e-6, (x, n)
    # carried by the table and the ground at once: the two normals average (as many lowest points on each)
    block = trimesh.creation.box([0.1, 0.1, 0.1]).apply_transform(make_pose(tilt, tilt @ np.array([0, 0, 0.101])))
    both = support_normal(block, {"table": table, "ground": None})
    mean = expected + np.array([0.0, 0.0, 1.0])
    assert math.degrees(math.acos(min(1.0, float(both @ (mean / np.linalg.norm(mean)))))) < 1e-6


@pytest.mark.parametrize("sideways", ["always", "off_support"])
def test_a_supporter_pushed_sideways_carries_what_it_holds_only_when_needed(work, sideways):
    """The table (0.8 m square, 10 cm thick) overlaps a column standing on the floor by 3 cm along x; pushed out
    horizontally (it stands on the floor alone) it moves 3 cm + eps (5 mm) along -x. The box on its centre is
    still over the moved top: with ``carry_sideways: off_support`` it keeps its input position, with ``always``
    it moves with the table."""
    column = make_pose(translation=(0.42, 0.0, 0.15))  # its face at x = 0.37, inside the table's edge (0.4)
    box = make_pose(translation=(0.0, 0.0, 0.1 + 0.05 + 0.001))
    scene = scene_of(work, {"column": ("column", column), "table": ("table", TABLE), "box": ("box", box)})
    g = graph_of(scene, [("ground", "column", "supports"), ("ground", "table", "supports"),
                         ("table", "box", "supports")])
    params = {"faithful": {"enabled": True, "carry_sideways": sideways}, "penetration_params": PHI_SCENE_SDF}
    out, rec = run(work, scene, g, params=params)
    table_xy = out.get("table").pose[:2, 3]  # the search's nearest direction: (-0.035, 0.007)
    assert table_xy[0] == pytest.approx(-0.035, abs=0.003)  # out of the column by eps (the grids' error aside)
    cert = rec["objects"]["box"]["certificate"]
    assert cert["settled"] and cert["supporters_kept"]
    lo = out.get("box").world_mesh().bounds[0]
    assert lo[2] == pytest.approx(0.1, abs=0.003)  # on the table top
    expected = np.zeros(2) if sideways == "off_support" else table_xy
    assert np.linalg.norm(out.get("box").pose[:2, 3] - expected) < 0.003
    assert bool(rec["objects"]["box"].get("carried_vertically")) == (sideways == "off_support")


def test_a_box_left_beyond_its_moved_supporter_is_carried_with_it(work):
    """The table moves 3.5 cm along -x (as above); a box near its +x edge (centre 1.5 cm inside it) would no longer be
    over the top with its margin (half its half-width either side), so it is carried along with the table."""
    from phiscene.assembly.beneath import over_support

    table = trimesh.creation.box((0.8, 0.8, 0.1))
    box_points = np.asarray(trimesh.creation.box((0.1, 0.1, 0.1)).vertices)
    moved = table.copy().apply_transform(make_pose(translation=(-0.035, 0.0, 0.05)))
    inside = make_pose(translation=(0.30, 0.0, 0.15))
    near_edge = make_pose(translation=(0.35, 0.0, 0.15))
    assert over_support(inside, np.zeros(3), box_points, moved, 0.5)
    assert not over_support(near_edge, np.zeros(3), box_points, moved, 0.5)  # 0.35 + 0.025 > 0.365, its edge
    assert over_support(near_edge, np.zeros(3), box_points, moved, 0.0)  # its centre alone is still over it


@pytest.mark.parametrize("drop", [0.0, 0.002])
def test_the_joint_check_releases_the_scene_as_the_drift_metric_does(work, tmp_path, drop):
    """With ``joint_drop`` the drift protocol's lift (``metrics.physical.upward_offset``) and ``joint_frames`` its
    frames, each certificate's ``joint_drift`` is the pybullet drift metric of that object in the grounded scene as
    written and read back (a box tilted on a table, so that it has something to settle)."""
    from phiscene.metrics.drift import drift_bullet
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.scene import load_scene, save_scene

    R = Rotation.from_euler("x", 6, degrees=True).as_matrix()
    scene = scene_of(work, {"table": ("table", TABLE), "box": ("box", make_pose(R, (0.1, 0.0, 0.16)))})
    g = graph_of(scene, [("ground", "table", "supports"), ("table", "box", "supports")])
    out, rec = run(work, scene, g, params={"faithful": {"enabled": True, "joint_drop": drop, "joint_frames": 120}})
    out = load_scene(save_scene(out, tmp_path / "grounded" / "scene.json"))
    metric = drift_bullet(out, convex_proxies(out, work["cache"]), PhysicalParams(upward_offset=drop, frames=120),
                          SIM, work["cache"])
    for oid in ("table", "box"):
        got = rec["objects"][oid]["certificate"]["joint_drift"]
        assert got[0] == pytest.approx(metric["objects"][oid]["drift_trans"], abs=1e-6)
        assert got[1] == pytest.approx(metric["objects"][oid]["drift_rot"], abs=1e-4)
    # flush on the table, the box lands back where it rested (the drift is measured from before the lift)
    assert rec["objects"]["box"]["certificate"]["joint_drift"][0] < 1e-3
    assert rec["objects"]["box"]["certificate"]["joint_stable"]
