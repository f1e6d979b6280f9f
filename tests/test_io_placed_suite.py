"""A folder of placed-mesh scenes as a workflow suite (`source: {kind: placed}`, phiscene.io.placed_suite)."""

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from phiscene.errors import InputError
from phiscene.io.placed_suite import read_camera, run_placed_scene, scene_ids
from phiscene.io.rest3d import import_rest3d
from phiscene.scene import load_scene
from tests.rest3d_fixture import write_scene


def _as_placed(rest3d_root: Path, scene: str, out: Path, camera: bool = True) -> None:
    """The fixture's REST3D scene written in the placed layout: its meshes, frame 0's placements as
    placements.json and the page's camera as camera.json."""
    folder = rest3d_root / "assets" / scene / "sam3d"
    sim = json.loads((folder / "simulation.json").read_text())
    out.mkdir(parents=True)
    for f in (folder / "meshes").iterdir():
        shutil.copy(f, out / f.name)
    (out / "placements.json").write_text(json.dumps(
        {a: {"pos": sim["tracks"][a]["pos"][0], "quat": sim["tracks"][a]["quat"][0]} for a in sim["actors"]}))
    if camera:
        cam = sim["camera"]
        (out / "camera.json").write_text(json.dumps({"eye": cam["position"], "target": cam["target"],
                                                     "fov_y_deg": cam["fov"]}))


def test_a_placed_scene_imports_as_its_rest3d_twin(tmp_path):
    """The same meshes, placements and camera in both layouts: the same levelled scene (poses to 1e-9 m), the same
    camera and walls; without camera.json, no reference camera."""
    write_scene(tmp_path / "r3d", "s", (14.0, -6.0))
    _as_placed(tmp_path / "r3d", "s", tmp_path / "root" / "withcam")
    _as_placed(tmp_path / "r3d", "s", tmp_path / "root" / "nocam", camera=False)
    assert scene_ids(tmp_path / "root") == ["nocam", "withcam"]
    twin = import_rest3d(tmp_path / "r3d", "s", tmp_path / "twin")
    source = {"kind": "placed", "root": str(tmp_path / "root")}
    placed = run_placed_scene(source, "withcam", tmp_path / "placed")
    assert sorted(placed.ids) == sorted(twin.ids)
    for o in twin.objects:
        assert np.allclose(placed.get(o.id).pose, o.pose, atol=1e-9)
    cams = [json.loads((tmp_path / d / "reference" / "camera.json").read_text()) for d in ("twin", "placed")]
    assert np.allclose(cams[0]["world_to_camera"], cams[1]["world_to_camera"], atol=1e-9)
    assert [p.id for p in placed.structure] == [p.id for p in twin.structure] and placed.structure
    bare = run_placed_scene(source, "nocam", tmp_path / "bare")
    assert not (tmp_path / "bare" / "reference" / "camera.json").exists()
    for o in twin.objects:  # levelled the same, only the heading (a turn about z) is not the camera's
        assert np.allclose(bare.get(o.id).world_mesh().bounds[:, 2], o.world_mesh().bounds[:, 2], atol=1e-6)


def test_bad_folders_and_cameras_are_named(tmp_path):
    with pytest.raises(InputError, match="placed-mesh scenes not found"):
        scene_ids(tmp_path / "absent")
    (tmp_path / "root" / "notes").mkdir(parents=True)
    with pytest.raises(InputError, match=r"root: no scenes"):
        scene_ids(tmp_path / "root")
    (tmp_path / "root" / "my-scene").mkdir()
    (tmp_path / "root" / "my-scene" / "box.ply").write_text("")
    with pytest.raises(InputError, match=r"my-scene: a scene folder's name"):
        scene_ids(tmp_path / "root")
    cam = tmp_path / "camera.json"
    for text, match in (("{", "not valid JSON"), ("[1, 2]", "expected"),
                        ('{"eye": [0, 1, 2], "target": [0, 0, 0]}', "fov_y_deg: missing"),
                        ('{"eye": [0, 1], "target": [0, 0, 0], "fov_y_deg": 50}', "eye: expected 3 finite numbers"),
                        ('{"eye": [0, 1, 2], "target": "here", "fov_y_deg": 50}', "target: not numeric"),
                        ('{"eye": [0, 1, 2], "target": [0, 0, 0], "fov_y_deg": [50]}', "fov_y_deg: expected a number")):
        cam.write_text(text)
        with pytest.raises(InputError, match=re.escape(str(cam)) + ".*" + match):
            read_camera(cam)


@pytest.mark.workflow
def test_a_folder_of_placed_scenes_is_a_workflow_suite(tmp_path):
    """`source: {kind: placed, root: ...}`: each scene folder a scene (one rule for those with camera.json, one
    for the others), imported as `run_placed_scene` imports it; the real-scenes table plans over them; an unknown
    key of the source is refused by the config check, naming it."""
    import yaml

    from tests import workflow_run

    write_scene(tmp_path / "r3d", "s", (10.0, 5.0))
    _as_placed(tmp_path / "r3d", "s", tmp_path / "root" / "withcam")
    _as_placed(tmp_path / "r3d", "s", tmp_path / "root" / "nocam", camera=False)
    cfg = {"suites": {"mine": {"source": {"kind": "placed", "root": str(tmp_path / "root")}}},
           "tables": {"mine": {"kind": "real", "suite": "mine", "methods": ["initial", "phi_scene"]}}}
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(cfg))

    def snakemake(*args):
        return workflow_run.snakemake(tmp_path / "wf", [tmp_path / "mine.yaml"], *args)

    plan = snakemake("-n", "results/tables/mine.csv")
    assert plan.returncode == 0, plan.stderr[-3000:]
    for rule in ("placed_scene_mine_camera", "placed_scene_mine"):
        assert re.search(rf"^{rule}\s+1$", plan.stdout + plan.stderr, re.M), plan.stdout[-3000:]
    scenes = ["results/scenes/mine/withcam/initial/scene.json", "results/scenes/mine/withcam/reference/camera.json",
              "results/scenes/mine/nocam/initial/scene.json"]
    res = snakemake("-j2", *scenes)
    assert res.returncode == 0, res.stderr[-3000:]
    direct = run_placed_scene(cfg["suites"]["mine"]["source"], "withcam", tmp_path / "direct")
    built = load_scene(tmp_path / "wf" / scenes[0])
    for o in direct.objects:
        assert np.allclose(built.get(o.id).pose, o.pose, atol=1e-12)
    assert not (tmp_path / "wf/results/scenes/mine/nocam/reference/camera.json").exists()
    cfg["suites"]["mine"]["source"]["upp"] = "z"
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(cfg))
    bad = snakemake("-n", "results/tables/mine.csv")
    said = bad.stdout + bad.stderr
    assert bad.returncode != 0 and "suites.mine.source" in said and "upp" in said, said[-2000:]


def _phiscene(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """The ``phiscene`` command run in ``cwd``."""
    return subprocess.run([sys.executable, "-m", "phiscene.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300)


def test_import_placed_command_takes_the_camera(tmp_path):
    """`phiscene import-placed DIR OUT --placements P --camera C`: the REST3D twin's scene and camera; a bad camera
    file is one error line naming it."""
    write_scene(tmp_path / "r3d", "s", (8.0, 3.0))
    folder = tmp_path / "scene"
    _as_placed(tmp_path / "r3d", "s", folder)
    twin = import_rest3d(tmp_path / "r3d", "s", tmp_path / "twin")

    res = _phiscene(tmp_path, "import-placed", str(folder), str(tmp_path / "out"), "--placements",
                   str(folder / "placements.json"), "--camera", str(folder / "camera.json"))
    assert res.returncode == 0, res.stderr[-2000:]
    out = load_scene(tmp_path / "out" / "initial" / "scene.json")
    for o in twin.objects:
        assert np.allclose(out.get(o.id).pose, o.pose, atol=1e-9)
    cams = [json.loads((tmp_path / d / "reference" / "camera.json").read_text()) for d in ("twin", "out")]
    assert np.allclose(cams[0]["world_to_camera"], cams[1]["world_to_camera"], atol=1e-9)
    (tmp_path / "bad.json").write_text('{"eye": [0, 1, 2], "target": [0, 1, 2], "fov_y_deg": 50}')
    res = _phiscene(tmp_path, "import-placed", str(folder), str(tmp_path / "bad"), "--camera",
                    str(tmp_path / "bad.json"))
    assert res.returncode == 1 and res.stderr.strip().count("\n") == 0 and "apart" in res.stderr, res.stderr
    assert not (tmp_path / "bad").exists()


def test_a_folder_without_meshes_says_where_they_are(tmp_path):
    """A folder without mesh files names the sub-folder or SAM 3D run that has them; a point cloud (a Gaussian
    splat) is named as one."""
    import trimesh

    from phiscene.io.placed import read_placed_dir

    (tmp_path / "scene/meshes").mkdir(parents=True)
    trimesh.creation.box([0.1, 0.1, 0.1]).export(tmp_path / "scene/meshes/cube.glb")
    with pytest.raises(InputError, match=re.escape(f"has them: pass {tmp_path / 'scene/meshes'}")):
        read_placed_dir(tmp_path / "scene")
    (tmp_path / "run/chair").mkdir(parents=True)
    (tmp_path / "run/chair/pose.json").write_text("{}")
    with pytest.raises(InputError, match="import-sam3d"):
        read_placed_dir(tmp_path / "run")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"in the folder$"):
        read_placed_dir(tmp_path / "empty")
    (tmp_path / "splat").mkdir()
    trimesh.PointCloud(np.random.default_rng(0).normal(size=(300, 3))).export(tmp_path / "splat/bear.ply")
    with pytest.raises(InputError, match=r"bear.ply: no triangles in the file: a point cloud of 300 points"):
        read_placed_dir(tmp_path / "splat")


def _scene_file(path: Path) -> dict:
    """A glTF scene as exporters write one: a wrapper node over the objects, a table of five part nodes under its
    own placed node, a book rotated by its node. Returns each object's world vertices (source frame), built here
    from the primitives and the node transforms."""
    import trimesh
    from trimesh.transformations import rotation_matrix, translation_matrix

    s = trimesh.Scene()
    s.graph.update(frame_from=s.graph.base_frame, frame_to="Root", matrix=translation_matrix((0.0, 0.0, -1.5)))
    table_at = translation_matrix((0.3, 0.0, -0.2))
    s.graph.update(frame_from="Root", frame_to="wooden table", matrix=table_at)
    parts = {"top": ((1.2, 0.05, 0.8), (0.0, 0.75, 0.0))}
    parts.update({f"leg{i}": ((0.05, 0.725, 0.05), (x, 0.3625, z))
                  for i, (x, z) in enumerate([(-0.5, -0.3), (0.5, -0.3), (-0.5, 0.3), (0.5, 0.3)])})
    table = []
    for name, (extents, at) in parts.items():
        box = trimesh.creation.box(extents)
        s.add_geometry(box, node_name=name, geom_name=name, parent_node_name="wooden table",
                       transform=translation_matrix(at))
        table.append(trimesh.transform_points(box.vertices, translation_matrix((0.3, 0.0, -1.7)) @
                                              translation_matrix(at)))
    book = trimesh.creation.box((0.2, 0.04, 0.15))
    book_at = translation_matrix((0.4, 0.795, -0.2)) @ rotation_matrix(0.5, (0.0, 1.0, 0.0))
    s.add_geometry(book, node_name="book", geom_name="book", parent_node_name="Root", transform=book_at)
    # what exporters add beside the objects: a camera (an empty node) and a point set
    s.graph.update(frame_from="Root", frame_to="Camera", matrix=translation_matrix((0.0, 1.0, 3.0)))
    s.add_geometry(trimesh.PointCloud(np.random.default_rng(0).normal(size=(50, 3))), node_name="markers",
                   geom_name="markers", parent_node_name="Root")
    s.export(path)
    return {"wooden_table": np.vstack(table),
            "book": trimesh.transform_points(book.vertices, translation_matrix((0.0, 0.0, -1.5)) @ book_at)}


def test_a_scene_file_imports_one_object_per_top_level_node(tmp_path, caplog):
    """`phiscene import-placed SCENE.glb OUT`: each node under the exporter's wrapper is an object, its parts merged
    in the file's frame (the world vertices of the construction, y-up taken to z-up), its camera and point set left
    out with a warning; the same file alone in a folder is one object with a warning naming its nodes, and
    `--objects nodes` (`objects: nodes` in a suite) reads its nodes; a PLY cannot be a scene file."""
    from phiscene.io.placed import PlacedParams, import_placed, read_placed_dir, read_scene_file
    from phiscene.transforms import Y_UP_TO_Z_UP

    folder = tmp_path / "suite" / "room"
    folder.mkdir(parents=True)
    truth = _scene_file(folder / "room.glb")
    with caplog.at_level("WARNING"):
        objects = read_scene_file(folder / "room.glb")
    assert [o.id for o in objects] == ["book", "wooden_table"]
    assert "2 top-level nodes without triangles left out (Camera, markers)" in caplog.text
    caplog.clear()
    assert [o.description for o in objects] == ["book", "wooden table"]
    for o in objects:
        assert len(o.mesh.vertices) == len(truth[o.id])
        assert np.allclose(np.sort(o.mesh.vertices, axis=0), np.sort(truth[o.id], axis=0), atol=1e-6)
    scene = import_placed(objects, tmp_path / "out", PlacedParams(level=False))
    for o in scene.objects:
        world = o.mesh().copy().apply_transform(o.pose)
        expected = truth[o.id] @ Y_UP_TO_Z_UP[:3, :3].T
        assert np.allclose(world.bounds, [expected.min(axis=0), expected.max(axis=0)], atol=1e-6)
        assert o.meta["source_node"] in ("book", "wooden table")

    with caplog.at_level("WARNING"):
        merged = read_placed_dir(folder)
    assert [o.id for o in merged] == ["room"] and "holds 2 top-level nodes (book, wooden table)" in caplog.text
    nodes = read_placed_dir(folder, objects="nodes")
    assert [o.id for o in nodes] == ["book", "wooden_table"]
    run_placed_scene({"root": str(tmp_path / "suite"), "kind": "placed", "objects": "nodes",
                      "params": {"level": False}}, "room", tmp_path / "suite_out")
    assert load_scene(tmp_path / "suite_out" / "initial" / "scene.json").ids == ["book", "wooden_table"]

    res = _phiscene(tmp_path, "import-placed", str(folder / "room.glb"), str(tmp_path / "cli"), "--no-level")
    assert res.returncode == 0, res.stderr[-2000:]
    assert load_scene(tmp_path / "cli" / "initial" / "scene.json").ids == ["book", "wooden_table"]
    res = _phiscene(tmp_path, "import-placed", str(folder / "room.glb"), str(tmp_path / "cli2"), "--objects", "files")
    assert res.returncode == 1 and res.stderr.strip().count("\n") == 0 and "scene file" in res.stderr, res.stderr

    objects[0].mesh.export(tmp_path / "book.ply")
    with pytest.raises(InputError, match=r"book.ply: its nodes cannot be read as objects"):
        read_scene_file(tmp_path / "book.ply")
    with pytest.raises(InputError, match=r"placements for objects without a mesh: \['lamp'\]"):
        read_scene_file(folder / "room.glb", {"wooden table": np.eye(4).tolist(), "lamp": np.eye(4).tolist()})
    shutil.copy(folder / "room.glb", folder / "room2.glb")
    with pytest.raises(InputError, match=r"room2.glb: object id 'book' is also the id of room.glb:book"):
        read_placed_dir(folder, objects="nodes")


def test_an_opencv_frame_imports_as_its_y_up_twin(tmp_path):
    """`up: -y` (OpenCV's camera frame: y down, z forward) is the y-up scene turned half a turn about x: imported
    without levelling, each object lands where the y-up files put it (the two conventions differ by exactly that
    turn); with levelling, both estimate the same up."""
    from phiscene.io.placed import PlacedObject, PlacedParams, import_placed, read_scene_file

    _scene_file(tmp_path / "room.glb")
    y_up = read_scene_file(tmp_path / "room.glb")
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    y_down = [PlacedObject(o.id, o.mesh.copy().apply_transform(flip), o.description, o.source) for o in y_up]
    for level in (False, True):
        a = import_placed(y_up, tmp_path / f"a{level}", PlacedParams(up="y", level=level))
        b = import_placed(y_down, tmp_path / f"b{level}", PlacedParams(up="-y", level=level))
        for oa in a.objects:
            ob = b.get(oa.id)
            wa = oa.mesh().copy().apply_transform(oa.pose)
            wb = ob.mesh().copy().apply_transform(ob.pose)
            assert np.allclose(wa.vertices, wb.vertices, atol=1e-6), (level, oa.id)
    with pytest.raises(ValueError, match=r"'up' must be one of"):
        PlacedParams.from_dict({"up": "down"})


def test_the_room_s_own_meshes_do_not_set_the_scene_s_scale(tmp_path, caplog):
    """The median object of a scene whose floor, wall and ceiling are meshed (4 m each) is a chair or a box: no warning
    about units; the same meshes named as objects give the warning (a median of 4.7 m)."""
    import trimesh

    from phiscene.io.placed import PlacedObject, check_placed

    sizes = {"wooden floor": (4.0, 4.0, 0.05), "white wall": (4.0, 0.1, 2.5), "ceiling": (4.0, 4.0, 0.05),
             "chair": (0.5, 0.5, 0.9),
             "box": (0.3, 0.3, 0.3)}
    objects = [PlacedObject(d.replace(" ", "_"), trimesh.creation.box(s), d, tmp_path / f"{d}.glb")
               for d, s in sizes.items()]
    with caplog.at_level("WARNING"):
        check_placed(objects, None, tmp_path / "out")
    assert "are the meshes in metres" not in caplog.text
    renamed = [PlacedObject(o.id, o.mesh, f"object {k}", o.source) for k, o in enumerate(objects)]
    with caplog.at_level("WARNING"):
        check_placed(renamed, None, tmp_path / "out")
    assert "median object is 4.72 m across" in caplog.text


def test_a_flat_floor_or_wall_mesh_becomes_a_slab_behind_its_face(tmp_path):
    """Layouts mesh their floor and walls as single quads. A flat mesh named as the room's own surface is made a slab
    `STRUCTURE_THICKNESS` thick behind its face, away from the other objects (the floor's top stays where the quad
    was, the wall's face too); a flat mesh of anything else is still refused, naming it."""
    import trimesh

    from phiscene.io.placed import STRUCTURE_THICKNESS, PlacedObject, PlacedParams, import_placed

    quad = trimesh.Trimesh([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    wall = trimesh.Trimesh([[-2, 1.6, 0], [2, 1.6, 0], [2, 1.6, 2.5], [-2, 1.6, 2.5]], [[0, 1, 2], [0, 2, 3]],
                           process=False)
    box = trimesh.creation.box((0.3, 0.3, 0.3)).apply_translation((0.0, 0.5, 0.15))
    objects = [PlacedObject("floor", quad, "wooden floor", tmp_path / "floor.glb"),
               PlacedObject("wall", wall, "white wall", tmp_path / "wall.glb"),
               PlacedObject("box", box, "cardboard box", tmp_path / "box.glb")]
    scene = import_placed(objects, tmp_path / "out", PlacedParams(up="z", level=False))
    world = {o.id: o.mesh().copy().apply_transform(o.pose).bounds for o in scene.objects}
    lift = world["box"][0, 2]  # the box stood on the quad: the floor's top is its bottom
    close = {"abs": 1e-6}  # the meshes are written as GLB: float32
    assert world["floor"][1, 2] == pytest.approx(lift, **close)
    assert world["floor"][0, 2] == pytest.approx(lift - STRUCTURE_THICKNESS, **close)
    assert world["wall"][0, 1] == pytest.approx(1.6, **close)
    assert world["wall"][1, 1] == pytest.approx(1.6 + STRUCTURE_THICKNESS, **close)
    poster = trimesh.Trimesh([[0, 1.59, 1], [0.5, 1.59, 1], [0.5, 1.59, 1.5]], [[0, 1, 2]], process=False)
    with pytest.raises(InputError, match=r"poster.glb: mesh has no volume"):
        import_placed([*objects, PlacedObject("poster", poster, "paper poster", tmp_path / "poster.glb")],
                      tmp_path / "out2", PlacedParams(up="z", level=False))
