"""Walls estimated from the panels hanging on them (phiscene.walls): analytic planes, push-back, rejection, and a
plank that leans on an estimated wall as it would on a given one."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from rest3d_fixture import write_scene
from scenes import PLANK, convex_proxies, leaning_pose

from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.io.rest3d import import_rest3d
from phiscene.meshes import save_mesh
from phiscene.scene import Plane, Scene, SceneObject, load_scene
from phiscene.sim.settings import SimSettings
from phiscene.topology.attached import attached_ids
from phiscene.transforms import make_pose
from phiscene.walls import WallParams, estimate_walls


def heading(deg: float) -> np.ndarray:
    """Rotation (4, 4) about z by ``deg``."""
    return trimesh.transformations.rotation_matrix(np.radians(deg), [0, 0, 1])


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    root = tmp_path_factory.mktemp("walls")
    shapes = {"poster": trimesh.creation.box((0.01, 0.6, 0.8)), "painting": trimesh.creation.box((0.02, 0.4, 0.3)),
              "cabinet": trimesh.creation.box((0.4, 0.8, 0.9)), "plank": trimesh.creation.box(PLANK)}
    return {n: save_mesh(m, root / f"{n}.obj").resolve() for n, m in shapes.items()}


def obj(meshes, oid: str, shape: str, pose: np.ndarray, description: str | None = None) -> SceneObject:
    return SceneObject(oid, meshes[shape], pose, description or shape)


def poster_at(meshes, oid: str, back_x: float, y: float = 0.0, z: float = 1.5, turn: float = 0.0) -> SceneObject:
    """A poster on the wall x = ``back_x`` (turned by ``turn`` deg about the vertical through the origin)."""
    return obj(meshes, oid, "poster", heading(turn) @ make_pose(translation=(back_x + 0.005, y, z)),
               "paper poster on the wall")


def cabinet_at(meshes, back_x: float, y: float = 1.0) -> SceneObject:
    return obj(meshes, "cabinet", "cabinet", make_pose(translation=(back_x + 0.2, y, 0.45)), "wooden cabinet")


def test_wall_is_the_plane_of_the_poster_back_facing_the_room(meshes):
    # a poster turned 30 deg about the vertical, a cabinet in front of it: the wall is the plane through the poster's
    # back, its normal the poster's thin axis turned towards the cabinet
    scene = Scene([poster_at(meshes, "poster", 0.0, turn=30.0), cabinet_at(meshes, 0.5, 0.0)])
    est = estimate_walls(scene)
    assert len(est.planes) == 1
    wall = est.planes[0]
    expected = heading(30.0)[:3, :3] @ [1.0, 0.0, 0.0]
    assert wall.kind == "wall" and wall.estimated and np.allclose(wall.normal, expected, atol=1e-6)
    assert wall.offset == pytest.approx(0.0, abs=1e-6)  # the back x = 0 turned about the origin: through it
    assert est.record["walls"][0]["evidence"] == ["poster"] and est.record["walls"][0]["pushed_back"] == 0.0


def test_furniture_behind_the_poster_pushes_the_wall_back_within_the_bound(meshes):
    # a depth error put the cabinet 10 cm behind the poster's back: the wall goes behind the cabinet, so nothing
    # starts inside it
    est = estimate_walls(Scene([poster_at(meshes, "poster", 0.0), cabinet_at(meshes, -0.1)]))
    (wall,) = est.planes
    assert np.allclose(wall.normal, (1.0, 0.0, 0.0), atol=1e-9) and wall.offset == pytest.approx(0.1, abs=1e-6)
    assert est.record["walls"][0]["pushed_by"] == "cabinet"
    assert est.record["walls"][0]["pushed_back"] == pytest.approx(0.1, abs=1e-6)
    # 40 cm behind (the camera at x = 3 tells the room's side): the poster is not on a wall the scene stands
    # against; no wall, and the record says why
    deep = Scene([poster_at(meshes, "poster", 0.0), cabinet_at(meshes, -0.4)])
    eye = np.array([3.0, 0.0, 1.5])
    far = estimate_walls(deep, eye=eye)
    assert far.planes == [] and "cabinet" in far.record["rejected"][0]["why"]
    assert estimate_walls(deep, WallParams(max_behind=0.5), eye=eye).planes[0].offset == pytest.approx(0.4, abs=1e-6)


def test_panels_on_one_wall_make_one_plane_and_perpendicular_walls_two(meshes):
    # two posters 4 deg apart on the wall x = 0 (one 5 cm proud of it), a painting on the wall y = 2 facing -y
    scene = Scene([poster_at(meshes, "a", 0.0, y=-0.5), poster_at(meshes, "b", 0.05, y=0.8),
                   obj(meshes, "c", "painting", make_pose(heading(90.0)[:3, :3], (1.0, 2.0 - 0.01, 1.5)),
                       "framed painting on the wall"),
                   cabinet_at(meshes, 0.5)])
    est = estimate_walls(scene)
    assert [w["evidence"] for w in est.record["walls"]] == [["a", "b"], ["c"]]
    x_wall, y_wall = est.planes
    assert np.allclose(x_wall.normal, (1, 0, 0), atol=1e-9) and x_wall.offset == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(y_wall.normal, (0, -1, 0), atol=1e-9) and y_wall.offset == pytest.approx(2.0, abs=1e-6)
    # merge_gap 2 cm: the proud poster is a wall of its own, in front of the first one
    split = estimate_walls(scene, WallParams(merge_gap=0.02))
    assert len(split.planes) == 3


def test_given_walls_are_kept_and_estimation_can_be_off(meshes):
    scene = Scene([poster_at(meshes, "poster", 0.0), cabinet_at(meshes, 0.5)])
    given = Scene(scene.objects, structure=[Plane("wall_0", "wall", (0.0, 1.0, 0.0), 3.0)])
    assert estimate_walls(given).planes == []
    assert estimate_walls(scene, WallParams(enabled=False)).planes == []
    # a board standing on the floor is not evidence (nothing is attached)
    floor_board = Scene([obj(meshes, "board", "poster", make_pose(translation=(0.0, 0.0, 0.4)), "poster")])
    assert estimate_walls(floor_board).planes == []


@pytest.mark.parametrize("evidence", ["poster", "words", None])
def test_plank_leans_on_the_wall_its_poster_or_its_description_stands_for(meshes, tmp_path, evidence):
    # the ladder of tests/test_clutter.py, with no given wall. Its only evidence: a poster on the wall x = 0, or the
    # plank's description ("leaning against the wall"; the plank's top leans towards -x). Estimated, the wall keeps
    # the plank leaning (statics: mu_ground >= tan(30 deg) / 2 = 0.29; pybullet combines 0.8 * 0.8 = 0.64) and is
    # its supporter; without evidence the plank falls flat
    from phiscene import topology

    sim = SimSettings()
    assert sim.friction ** 2 >= np.tan(np.radians(30.0)) / 2
    # the poster's top 3 deg proud of its wall, its back's lowest point on x = 0 (made flush with a given wall, it
    # would turn 3 deg; fixed to the one it stands for, it stays as put)
    R = trimesh.transformations.rotation_matrix(np.radians(-3.0), [0, 1, 0])[:3, :3]
    back = (trimesh.creation.box((0.01, 0.6, 0.8)).vertices @ R.T)[:, 0].min()
    poster = obj(meshes, "poster", "poster", make_pose(R, (-back, 0.0, 1.6)),
                 "paper poster on the wall" if evidence == "poster" else "paper poster")
    plank = obj(meshes, "plank", "plank", leaning_pose(PLANK, 60.0),
                "wooden plank leaning against the wall" if evidence == "words" else "wooden plank")
    scene = Scene([poster, plank] if evidence == "poster" else [plank])
    est = estimate_walls(scene)
    assert [w["evidence"] for w in est.record["walls"]] == ([[evidence if evidence == "poster" else "plank"]]
                                                            if evidence else [])
    if evidence:
        assert np.allclose(est.planes[0].normal, (1, 0, 0), atol=1e-9)
        assert est.planes[0].offset == pytest.approx(0.0, abs=1e-9)
    scene = Scene(scene.objects, structure=est.planes)
    graph = topology.infer(scene, "geometric", {})
    assert sorted(graph.parents("plank")) == (["ground", "wall_0"] if evidence else ["ground"])
    params = AssemblyParams.from_dict({"faithful": {"enabled": True}})
    out, record = ground_scene(scene, graph.order, convex_proxies(scene, tmp_path), params, sim, tmp_path,
                               graph=graph, attached=attached_ids(graph, holders=True))
    cert = record["objects"]["plank"]["certificate"]
    if evidence == "poster":
        assert attached_ids(graph, holders=True) == {"poster": "wall_0"}
        assert record["objects"]["poster"]["settle_remedy"] == "attached"
        assert np.array_equal(out.get("poster").pose, scene.get("poster").pose)  # kept exactly where it was put
    if evidence:
        assert cert["settled"] and cert["supporters_kept"] and cert["rotation_change"] < 1.0
        assert cert["displacement"] < 0.01
    else:
        assert cert["rotation_change"] > 20.0


def test_a_board_standing_against_the_wall_gives_the_wall_behind_it(meshes):
    # upright (no lean), so its thin axis turned towards the camera is the wall's normal; the wall touches its back
    board = obj(meshes, "board", "poster", make_pose(translation=(-0.995, 0.0, 0.4)), "white board against the wall")
    est = estimate_walls(Scene([board]), eye=np.array([3.0, 0.0, 1.5]))
    assert np.allclose(est.planes[0].normal, (1, 0, 0), atol=1e-9)
    assert est.planes[0].offset == pytest.approx(1.0, abs=1e-9)
    assert estimate_walls(Scene([replace(board, description="white board")])).planes == []


def test_import_writes_the_estimated_wall_of_the_fixture_poster(tmp_path):
    # the REST3D-layout fixture: a poster on the wall z = -1 (y up) behind a table, in a camera frame tilted 12 and
    # 4 deg. Imported, the wall is the levelled image of the poster's back plane, facing the camera
    tilt = write_scene(tmp_path / "data", "scene_a", tilt_deg=(12.0, 4.0))
    scene = import_rest3d(tmp_path / "data", "scene_a", tmp_path / "out")
    record = json.loads((tmp_path / "out" / "import.json").read_text())
    T = np.asarray(record["transform"])
    (wall,) = scene.structure
    normal = T[:3, :3] @ tilt @ [0.0, 0.0, 1.0]  # the poster's normal, y-up source -> levelled world
    assert np.degrees(np.arccos(np.clip(np.dot(wall.normal, normal), -1, 1))) < 1.0
    poster = scene.get("paper_poster_on_the_wall_000").world_mesh()
    assert float(wall.signed_distance(poster.vertices).min()) == pytest.approx(0.0, abs=1e-6)
    for o in scene.objects:  # nothing starts inside it
        assert float(wall.signed_distance(o.world_mesh().vertices).min()) >= -1e-6
    assert record["walls"]["walls"][0]["evidence"] == ["paper_poster_on_the_wall_000"]
    assert load_scene(tmp_path / "out" / "initial" / "scene.json").structure == scene.structure


def test_a_peer_result_in_its_own_frame_does_not_take_our_walls(tmp_path):
    # REST3D's result is in REST3D's frame: our estimated wall (in the levelled input's frame) would be misplaced
    from phiscene.baselines.external import import_external

    write_scene(tmp_path / "data", "scene_a", tilt_deg=(12.0, 4.0))
    write_scene(tmp_path / "data", "scene_a", tilt_deg=(0.0, 0.0), variant="ours")
    initial = import_rest3d(tmp_path / "data", "scene_a", tmp_path / "in")
    assert len(initial.structure) == 1
    out, rec = import_external(tmp_path / "data" / "assets" / "scene_a" / "ours", initial,
                               tmp_path / "out" / "scene.json")
    assert rec["layout"] == "rest3d" and out.structure == []


@pytest.mark.parametrize("described", [True, False])
def test_a_description_against_the_wall_makes_the_touching_wall_a_supporter(meshes, described):
    # the cabinet box (0.4 deep) turned 5 deg about y, its top edge on the wall x = 0: its centre of mass stays over
    # its base, so the geometry alone reads it as standing; its description says it leans on the wall it touches
    from phiscene import topology

    R = trimesh.transformations.rotation_matrix(np.radians(-5.0), [0, 1, 0])[:3, :3]
    v = trimesh.creation.box((0.4, 0.8, 0.9)).vertices @ R.T
    cab = obj(meshes, "cab", "cabinet", make_pose(R, (-v[:, 0].min(), 0.0, -v[:, 2].min())),
              "wooden cabinet leaning against the wall" if described else "wooden cabinet")
    scene = Scene([cab], structure=[Plane("wall_0", "wall", (1.0, 0.0, 0.0), 0.0)])
    graph = topology.infer(scene, "geometric", {})
    assert sorted(graph.parents("cab")) == (["ground", "wall_0"] if described else ["ground"])
    if described:
        (edge,) = [e for e in graph.edges if e.source == "wall_0"]
        assert edge.relation == "leans_on"
