"""Support topology: graph file, placement order, cycle breaking, backends, edge metrics.

Oracles are the constructions: scenes built from boxes whose support edges
are known, footprints of boxes in closed form, and order properties that any
correct topological sort must satisfy.
"""

import json
import math
import time

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from phiscene import topology
from phiscene.errors import InputError
from phiscene.meshes import save_mesh
from phiscene.metrics.topology import edge_scores, file_scores, macro_scores, micro_scores
from phiscene.scene import Scene, SceneObject
from phiscene.topology.contacts import hull_offset
from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph, load, save
from phiscene.topology.order import break_cycles, footprint_area, footprint_key, kahn_order
from phiscene.transforms import make_pose, random_rotation

# ---------------------------------------------------------------- scene builders

def make_scene(root, specs) -> Scene:
    """specs: (id, trimesh mesh in local frame, pose) -> a Scene with meshes saved under ``root``."""
    objs = []
    for name, mesh, pose in specs:
        path = save_mesh(mesh, root / "meshes" / f"{name}.ply")
        objs.append(SceneObject(name, path, np.asarray(pose, dtype=float)))
    return Scene(objs)


def degrade(specs, seed, trans=0.015, rot_deg=3.0):
    """Noisy poses: translation uniform in +-trans per axis, rotation up to rot_deg about a random axis."""
    rng = np.random.default_rng(seed)
    out = []
    for name, mesh, pose in specs:
        p = np.array(pose, dtype=float)
        p[:3, :3] = random_rotation(rng, math.radians(rot_deg)) @ p[:3, :3]
        p[:3, 3] += rng.uniform(-trans, trans, 3)
        out.append((name, mesh, p))
    return out


def box(extents):
    return trimesh.creation.box(extents)


def stack_specs():
    return [("bottom", box([0.4, 0.3, 0.2]), make_pose(translation=[0, 0, 0.1])),
            ("middle", box([0.3, 0.25, 0.15]), make_pose(translation=[0.02, 0, 0.275])),
            ("top", box([0.15, 0.15, 0.1]), make_pose(translation=[0, 0.01, 0.4]))]


def bridge_specs():
    return [("left", box([0.2, 0.2, 0.25]), make_pose(translation=[-0.3, 0, 0.125])),
            ("right", box([0.2, 0.2, 0.25]), make_pose(translation=[0.3, 0, 0.125])),
            ("plank", box([0.8, 0.2, 0.03]), make_pose(translation=[0, 0, 0.265]))]


def lean_specs(tilt_deg=25.0, length=1.0, thick=0.03):
    """A plank standing on the ground, its top edge against the face x = 0.5 of a wall."""
    phi = math.radians(tilt_deg)
    R = Rotation.from_euler("y", phi).as_matrix()  # tilts the plank's top towards +x
    z_min = -math.sin(phi) * thick / 2 - math.cos(phi) * length / 2
    x_max = math.cos(phi) * thick / 2 + math.sin(phi) * length / 2
    return [("wall", box([0.1, 1.0, 1.2]), make_pose(translation=[0.55, 0, 0.6])),
            ("plank", box([thick, 0.2, length]), make_pose(R, [0.5 - x_max, 0, -z_min]))]


def tray_mesh(x=0.4, y=0.3, h=0.06, wall=0.01, floor=0.01):
    parts = [box([x, y, floor]).apply_translation([0, 0, -h / 2 + floor / 2])]
    parts += [box([wall, y, h]).apply_translation([s * (x / 2 - wall / 2), 0, 0]) for s in (-1, 1)]
    parts += [box([x - 2 * wall, wall, h]).apply_translation([0, s * (y / 2 - wall / 2), 0]) for s in (-1, 1)]
    return trimesh.util.concatenate(parts)


def tray_specs():
    return [("tray", tray_mesh(), make_pose(translation=[0, 0, 0.03])),
            ("cup", box([0.12, 0.1, 0.08]), make_pose(translation=[0.05, 0, 0.05]))]


def write_topology(path, objects, edges, **extra):
    data = {"format": "phiscene.topology/1", "objects": objects,
            "edges": [{"from": u, "to": v, "relation": "supports", "confidence": c} for u, v, c in edges], **extra}
    path.write_text(json.dumps(data))
    return path


# ---------------------------------------------------------------- graph file

def test_graph_round_trip(tmp_path):
    g = SupportGraph(["a", "b"], [SupportEdge("ground", "a", "supports", 0.9, "on the floor"),
                                  SupportEdge("a", "b", "leans_on", 0.5)],
                     order=["a", "b"], backend="test", meta={"k": 1})
    path = save(g, tmp_path / "out" / "topology.json")
    data = json.loads(path.read_text())
    assert data["objects"] == ["ground", "a", "b"]
    assert data["edges"][0] == {"from": "ground", "to": "a", "relation": "supports", "confidence": 0.9,
                                "reason": "on the floor"}
    back = load(path, scene_ids=["b", "a"])
    assert back == g
    assert not list((tmp_path / "out").glob(".*"))  # no temporary file left behind


def test_ground_is_implicit(tmp_path):
    path = write_topology(tmp_path / "t.json", ["a"], [("ground", "a", 1.0)])
    assert load(path).objects == ["ground", "a"]


@pytest.mark.parametrize("objects, edges, extra, field, words", [
    (["ground", "a"], [("ground", "x", 1.0)], {}, "edges[0].to", "unknown node 'x'"),
    (["ground", "a"], [("y", "a", 1.0)], {}, "edges[0].from", "unknown node 'y'"),
    (["ground", "a"], [("a", "a", 1.0)], {}, "edges[0]", "self loop"),
    (["ground", "a", "b"], [("a", "b", 1.0), ("a", "b", 0.5)], {}, "edges[1]", "duplicate edge"),
    (["ground", "a"], [("a", "ground", 1.0)], {}, "edges[0].to", "ground cannot be supported"),
    (["ground", "a"], [("ground", "a", 1.5)], {}, "edges[0].confidence", "1.5"),
    (["ground", "a", "b"], [], {"order": ["a"]}, "order", "not a permutation"),
    (["ground", "a"], [], {"format": "phiscene.topology/7"}, "format", "unknown format"),
    (["ground", "a"], [], {"colour": 1}, "colour", "unknown field"),
])
def test_bad_topology_names_file_and_field(tmp_path, objects, edges, extra, field, words):
    path = write_topology(tmp_path / "bad.json", objects, edges, **extra)
    with pytest.raises(InputError) as exc:
        load(path)
    assert exc.value.path == str(path) and exc.value.field == field
    assert words in str(exc.value) and "bad.json" in str(exc.value)


@pytest.mark.parametrize("ids, words", [(["a", "b", "c"], "missing scene objects ['c']"),
                                        (["a"], "objects not in the scene ['b']")])
def test_topology_must_match_scene_ids(tmp_path, ids, words):
    path = write_topology(tmp_path / "t.json", ["ground", "a", "b"], [("ground", "a", 1.0)])
    with pytest.raises(InputError, match=words.replace("[", r"\[").replace("]", r"\]")) as exc:
        load(path, scene_ids=ids)
    assert exc.value.field == "objects"


def test_save_refuses_bad_graph(tmp_path):
    g = SupportGraph(["a"], [SupportEdge("a", "a")])
    with pytest.raises(InputError, match="self loop"):
        save(g, tmp_path / "t.json")
    assert not (tmp_path / "t.json").exists()


# ---------------------------------------------------------------- order

def test_footprint_of_boxes_is_analytic():
    m = box([0.4, 0.2, 0.1])
    m.apply_transform(make_pose(Rotation.from_euler("z", 0.7).as_matrix(), [1, 2, 3]))
    assert footprint_area(m) == pytest.approx(0.08, rel=1e-6)
    m = box([0.4, 0.2, 0.1])
    m.apply_transform(make_pose(Rotation.from_euler("x", 90, degrees=True).as_matrix()))  # y and z swap
    assert footprint_area(m) == pytest.approx(0.04, rel=1e-6)


def test_ties_broken_by_footprint_then_id(tmp_path):
    # "a_small" sorts first by id, but the larger footprint is placed first
    specs = [("a_small", box([0.1, 0.1, 0.5]), make_pose(translation=[0, 0, 0.25])),
             ("b_large", box([0.5, 0.4, 0.05]), make_pose(translation=[1, 0, 0.025])),
             ("c_twin", box([0.1, 0.1, 0.5]), make_pose(Rotation.from_euler("z", 90, degrees=True).as_matrix(),
                                                        [2, 0, 0.25]))]
    scene = make_scene(tmp_path, specs)
    path = write_topology(tmp_path / "gt.json", ["ground", "a_small", "b_large", "c_twin"],
                          [("ground", "a_small", 1.0), ("ground", "b_large", 1.0), ("ground", "c_twin", 1.0)])
    g = topology.infer(scene, "given", given_path=path)
    assert g.order == ["b_large", "a_small", "c_twin"]  # equal footprints (rotated twin) fall back to id
    assert g.backend == "given" and g.meta["source"] == str(path)


def test_cycle_loses_its_weakest_edge():
    edges = [SupportEdge("ground", "a", confidence=1.0), SupportEdge("a", "b", confidence=0.9),
             SupportEdge("b", "c", confidence=0.8), SupportEdge("c", "a", confidence=0.3),
             SupportEdge("c", "d", confidence=0.7), SupportEdge("d", "c", confidence=0.6)]
    kept, dropped = break_cycles(edges)
    assert {e.pair for e in dropped} == {("c", "a"), ("d", "c")}
    g = topology.order.finalize(SupportGraph(["a", "b", "c", "d"], edges), areas={})
    pos = {n: i for i, n in enumerate(g.order)}
    assert all(pos[e.source] < pos[e.target] for e in g.edges if e.source != GROUND)
    assert g.order == ["a", "b", "c", "d"] and len(g.edges) == 4 and len(g.dropped_edges) == 2


def test_given_backend_breaks_cycles_of_the_file(tmp_path):
    scene = make_scene(tmp_path, stack_specs()[:2])
    path = write_topology(tmp_path / "t.json", ["ground", "bottom", "middle"],
                          [("ground", "bottom", 1.0), ("bottom", "middle", 0.9), ("middle", "bottom", 0.4)],
                          order=["middle", "bottom"])
    g = topology.infer(scene, "given", given_path=path)
    assert [e.pair for e in g.dropped_edges] == [("middle", "bottom")]
    assert g.order == ["bottom", "middle"]  # the file's order is recomputed
    assert load(save(g, tmp_path / "out.json")).dropped_edges == g.dropped_edges


def test_cycle_breaking_does_not_depend_on_edge_order():
    edges = [SupportEdge("a", "b", confidence=0.5), SupportEdge("b", "a", confidence=0.5)]
    assert break_cycles(edges)[1] == break_cycles(edges[::-1])[1]


@st.composite
def dags(draw):
    n = draw(st.integers(1, 12))
    names = [f"o{i:02d}" for i in range(n)]
    rank = draw(st.permutations(names))
    pairs = [(rank[i], rank[j]) for i in range(n) for j in range(i + 1, n)]
    edges = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=30)) if pairs else []
    areas = {k: draw(st.sampled_from([0.01, 0.02, 0.05, 0.3])) for k in names}
    return names, edges, areas


@settings(max_examples=150, deadline=None)
@given(dags())
def test_toposort_respects_edges_and_prefers_large_footprints(case):
    names, edges, areas = case
    order = kahn_order(names, edges, footprint_key(areas))
    assert sorted(order) == sorted(names)
    pos = {n: i for i, n in enumerate(order)}
    assert all(pos[u] < pos[v] for u, v in edges)
    # Kahn with priority: each placed node is the best (largest footprint, then id) of the ready ones
    preds = {n: {u for u, v in edges if v == n} for n in names}
    for i, n in enumerate(order):
        ready = [m for m in order[i:] if preds[m] <= set(order[:i])]
        assert n == min(ready, key=footprint_key(areas))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6), st.integers(1, 9)), max_size=25))
def test_break_cycles_leaves_an_acyclic_graph(raw):
    import networkx as nx

    edges, seen = [], set()
    for u, v, c in raw:
        if u != v and (f"n{u}", f"n{v}") not in seen:
            seen.add((f"n{u}", f"n{v}"))
            edges.append(SupportEdge(f"n{u}", f"n{v}", confidence=c / 10))
    kept, dropped = break_cycles(edges)
    assert {e.pair for e in kept} | {e.pair for e in dropped} == seen
    assert len(kept) + len(dropped) == len(edges)
    assert nx.is_directed_acyclic_graph(nx.DiGraph([e.pair for e in kept]))
    if nx.is_directed_acyclic_graph(nx.DiGraph(list(seen))):
        assert dropped == []


# ---------------------------------------------------------------- backends

def test_registry(tmp_path):
    scene = make_scene(tmp_path, stack_specs()[:1])
    with pytest.raises(ValueError, match="unknown topology backend 'nope'"):
        topology.infer(scene, "nope")
    with pytest.raises(ValueError, match="unknown GeometricParams keys"):
        topology.infer(scene, "geometric", {"tolerance": 1})
    with pytest.raises(ValueError, match="needs a file"):
        topology.infer(scene, "given")
    with pytest.raises(ValueError, match="does not read a file"):
        topology.infer(scene, "height", given_path=tmp_path / "x.json")

    from dataclasses import dataclass

    from phiscene.topology.params import BackendParams

    @dataclass(frozen=True)
    class AllOnGround(BackendParams):
        confidence: float = 0.4

    def infer_fn(scene, params):
        edges = [SupportEdge(GROUND, i, confidence=params.confidence) for i in scene.ids]
        return topology.order.finalize(SupportGraph(scene.ids, edges, backend="ground_only"), areas={})

    topology.register_backend("ground_only", infer_fn, AllOnGround)
    g = topology.infer(scene, "ground_only", {"confidence": 0.3})
    assert g.pairs() == {("ground", "bottom")} and g.edges[0].confidence == 0.3
    assert "ground_only" in topology.backend_names()


@pytest.mark.parametrize("seed", range(4))
def test_geometric_noisy_stack_gives_the_exact_chain(tmp_path, seed):
    scene = make_scene(tmp_path, degrade(stack_specs(), seed, trans=0.015, rot_deg=3.0))
    g = topology.infer(scene, "geometric")
    assert g.pairs() == {("ground", "bottom"), ("bottom", "middle"), ("middle", "top")}
    assert g.order == ["bottom", "middle", "top"]
    assert all(e.relation == "supports" and 0 < e.confidence <= 1 for e in g.edges)


@pytest.mark.parametrize("seed", range(3))
def test_geometric_bridge_has_two_parents(tmp_path, seed):
    scene = make_scene(tmp_path, degrade(bridge_specs(), seed))
    g = topology.infer(scene, "geometric")
    assert sorted(g.parents("plank")) == ["left", "right"]
    assert g.pairs() == {("ground", "left"), ("ground", "right"), ("left", "plank"), ("right", "plank")}
    assert g.order[-1] == "plank"


@pytest.mark.parametrize("seed, tilt", [(0, 20.0), (1, 30.0), (2, 15.0)])
def test_geometric_leaning_plank_keeps_the_wall(tmp_path, seed, tilt):
    scene = make_scene(tmp_path, degrade(lean_specs(tilt), seed, trans=0.01))
    g = topology.infer(scene, "geometric")
    assert g.pairs() == {("ground", "wall"), ("ground", "plank"), ("wall", "plank")}
    rel = {e.pair: e.relation for e in g.edges}
    assert rel[("wall", "plank")] == "leans_on" and rel[("ground", "plank")] == "supports"
    assert g.order == ["wall", "plank"]


def test_geometric_plank_flat_on_ground_does_not_lean(tmp_path):
    # the same plank lying flat next to the wall is stable on the ground alone
    specs = [lean_specs()[0], ("plank", box([1.0, 0.2, 0.03]), make_pose(translation=[-0.005, 0, 0.015]))]
    g = topology.infer(make_scene(tmp_path, specs), "geometric")
    assert g.pairs() == {("ground", "wall"), ("ground", "plank")}


def sunk_plank_specs(angle_deg=30.0, sink=0.05, short=0.03, length=0.6, thick=0.03):
    """A plank at ``angle_deg`` from the floor, its low end sunk ``sink`` m into it, its upper face passing
    ``short`` m beside the top edge of a 20 cm box it leans on (a depth error pulled it away)."""
    phi = math.radians(angle_deg)
    R = Rotation.from_euler("y", -phi).as_matrix()  # the plank's length (local x) rises towards +x
    axis, up = R[:, 0], R[:, 2]
    low = np.array([0.0, 0.0, -sink])  # the bottom edge of the low end
    centre = low + axis * length / 2 + up * thick / 2
    # the box edge the plank's bottom face would touch: on the line through `low` along `axis`, at z = 0.2
    edge_x = (0.2 + sink) / math.tan(phi)
    box_centre = [edge_x + 0.1 + short / math.sin(phi), 0.0, 0.1]
    return [("box", box([0.2, 0.3, 0.2]), make_pose(translation=box_centre)),
            ("plank", box([length, 0.2, thick]), make_pose(R, centre))]


def test_geometric_plank_sunk_into_the_floor_still_leans_on_its_box(tmp_path):
    # 25 cm of the plank lie within the floor's contact tolerance, so the floor alone seems to hold it;
    # resting on its lowest samples, it turns 30 deg (closed form) to lie down: it leans, on the box it falls onto
    g = topology.infer(make_scene(tmp_path, sunk_plank_specs()), "geometric")
    assert {e.pair: e.relation for e in g.edges if e.target == "plank"} == {
        ("ground", "plank"): "supports", ("box", "plank"): "leans_on"}
    assert g.order == ["box", "plank"]
    assert g.meta["objects"]["plank"]["fall"] == pytest.approx(30.0, abs=1.5)


@pytest.mark.parametrize("angle", [25.0, 35.0])
def test_geometric_plank_resting_on_a_box_edge_leans_on_it(tmp_path, angle):
    # one end on the floor, its underside on the box's top edge: the box holds it up from below, yet on the floor
    # alone it would turn `angle` (closed form) to lie down, so it leans on the box; a bridge lies level on each
    g = topology.infer(make_scene(tmp_path, sunk_plank_specs(angle, sink=0.0, short=0.0)), "geometric")
    assert {e.pair: e.relation for e in g.edges if e.target == "plank"} == {
        ("ground", "plank"): "supports", ("box", "plank"): "leans_on"}
    bridge = topology.infer(make_scene(tmp_path / "bridge", bridge_specs()), "geometric")
    assert {e.relation for e in bridge.edges if e.target == "plank"} == {"supports"}


def test_geometric_plank_far_from_the_wall_plane_leans_on_it(tmp_path):
    # a plank 30 deg off vertical, 12 cm short of the wall plane x = 0.5 (farther than any contact tolerance)
    from phiscene.scene import Plane

    specs = lean_specs(30.0)[1:]
    specs[0][2][0, 3] -= 0.12
    scene = make_scene(tmp_path, specs)
    scene.structure.append(Plane("wall_0", "wall", (-1.0, 0.0, 0.0), 0.5))
    g = topology.infer(scene, "geometric")
    rel = {e.pair: e.relation for e in g.edges if e.target == "plank"}
    assert rel == {("ground", "plank"): "supports", ("wall_0", "plank"): "leans_on"}
    assert g.meta["objects"]["plank"]["fall"] == pytest.approx(60.0, abs=2.5)  # the pivot is a sample, 1 cm apart


@pytest.mark.parametrize("lift", [0.12, 0.2])
def test_geometric_floating_plank_far_from_the_wall_plane_leans_on_it(tmp_path, lift):
    # the plank of the test above, also lifted `lift` m off the floor (out of every contact tolerance: only the
    # fallback holds it, as a depth error leaves a leaning book): lowered onto the floor it would turn 60 deg
    # (closed form) to lie down, and it tips onto the wall first
    from phiscene.scene import Plane

    specs = lean_specs(30.0)[1:]
    specs[0][2][0, 3] -= 0.12
    specs[0][2][2, 3] += lift
    scene = make_scene(tmp_path, specs)
    scene.structure.append(Plane("wall_0", "wall", (-1.0, 0.0, 0.0), 0.5))
    g = topology.infer(scene, "geometric")
    rel = {e.pair: e.relation for e in g.edges if e.target == "plank"}
    assert rel == {("ground", "plank"): "supports", ("wall_0", "plank"): "leans_on"}
    info = g.meta["objects"]["plank"]
    assert info["fallback"] and info["tips_onto"] == "wall_0"


@pytest.mark.parametrize("tilt", [0.0, 8.0])
def test_geometric_floating_box_near_a_wall_does_not_lean(tmp_path, tilt):
    # a box 15 cm above the floor, 5 cm from a wall, level or tilted 8 deg towards it (a rotation error): lowered onto
    # the floor it stands, or turns 8 deg to lie flat; it falls back on the floor and leans on nothing
    from phiscene.scene import Plane

    R = Rotation.from_euler("y", tilt, degrees=True).as_matrix()
    scene = make_scene(tmp_path, [("box", box([0.2, 0.2, 0.3]), make_pose(R, [0.33, 0.0, 0.3]))])
    scene.structure.append(Plane("wall_0", "wall", (-1.0, 0.0, 0.0), 0.5))
    g = topology.infer(scene, "geometric")
    assert g.pairs() == {("ground", "box")}
    assert g.meta["objects"]["box"]["fallback"]


@pytest.mark.parametrize("seed", range(3))
def test_geometric_tilted_box_beside_another_does_not_lean(tmp_path, seed):
    # a rotation error tilts a box 8 deg onto its neighbour: it turns 8 deg to lie flat, an input error, no lean
    tilt = Rotation.from_euler("y", -8.0, degrees=True).as_matrix()
    specs = [("big", box([0.3, 0.3, 0.4]), make_pose(translation=[0, 0, 0.2])),
             ("small", box([0.2, 0.2, 0.2]), make_pose(tilt, [0.262, 0, 0.1 + 0.1 * math.sin(math.radians(8))]))]
    g = topology.infer(make_scene(tmp_path, degrade(specs, seed, trans=0.003, rot_deg=1.0)), "geometric")
    assert g.pairs() == {("ground", "big"), ("ground", "small")}
    assert g.meta["objects"]["small"]["fall"] == pytest.approx(8.0, abs=2.0)


@pytest.mark.parametrize("seed", range(3))
def test_geometric_box_in_tray_does_not_touch_ground(tmp_path, seed):
    scene = make_scene(tmp_path, degrade(tray_specs(), seed, trans=0.008))
    g = topology.infer(scene, "geometric")
    assert g.pairs() == {("ground", "tray"), ("tray", "cup")}
    assert {e.pair: e.relation for e in g.edges}[("tray", "cup")] == "contains"


@pytest.mark.parametrize("sink_lift", [0.02, 0.0])
def test_geometric_tray_sunk_under_the_floor_still_holds_its_cup(tmp_path, sink_lift):
    """A depth error put the tray 8 cm under the floor and its cup, placed with an error of its own, at the
    floor's height inside it: raised onto the ground as grounding will raise it, the tray contains the cup; the box
    beside the tray stays on the ground. Without the second reading (sink_lift 0) the cup stands on the ground."""
    specs = [("tray", tray_mesh(), make_pose(translation=[0, 0, 0.03 - 0.08])),
             ("cup", box([0.12, 0.1, 0.08]), make_pose(translation=[0.05, 0, 0.045])),
             ("beside", box([0.1, 0.1, 0.1]), make_pose(translation=[0.32, 0, 0.05]))]
    g = topology.infer(make_scene(tmp_path, specs), "geometric", {"sink_lift": sink_lift})
    if sink_lift:
        assert g.pairs() == {("ground", "tray"), ("tray", "cup"), ("ground", "beside")}
        assert {e.pair: e.relation for e in g.edges}[("tray", "cup")] == "contains"
        assert g.meta["raised"] == {"tray": pytest.approx(0.08, abs=1e-6)} and g.meta["reread"] == ["cup"]
    else:
        assert g.pairs() == {("ground", "tray"), ("ground", "cup"), ("ground", "beside")}
        assert "raised" not in g.meta


def hollow_box(extents, wall):
    """A hollow, double-walled box (a reconstruction's shell): the outer box and, facing the sealed cavity, an
    inner box ``wall`` smaller on every side with its faces turned inward."""
    inner = box(np.asarray(extents) - 2 * wall)
    inner.invert()
    return trimesh.util.concatenate([box(extents), inner])


def test_geometric_hollow_box_on_a_book_does_not_contain_it(tmp_path):
    """A hollow box on a book that a depth error pushed 2.5 cm into the box, through its 1 cm bottom wall: the
    book carries the box (the box's cavity floor, facing up above the book's top, is no surface the book touches;
    the graph read the box as containing the book until the topology sampled the outer shell). The same scene with
    a solid box reads the same."""
    for name, mesh in (("hollow", hollow_box([0.2, 0.2, 0.2], 0.01)), ("solid", box([0.2, 0.2, 0.2]))):
        specs = [("book", box([0.25, 0.2, 0.04]), make_pose(translation=[0, 0, 0.02])),
                 ("crate", mesh, make_pose(translation=[0.01, 0, 0.04 - 0.025 + 0.1]))]
        g = topology.infer(make_scene(tmp_path / name, specs), "geometric")
        assert g.pairs() == {("ground", "book"), ("book", "crate")}, (name, g.pairs())
        assert g.order == ["book", "crate"]


def test_geometric_side_by_side_boxes_do_not_support_each_other(tmp_path):
    specs = [("big", box([0.3, 0.3, 0.4]), make_pose(translation=[0, 0, 0.2])),
             ("small", box([0.2, 0.2, 0.2]), make_pose(translation=[0.252, 0, 0.1]))]
    g = topology.infer(make_scene(tmp_path, degrade(specs, 0, trans=0.004)), "geometric")
    assert g.pairs() == {("ground", "big"), ("ground", "small")}


def test_geometric_floating_object_falls_back_to_the_object_below(tmp_path):
    specs = stack_specs()
    specs[2] = ("top", specs[2][1], make_pose(translation=[0, 0.01, 0.55]))  # 15 cm above "middle"
    g = topology.infer(make_scene(tmp_path, specs), "geometric")
    e = [e for e in g.edges if e.target == "top"]
    assert [x.source for x in e] == ["middle"] and e[0].confidence == pytest.approx(0.2)


def test_geometric_is_deterministic_and_fast(tmp_path):
    specs = [("slab", box([1.2, 0.8, 0.05]), make_pose(translation=[0, 0, 0.025]))]
    gt = {("ground", "slab")}
    for s in range(3):
        below, z = "slab", 0.05
        for k in range(3):
            name, e = f"s{s}{k}", 0.2 - 0.04 * k
            specs.append((name, box([e, e, 0.1]), make_pose(translation=[-0.35 + 0.35 * s, 0, z + 0.05])))
            gt.add((below, name))
            below, z = name, z + 0.1
    scene = make_scene(tmp_path, degrade(specs, 7, trans=0.01))
    topology.infer(scene, "geometric")  # warm caches (mesh loading)
    t = time.perf_counter()
    g1 = topology.infer(scene, "geometric")
    elapsed = time.perf_counter() - t
    assert g1.pairs() == gt
    assert topology.infer(scene, "geometric").to_dict() == g1.to_dict()
    back = load(save(g1, tmp_path / "geometric.json"), scene_ids=scene.ids)  # meta and all is valid JSON
    assert back.pairs() == gt and back.order == g1.order and back.backend == "geometric"
    assert elapsed < 1.5  # ~0.2 s measured on 2 cores; loose to stay robust on a busy machine


def test_height_backend_is_the_z_topo_baseline(tmp_path):
    scene = make_scene(tmp_path, bridge_specs() + [("cube", box([0.1, 0.1, 0.1]), make_pose(translation=[1, 0, 0.3]))])
    g = topology.infer(scene, "height")
    # a single parent each: the bridge loses one support, the floating cube goes to the ground
    assert len(g.parents("plank")) == 1 and g.parents("plank")[0] in {"left", "right"}
    assert g.parents("cube") == ["ground"]
    mean_z = {o.id: o.world_mesh().vertices[:, 2].mean() for o in scene.objects}
    assert g.order == sorted(scene.ids, key=lambda k: (mean_z[k], k))
    stack = topology.infer(make_scene(tmp_path / "s", stack_specs()), "height")
    assert stack.pairs() == {("ground", "bottom"), ("bottom", "middle"), ("middle", "top")}


def test_hull_offset():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    assert hull_offset(square, np.array([0.5, 0.5]))[0] == pytest.approx(-0.5)
    d, u = hull_offset(square, np.array([2.0, 0.5]))
    assert d == pytest.approx(1.0) and np.allclose(u, [1, 0])
    d, u = hull_offset(np.array([[0, 0], [1, 0]], float), np.array([0.5, 0.3]))  # a segment
    assert d == pytest.approx(0.3) and np.allclose(u, [0, 1])


# ---------------------------------------------------------------- metrics

def test_edge_scores_by_hand():
    gt = [("ground", "a"), ("a", "b"), ("a", "c")]
    pred = [("ground", "a"), ("a", "b"), ("b", "c"), ("ground", "c")]
    s = edge_scores(pred, gt)
    assert (s.tp, s.fp, s.fn) == (2, 2, 1)
    assert s.precision == pytest.approx(0.5) and s.recall == pytest.approx(2 / 3)
    assert s.f1 == pytest.approx(2 * 0.5 * (2 / 3) / (0.5 + 2 / 3))


def test_relation_counts_by_hand(tmp_path):
    from phiscene.metrics.topology import relation_counts
    from phiscene.tables import topology_table

    gt = [SupportEdge("ground", "a"), SupportEdge("a", "b", "leans_on"), SupportEdge("ground", "b"),
          SupportEdge("a", "c", "contains")]
    pred = [SupportEdge("ground", "a"), SupportEdge("a", "b"), SupportEdge("ground", "b"),
            SupportEdge("a", "c", "contains"), SupportEdge("b", "c", "leans_on")]  # the last is no GT pair
    assert relation_counts(pred, gt) == (3, 4)
    assert relation_counts([], gt) == (0, 0)
    # pooled over scenes in the table: 3 of 4 here, 1 of 1 in a second scene
    objs = ["a", "b", "c"]
    paths = [save(SupportGraph(objs, pred), tmp_path / "p0.json"),
             save(SupportGraph(objs, [SupportEdge("ground", "a"), SupportEdge("ground", "b"),
                                      SupportEdge("ground", "c")]), tmp_path / "p1.json")]
    gts = [save(SupportGraph(objs, gt), tmp_path / "g0.json"),
           save(SupportGraph(objs, [SupportEdge("ground", "a"), SupportEdge("a", "b"), SupportEdge("b", "c")]),
                tmp_path / "g1.json")]
    assert topology_table({"x": paths}, gts).loc["x", "relation_acc"] == pytest.approx(4 / 5)


def test_edge_scores_empty_sets():
    assert edge_scores([], []).to_dict() == {"tp": 0, "fp": 0, "fn": 0, "precision": 1.0, "recall": 1.0, "f1": 1.0}
    s = edge_scores([], [("ground", "a")])
    assert (s.precision, s.recall, s.f1) == (0.0, 0.0, 0.0)
    s = edge_scores([("ground", "a")], [])
    assert (s.precision, s.recall, s.f1) == (0.0, 0.0, 0.0)


def test_micro_and_macro_scores():
    g1 = SupportGraph(["a"], [SupportEdge("ground", "a", "leans_on", 0.1)])  # relation ignored
    preds = [g1, [("ground", "a"), ("ground", "b")]]
    gts = [[{"from": "ground", "to": "a"}], [("ground", "a"), ("a", "b"), ("ground", "c")]]
    micro = micro_scores(preds, gts)
    assert (micro.tp, micro.fp, micro.fn) == (2, 1, 2)
    assert micro.precision == pytest.approx(2 / 3) and micro.recall == pytest.approx(0.5)
    macro = macro_scores(preds, gts)
    assert macro["precision"] == pytest.approx((1 + 0.5) / 2) and macro["recall"] == pytest.approx((1 + 1 / 3) / 2)
    with pytest.raises(ValueError):
        micro_scores(preds, gts[:1])


def test_file_scores(tmp_path):
    gt = write_topology(tmp_path / "gt.json", ["ground", "a", "b"], [("ground", "a", 1.0), ("a", "b", 1.0)])
    pred = save(SupportGraph(["a", "b"], [SupportEdge("ground", "a"), SupportEdge("ground", "b")]),
                tmp_path / "pred.json")
    s = file_scores(pred, gt)
    assert (s.tp, s.fp, s.fn) == (1, 1, 1)
    other = write_topology(tmp_path / "other.json", ["ground", "a"], [("ground", "a", 1.0)])
    with pytest.raises(InputError, match="missing scene objects"):
        file_scores(other, gt)


# ---------------------------------------------------------------- topology + assembly end to end

def _ground_with_topology(tmp_path, scene):
    from phiscene.assembly import AssemblyParams, ground_scene
    from phiscene.proxies import ProxyParams, scene_proxies
    from phiscene.sim.settings import SimSettings

    g = topology.infer(scene, "geometric")
    cache = tmp_path / "cache"
    proxies = scene_proxies(scene, ProxyParams(backend="convex"), cache)
    out, rec = ground_scene(scene, g.order, proxies, AssemblyParams(), SimSettings(), cache)
    return g, out, rec


def _tilt_deg(pose):
    """Angle (deg) between the object's local z axis and the world z axis."""
    return math.degrees(math.acos(np.clip(pose[2, 2] / np.linalg.norm(pose[:3, 2]), -1, 1)))


@pytest.mark.parametrize("seed", [0, 1])
def test_leaning_plank_stays_leaning_after_assembly(tmp_path, seed):
    # oracle: a plank at 25 deg against a wall with friction 0.8 is statically stable (tan 25 deg < 2 mu),
    # so grounding must keep it leaning on the wall, not lay it flat or push it away
    scene = make_scene(tmp_path, degrade(lean_specs(25.0), seed, trans=0.01, rot_deg=1.0))
    g, out, rec = _ground_with_topology(tmp_path, scene)
    assert "wall" in g.parents("plank") and rec["objects"]["plank"]["settled"] is True
    tilt_before, tilt_after = _tilt_deg(scene.get("plank").pose), _tilt_deg(out.get("plank").pose)
    assert abs(tilt_after - tilt_before) < 3.0 and tilt_after > 15.0
    plank, wall = out.get("plank").world_mesh(), out.get("wall").world_mesh()
    from phiscene.sdf import signed_distance

    gap = signed_distance(wall, plank.vertices).min()  # the plank's top edge against the wall face
    assert -1e-3 < gap < 6e-3  # touching (within the SDF clearance eps and settling), not penetrating
    assert plank.bounds[0, 2] == pytest.approx(0.0, abs=2e-3)  # and standing on the ground


@pytest.mark.parametrize("seed", [0, 1])
def test_bridge_keeps_two_parents_after_assembly(tmp_path, seed):
    scene = make_scene(tmp_path, degrade(bridge_specs(), seed, trans=0.01, rot_deg=1.0))
    g, out, rec = _ground_with_topology(tmp_path, scene)
    assert sorted(g.parents("plank")) == ["left", "right"] and g.order[-1] == "plank"
    assert all(r["settled"] for r in rec["objects"].values())
    plank = out.get("plank").world_mesh()
    tops = [out.get(s).world_mesh().bounds[1, 2] for s in ("left", "right")]
    # the plank rests on both supports: its bottom is at the higher support top, and it stays level
    assert plank.bounds[0, 2] == pytest.approx(max(tops), abs=2e-3)
    assert _tilt_deg(out.get("plank").pose) < 1.0


# ---------------------------------------------------------------- floor furniture prior

def test_head_noun_of_descriptions():
    from phiscene.topology.words import head_noun, names_furniture

    assert head_noun("white and gold table lamp on nightstand") == "lamp"
    assert head_noun("wooden chair 87 cm") == "chair"
    assert head_noun("wooden cabinet partially visible in the bottom left") == "cabinet"
    assert names_furniture("white oval table") and names_furniture("light wood nightstand")
    assert not names_furniture("desk lamp") and not names_furniture("vase on the table")
    assert names_furniture("white shelf 1.0 m") and not names_furniture("wooden wall-mounted shelf 54 cm")


def table_over_chairs(root, table_description, lift=0.06):
    """A table (0.04 m top on four legs cut ``lift`` above the floor) over two chair-height boxes 1 cm under its top."""
    legs = [box([0.04, 0.04, 0.70 - lift]).apply_translation([x, y, (0.70 + lift) / 2 - 0.72])
            for x in (-0.48, 0.48) for y in (-0.28, 0.28)]
    table = trimesh.util.concatenate([box([1.0, 0.6, 0.04])] + legs)
    specs = [("table", table, make_pose(translation=[0, 0, 0.72])),
             ("chair_a", box([0.3, 0.3, 0.69]), make_pose(translation=[-0.2, 0, 0.345])),
             ("chair_b", box([0.3, 0.3, 0.69]), make_pose(translation=[0.2, 0, 0.345]))]
    scene = make_scene(root, specs)
    descriptions = {"table": table_description, "chair_a": "wooden chair", "chair_b": "wooden chair"}
    return Scene([SceneObject(o.id, o.mesh_path, o.pose, description=descriptions[o.id]) for o in scene.objects])


@pytest.mark.parametrize("description, on_floor", [("white oval table", True), ("grey shelf 97 cm", True),
                                                   ("wooden crate", False)])
def test_floor_furniture_stands_on_the_floor_not_on_the_chairs_under_it(tmp_path, description, on_floor):
    from phiscene.topology.geometric import GeometricParams, infer

    scene = table_over_chairs(tmp_path, description)
    # the geometry alone: the top's underside lies 1 cm over both boxes, the cut legs 6 cm over the floor
    plain = {e.source for e in infer(scene, GeometricParams(floor_reach=0.0)).edges if e.target == "table"}
    assert plain == {"chair_a", "chair_b"}
    graph = infer(scene, GeometricParams())
    into_table = {e.source for e in graph.edges if e.target == "table"}
    assert into_table == ({GROUND} if on_floor else {"chair_a", "chair_b"})
    assert graph.meta["floor_standing"] == (["table"] if on_floor else [])
    # the chairs stand on the floor either way
    assert {e.source for e in graph.edges if e.target in ("chair_a", "chair_b")} == {GROUND}


def test_floor_prior_leaves_furniture_that_is_high_up(tmp_path):
    from phiscene.topology.geometric import GeometricParams, infer

    # a stool standing on a table, 0.75 m above the floor: the table holds it whatever its name
    specs = [("table", box([1.0, 0.6, 0.75]), make_pose(translation=[0, 0, 0.375])),
             ("stool", box([0.3, 0.3, 0.4]), make_pose(translation=[0, 0, 0.95]))]
    scene = make_scene(tmp_path, specs)
    scene = Scene([SceneObject(o.id, o.mesh_path, o.pose, description=f"wooden {o.id}") for o in scene.objects])
    graph = infer(scene, GeometricParams())
    assert {e.source for e in graph.edges if e.target == "stool"} == {"table"}
    assert graph.meta["floor_standing"] == []


def test_geometric_fallback_passes_over_what_the_object_carries(tmp_path):
    # a board across two boxes, its bottom 10 cm above their tops (beyond contact), a plate sunk 1 cm into it from
    # above: the plate's top is the first upward surface straight below the board's lowest point + tolerance, but
    # the board carries it. Taken, that edge closes a cycle, and breaking it leaves the board on nothing but the
    # ground; passed over, the next surface below is a box's top
    bb = 0.25  # the board's bottom
    scene = make_scene(tmp_path, [
        ("box_a", box([0.2, 0.2, 0.15]), make_pose(translation=[-0.3, 0.0, 0.075])),
        ("box_b", box([0.2, 0.2, 0.15]), make_pose(translation=[0.3, 0.0, 0.075])),
        ("board", box([0.9, 0.25, 0.03]), make_pose(translation=[0.0, 0.0, bb + 0.015])),
        ("plate", box([0.15, 0.15, 0.02]), make_pose(translation=[0.0, 0.0, bb + 0.03]))])
    g = topology.infer(scene, "geometric")
    assert g.parents("board") == ["box_a"]  # the two tops are level: the first by name
    assert g.parents("plate") == ["board"] and g.dropped_edges == []
    assert g.meta["objects"]["board"]["passed_over"] == ["plate"]
