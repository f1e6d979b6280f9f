"""Objects fixed to a wall or the ceiling: decided from geometry and descriptions, kept in place, not drifting."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from phiscene import topology
from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.meshes import save_mesh
from phiscene.metrics.drift import drift_mujoco
from phiscene.metrics.physical import PhysicalParams, contact_validity, physical_metrics
from phiscene.proxies import ProxyParams, scene_proxies
from phiscene.scene import Plane, Scene, SceneObject
from phiscene.sim.settings import SimSettings
from phiscene.topology.attached import AttachedParams, attached_ids, attached_objects, is_fragment, panel_normal
from phiscene.topology.words import head_words, names_fixture, names_structure, says_mounted
from phiscene.transforms import make_pose, rotation_z

SIM = SimSettings()


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """A room corner: a table with a book on it, a poster on the wall, a ceiling lamp, a painting on the table."""
    root = tmp_path_factory.mktemp("attached")
    boxes = {"table": (1.0, 0.6, 0.75), "book": (0.25, 0.18, 0.04), "poster": (0.6, 0.01, 0.8),
             "lamp": (0.3, 0.3, 0.2), "painting": (0.4, 0.03, 0.3), "shelf_poster": (0.5, 0.01, 0.7)}
    mesh = {n: save_mesh(trimesh.creation.box(s), root / f"{n}.obj") for n, s in boxes.items()}
    objs = [
        SceneObject("table", mesh["table"], make_pose(translation=[0, 0, 0.375]), "wooden table"),
        SceneObject("book", mesh["book"], make_pose(translation=[0.2, 0, 0.77]), "a red book"),
        SceneObject("poster", mesh["poster"], make_pose(translation=[0, 0.6, 1.6]), "paper poster on the back wall"),
        SceneObject("lamp", mesh["lamp"], make_pose(translation=[1.5, 0, 2.4]), "lamp hanging from the ceiling"),
        SceneObject("painting", mesh["painting"], make_pose(translation=[-0.3, 0.2, 0.9]), "framed painting"),
        SceneObject("shelf_poster", mesh["shelf_poster"], make_pose(translation=[-1.5, 0.6, 1.2]), "object_7"),
    ]
    return {"scene": Scene(objs), "cache": root / "cache"}


def test_descriptions():
    assert says_mounted("paper poster on the back wall") and says_mounted("brown ceiling fan")
    assert says_mounted("white curtain") and not says_mounted("wooden chair") and not says_mounted("red book")


def test_the_head_of_a_description_ends_at_its_first_preposition():
    assert head_words("wooden chair partially visible behind foreground table (left)") == [
        "wooden", "chair", "partially", "visible"]
    assert head_words("white curtains on left window") == ["white", "curtains"]


def test_fixture_names_are_read_from_the_head_of_the_description():
    assert names_fixture("white curtains on left window") and names_fixture("window_in_middle".replace("_", " "))
    assert not names_fixture("plant on the window sill") and not names_fixture("bench under middle window")
    assert names_fixture("white radiator under middle window")  # on its wall brackets, part of the building
    assert not names_fixture("wooden chair")


def test_a_window_over_a_radiator_and_a_floor_length_curtain_are_attached(tmp_path):
    """Fixtures (the window, the radiator under it, a floor-length curtain) are attached whatever stands under them;
    a plant on the sill under the same window stays free."""
    boxes = {"radiator": (0.8, 0.1, 0.5), "window": (0.8, 0.05, 1.0), "curtain": (0.4, 0.05, 2.2),
             "plant": (0.15, 0.15, 0.2)}
    mesh = {n: save_mesh(trimesh.creation.box(s), tmp_path / f"{n}.obj") for n, s in boxes.items()}
    scene = Scene([
        SceneObject("radiator", mesh["radiator"], make_pose(translation=[0, 0, 0.25]), "white radiator"),
        SceneObject("window", mesh["window"], make_pose(translation=[0, 0, 1.0]), "window in the middle"),
        SceneObject("curtain", mesh["curtain"], make_pose(translation=[1.0, 0, 1.1]), "white curtains on the window"),
        SceneObject("plant", mesh["plant"], make_pose(translation=[0.2, -0.1, 0.6]), "plant on the window sill"),
    ])
    decided = attached_objects(scene)
    assert decided == {"window": "fixture", "curtain": "fixture", "radiator": "fixture"}


def test_panel_at_any_heading_and_not_a_board_lying_flat():
    """The thin axis of a panel is found at any heading (oriented box), and must be horizontal."""
    heading = np.radians(37.0)
    poster = trimesh.creation.box((0.6, 0.01, 0.8)).apply_transform(make_pose(rotation_z(heading), [1.0, 2.0, 1.5]))
    axis = panel_normal(poster, 0.15)
    assert axis is not None
    # the box's thin local y axis, turned by the heading (up to sign)
    assert abs(axis @ [-np.sin(heading), np.cos(heading), 0.0]) == pytest.approx(1.0, abs=1e-6)
    board = trimesh.creation.box((0.6, 0.8, 0.01)).apply_transform(make_pose(rotation_z(heading), [0, 0, 0.9]))
    assert panel_normal(board, 0.15) is None  # thin, but its thin axis is vertical
    assert panel_normal(trimesh.creation.box((0.6, 0.2, 0.8)), 0.15) is None  # not thin


def test_posters_overlapping_on_a_wall_do_not_hold_each_other_up(tmp_path):
    """A poster whose bottom edge overlaps the top of another on the same wall is attached, as is the lower one; a
    thick reconstruction of the lower one (no thin panel) holds nothing up either: it names a wall object."""
    boxes = {"low": (0.3, 0.14, 0.25), "high": (0.3, 0.02, 0.3), "shelf": (0.4, 0.2, 0.02), "vase": (0.1, 0.1, 0.2)}
    mesh = {n: save_mesh(trimesh.creation.box(s), tmp_path / f"{n}.obj") for n, s in boxes.items()}
    turn = rotation_z(np.radians(25.0))
    scene = Scene([
        SceneObject("low", mesh["low"], make_pose(turn, [0.0, 2.0, 0.8]), "black wall poster"),
        # its bottom (0.92 - 0.15 = 0.77) is inside the lower poster (top at 0.925)
        SceneObject("high", mesh["high"], make_pose(turn, [-0.1, 2.05, 1.07]), "red wall poster"),
        # a vase standing on a wall shelf: the shelf holds it (shelves are not wall objects)
        SceneObject("shelf", mesh["shelf"], make_pose(translation=[1.5, 2.0, 1.2]), "wooden shelf on the wall"),
        SceneObject("vase", mesh["vase"], make_pose(translation=[1.5, 2.0, 1.31]), "vase"),
    ])
    decided = attached_objects(scene)
    assert decided == {"low": "description", "high": "description", "shelf": "description"}


def test_the_room_s_own_meshes_are_read_from_the_head_noun():
    assert names_structure("white wall") and names_structure("wooden floor on the left") and names_structure("ceiling")
    assert names_structure("back wall of the room") and names_structure("walls")
    for other in ("wall clock", "floor lamp", "ceiling fan", "round woven basket hanging from ceiling", "wall shelf",
                  "grey carpet on the floor", "plank leaning against the wall"):
        assert not names_structure(other), other


def test_a_wall_mesh_and_a_floor_mesh_stay_put_and_keep_what_they_carry(tmp_path):
    """A reconstruction that meshes its floor and a wall as objects: both are attached and kept exactly where they
    are, the wall reaching through the floor mesh and under the ground (a free wall mesh falls across the room; an
    attached one would be lifted out of the ground and cleared of the floor mesh); the poster touching the wall mesh
    is still attached (the wall holds it only from below, and nothing lies under the poster); the box standing on
    the floor mesh stays free and rests on it."""
    boxes = {"floor": (3.0, 3.0, 0.05), "wall": (3.0, 0.05, 2.5), "poster": (0.6, 0.01, 0.8), "box": (0.3, 0.3, 0.3)}
    mesh = {n: save_mesh(trimesh.creation.box(s), tmp_path / f"{n}.obj") for n, s in boxes.items()}
    scene = Scene([
        SceneObject("floor", mesh["floor"], make_pose(translation=[0, 0, 0.025]), "wooden floor"),
        # the wall mesh reaches through the floor mesh and 5 cm under the ground, as layouts' walls do
        SceneObject("wall", mesh["wall"], make_pose(translation=[0, 1.525, 1.2]), "white wall"),
        SceneObject("poster", mesh["poster"], make_pose(translation=[0.5, 1.495, 1.5]), "paper poster"),
        SceneObject("box", mesh["box"], make_pose(translation=[-0.5, 0.0, 0.2 + 0.03]), "cardboard box"),
    ])
    assert attached_objects(scene) == {"floor": "structure", "wall": "structure", "poster": "description"}
    cache = tmp_path / "cache"
    proxies = scene_proxies(scene, ProxyParams(backend="convex"), cache)
    g = topology.infer(scene, "geometric", {})
    assert attached_ids(g) == ["floor", "wall", "poster"] and g.parents("box") == ["floor"]
    fixed = attached_ids(g, holders=True)
    faithful = AssemblyParams.from_dict({"faithful": {"enabled": True}})  # phi_scene's: flushes and clears fixtures
    out, record = ground_scene(scene, g.order, proxies, faithful, SIM, cache, graph=g, attached=fixed)
    for oid in ("floor", "wall", "poster"):  # never lifted out of the ground or cleared of each other
        np.testing.assert_array_equal(out.get(oid).pose, scene.get(oid).pose)
    # the box comes down the 3 cm onto the floor mesh's top (z = 0.05): its bottom within a millimetre below (the
    # simulator's contact) and the clearance above it
    bottom, top = out.get("box").world_mesh().bounds[0, 2], out.get("floor").world_mesh().bounds[1, 2]
    assert top == pytest.approx(0.05) and top - 0.001 <= bottom <= top + 0.006
    assert record["objects"]["box"]["settled"]
    # penetration: the room's meshes are not measured against the ground or each other; read as any attached
    # objects, the wall is 5 cm into the ground and the floor slab reaches 5 cm into the wall
    per = contact_validity(out, PhysicalParams(samples=512))["objects"]
    assert per["wall"]["pen_depth"] < 1e-4 and per["floor"]["pen_depth"] < 1e-4  # the poster and box touch them
    unnamed = out.with_poses({})
    for k, o in enumerate(unnamed.objects):
        o.description = f"object {k}"
    per = contact_validity(unnamed, PhysicalParams(samples=512))["objects"]
    assert per["wall"]["pen_depth"] == pytest.approx(0.05, abs=0.005)


def test_decision_from_geometry_and_description(room):
    decided = attached_objects(room["scene"])
    # poster: description + no support; lamp: description; shelf_poster: a thin vertical panel high up, no name
    assert decided == {"poster": "description", "lamp": "description", "shelf_poster": "panel"}
    # the painting stands on the table (held from below) and the book lies on it: both stay free
    assert "painting" not in decided and "book" not in decided
    assert attached_objects(room["scene"], AttachedParams(enabled=False)) == {}


def test_graph_gets_attached_edges_for_every_inferring_backend(room):
    for backend in ("geometric", "height"):
        g = topology.infer(room["scene"], backend, {})
        assert attached_ids(g) == ["poster", "lamp", "shelf_poster"]
        assert g.parents("poster") == ["ground"]
        assert set(g.order) == set(room["scene"].ids)


def test_poster_stays_put_and_is_left_out_of_drift(room):
    scene = room["scene"]
    proxies = scene_proxies(scene, ProxyParams(backend="convex"), room["cache"])
    g = topology.infer(scene, "geometric", {})
    fixed = {oid: "ground" for oid in attached_ids(g)}
    out, record = ground_scene(scene, g.order, proxies, AssemblyParams(), SIM, room["cache"], attached=fixed)
    for oid in fixed:  # exactly where they were, and marked
        np.testing.assert_array_equal(out.get(oid).pose, scene.get(oid).pose)
        assert out.get(oid).attached == "ground"
        assert record["objects"][oid]["settle_remedy"] == "attached"
    # without the attachment a gravity-only grounding drops the poster to the floor (what the issue reports)
    dropped, _ = ground_scene(scene, g.order, proxies, AssemblyParams(), SIM, room["cache"])
    assert dropped.get("poster").world_mesh().bounds[0, 2] < 0.05
    # drift: attached objects are static colliders and not in the means
    phys = physical_metrics(out, proxies, PhysicalParams(samples=256), SIM, room["cache"])
    assert phys["objects"]["poster"]["attached"] == "ground" and phys["objects"]["poster"]["float_dist"] is None
    free = [v["drift_trans"] for k, v in phys["objects"].items() if k not in fixed]
    assert phys["drift_trans"] == pytest.approx(float(np.mean(free)))
    mj = drift_mujoco(out, proxies, PhysicalParams(samples=256), SIM)
    assert mj["objects"]["lamp"]["attached"] == "ground" and mj["drift_trans"] < 0.01


def test_fragments_of_floor_furniture_are_kept_where_they_are(tmp_path):
    """The visible top of a chair behind a table and a cabinet cut off by the photo's frame float higher above the
    floor than they are tall: each is a fragment whose unseen part stands on the ground (reason ``partial``, held
    by the ground, not the wall beside it). So is a chair 18 cm up whose description says it is seen only in part;
    the same chair described as a whole, a whole chair lifted by less than its height, a fragment-sized box that is
    not furniture, and a chair fragment only 20 cm up are grounded as usual."""
    boxes = {"back": (0.4, 0.1, 0.15), "cabinet": (0.4, 0.4, 0.2), "laptop": (0.3, 0.2, 0.02),
             "chair": (0.45, 0.45, 0.85), "box": (0.3, 0.3, 0.15), "low": (0.4, 0.1, 0.15), "seat": (0.4, 0.4, 0.25)}
    mesh = {n: save_mesh(trimesh.creation.box(s), tmp_path / f"{n}.obj") for n, s in boxes.items()}
    scene = Scene([
        SceneObject("back", mesh["back"], make_pose(translation=[0, 0, 0.40 + 0.075]), "wooden chair in the back"),
        SceneObject("cabinet", mesh["cabinet"], make_pose(translation=[1.5, 0.78, 0.35 + 0.1]),
                    "wooden cabinet partially visible in the bottom left"),
        SceneObject("laptop", mesh["laptop"], make_pose(translation=[1.5, 0.78, 0.56]), "black laptop on the cabinet"),
        SceneObject("chair", mesh["chair"], make_pose(translation=[-1.5, 0, 0.35 + 0.425]), "wooden chair"),
        SceneObject("box", mesh["box"], make_pose(translation=[3.0, 0, 0.40 + 0.075]), "cardboard box"),
        SceneObject("low", mesh["low"], make_pose(translation=[-3.0, 0, 0.20 + 0.075]), "chair in the front"),
        # 18 cm up and taller than that: a fragment only because its description says it is seen in part
        SceneObject("seen", mesh["seat"], make_pose(translation=[0, 3.0, 0.18 + 0.125]),
                    "wooden chair partially visible behind the table (left)"),
        SceneObject("whole", mesh["seat"], make_pose(translation=[0, -3.0, 0.18 + 0.125]), "wooden chair (left)"),
    ], structure=[Plane("wall", "wall", (0.0, -1.0, 0.0), 1.0)])  # the wall y = 1, 2 cm behind the cabinet
    decided = attached_objects(scene)
    assert decided == {"back": "partial", "cabinet": "partial", "seen": "partial"}
    params = AttachedParams()
    assert is_fragment("chair", 0.4, 0.55, 0.0, params) and not is_fragment("chair", 0.4, 0.85, 0.0, params)
    assert not is_fragment("chair partially visible", 0.05, 0.5, 0.0, params)  # within partial_gap: grounded
    assert not attached_objects(scene, AttachedParams(partial=False))
    g = topology.infer(scene, "geometric", {})
    assert attached_ids(g, holders=True) == {"back": "ground", "cabinet": "ground", "seen": "ground"}
    assert g.parents("laptop") == ["cabinet"]
    proxies = scene_proxies(scene, ProxyParams(backend="convex"), tmp_path / "cache")
    fixed = attached_ids(g, holders=True)
    out, _ = ground_scene(scene, g.order, proxies, AssemblyParams(), SIM, tmp_path / "cache", attached=fixed)
    for oid in fixed:
        np.testing.assert_array_equal(out.get(oid).pose, scene.get(oid).pose)
    # the laptop stays on the cabinet (within the contact clearance), the whole chair lands on the floor
    assert out.get("laptop").world_mesh().bounds[0, 2] == pytest.approx(0.55, abs=0.005)
    assert out.get("chair").world_mesh().bounds[0, 2] == pytest.approx(0.0, abs=0.005)


def test_an_attached_curtain_through_the_floor_does_not_lower_the_drift_ground(tmp_path):
    """The drift tests release a scene on a ground right below it; an attached curtain reconstructed 6 cm through
    the floor is static there and must not set that ground: a box resting on the floor stays put in both
    simulators (with the curtain setting it, the box would fall 6 cm)."""
    boxes = {"box": (0.3, 0.3, 0.3), "curtain": (1.0, 0.02, 2.0)}
    mesh = {n: save_mesh(trimesh.creation.box(s), tmp_path / f"{n}.obj") for n, s in boxes.items()}
    scene = Scene([SceneObject("box", mesh["box"], make_pose(translation=[0, 0, 0.15]), "cardboard box"),
                   SceneObject("curtain", mesh["curtain"], make_pose(translation=[1.0, 1.0, 1.0 - 0.06]),
                               "white curtain", attached="ground")])
    proxies = scene_proxies(scene, ProxyParams(backend="convex"), tmp_path / "cache")
    params = PhysicalParams(samples=256)
    phys = physical_metrics(scene, proxies, params, SIM, tmp_path / "cache")
    assert phys["ground_below"] == pytest.approx(0.0, abs=1e-9)
    assert phys["objects"]["box"]["drift_trans"] < 1e-3
    mj = drift_mujoco(scene, proxies, params, SIM)
    assert mj["ground_below"] == pytest.approx(0.0, abs=1e-9) and mj["objects"]["box"]["drift_trans"] < 1e-3
