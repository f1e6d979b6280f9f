"""SAM 3D Objects importer: fixtures in SAM 3D's exact output format whose world result is known analytically."""

import json
import re

import numpy as np
import pytest
import trimesh
from PIL import Image
from scipy.spatial.transform import Rotation

from phiscene.errors import InputError
from phiscene.io.sam3d import export_sam3d, import_sam3d, make_floor
from phiscene.meshes import save_mesh
from phiscene.scene import Scene, SceneObject

PITCH = np.radians(30.0)  # camera looks 30 deg below the horizon
HEIGHT = 1.5  # camera height above the floor (m)
# World axes (x right, y forward-horizontal, z up) in PyTorch3D camera coordinates (+X left, +Y up, +Z fwd).
EX = np.array([-1.0, 0.0, 0.0])
EY = np.array([0.0, np.sin(PITCH), np.cos(PITCH)])
EZ = np.array([0.0, np.cos(PITCH), -np.sin(PITCH)])
# (extents in the [-0.5, 0.5]^3 local frame, scale, yaw (deg), world xy of the box centre)
BOXES = {"crate": ((1.0, 0.6, 0.4), 0.5, 30.0, (0.2, 2.0)),
         "slab": ((1.0, 0.8, 0.1), 0.8, -20.0, (-0.6, 2.6)),
         "post": ((0.3, 0.3, 1.0), 0.6, 70.0, (0.7, 3.1))}


def world_to_cam(p):
    """Hand-written camera coordinates of world points (camera at (0, 0, HEIGHT), looking along +y)."""
    p = np.atleast_2d(p)
    return p[:, :1] * EX + p[:, 1:2] * EY + (p[:, 2:3] - HEIGHT) * EZ


def expected_world(extents, scale, yaw, xy):
    """World corners of a box resting on the floor: analytic."""
    corners = trimesh.creation.box(extents).vertices * scale
    R = Rotation.from_euler("z", yaw, degrees=True).as_matrix()
    return corners @ R.T + np.array([xy[0], xy[1], scale * extents[2] / 2])


def write_fixture(root, variant):
    """SAM 3D Objects output written by hand: row-vector pose p_cam = (s p) R + t, quaternion (w, x, y, z)."""
    A = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
    M = np.stack([EX, EY, EZ], axis=1)  # columns: world axes in camera coordinates
    for name, (ext, s, yaw, xy) in BOXES.items():
        Rw = Rotation.from_euler("z", yaw, degrees=True).as_matrix()
        R_row = (M @ Rw).T  # p_cam (row) = s p R_row + t
        x, y, z, w = Rotation.from_matrix(R_row).as_quat()  # scipy: quaternion of R_row as a column rotation
        t = world_to_cam([xy[0], xy[1], s * ext[2] / 2])[0]
        mesh = trimesh.creation.box(ext)
        d = root / name
        d.mkdir(parents=True)
        if variant == "glb":
            mesh.vertices = mesh.vertices @ A  # z-up -> y-up, row vectors
            mesh.export(d / "mesh.glb")
        else:
            mesh.export(d / "mesh.ply")
        (d / "pose.json").write_text(json.dumps({"rotation": [w, x, y, z], "translation": t.tolist(),
                                                 "scale": [s, s, s], "description": f"a {name}"}))
    return root


def world_corners(scene, oid):
    return scene.get(oid).world_mesh().vertices


def assert_matches_analytic(scene):
    for name, (ext, s, yaw, xy) in BOXES.items():
        got = np.asarray(world_corners(scene, name))
        want = expected_world(ext, s, yaw, xy)
        # same vertex set (order of box vertices is trimesh's in both)
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("variant", ["mesh", "glb"])
def test_given_floor_gives_analytic_world(tmp_path, variant):
    src = write_fixture(tmp_path / "in", variant)
    # floor n.p + d = 0 in the camera frame: world z = EZ.p + HEIGHT
    scene = import_sam3d(src, tmp_path / "out", floor=make_floor(EZ, HEIGHT))
    assert scene.ground_height == 0.0
    assert sorted(scene.ids) == sorted(BOXES)
    assert_matches_analytic(scene)
    rec = json.loads((tmp_path / "out/import.json").read_text())
    assert rec["objects"] == {k: variant for k in BOXES}
    np.testing.assert_allclose(rec["camera_height"], HEIGHT, atol=1e-9)
    assert scene.get("crate").description == "a crate"


def test_transposed_rotation_would_be_wrong(tmp_path):
    """Oracle sanity: the column-vector reading of R (the easy bug) moves the corners far from the analytic ones."""
    src = write_fixture(tmp_path / "in", "mesh")
    pose = json.loads((src / "crate/pose.json").read_text())
    w, x, y, z = pose["rotation"]
    R = Rotation.from_quat([x, y, z, w]).as_matrix()
    ext, s, yaw, xy = BOXES["crate"]
    local = trimesh.creation.box(ext).vertices
    right = (s * local) @ R + pose["translation"]
    wrong = (s * local) @ R.T + pose["translation"]
    cam = world_to_cam(expected_world(ext, s, yaw, xy))
    np.testing.assert_allclose(right, cam, atol=1e-9)
    assert np.abs(wrong - cam).max() > 0.05


@pytest.mark.parametrize("variant", ["mesh", "glb"])
def test_estimated_floor_matches_the_true_floor(tmp_path, variant):
    src = write_fixture(tmp_path / "in", variant)
    scene = import_sam3d(src, tmp_path / "out")
    rec = json.loads((tmp_path / "out/import.json").read_text())
    assert rec["floor"]["from"] == "estimated"
    np.testing.assert_allclose(rec["floor"]["normal"], EZ, atol=1e-6)
    np.testing.assert_allclose(rec["floor"]["offset"], HEIGHT, atol=1e-6)
    assert_matches_analytic(scene)


def test_round_trip_through_sam3d_format(tmp_path):
    """scene -> SAM 3D output (arbitrary camera, normalised meshes) -> scene: same geometry up to a z-rigid motion."""
    rng = np.random.default_rng(3)
    objs = []
    for k in range(3):
        m = trimesh.creation.box(rng.uniform(0.1, 0.5, 3))
        m.vertices += rng.uniform(-0.2, 0.2, 3)  # local frame not centred: the exporter normalises it
        path = save_mesh(m, tmp_path / f"src/meshes/o{k}.glb")
        R = Rotation.from_euler("z", rng.uniform(0, 360), degrees=True).as_matrix()
        pose = np.eye(4)
        pose[:3, :3] = 1.3 * R
        pose[:3, 3] = [rng.uniform(-1, 1), rng.uniform(-1, 1), -1.3 * m.bounds[0, 2]]  # resting on z = 0
        objs.append(SceneObject(f"o{k}", path, pose, f"box {k}", (10 * k, 20, 30)))
    scene = Scene(objs)
    # camera: 2 m up, yawed 40 deg, pitched 25 deg down, rolled 5 deg, off the origin
    R_wc = Rotation.from_euler("zyx", [40, 0, 0], degrees=True).as_matrix()
    look = R_wc @ Rotation.from_euler("x", -25, degrees=True).as_matrix() @ Rotation.from_euler(
        "y", 5, degrees=True).as_matrix()
    # camera axes in world: right, up, forward -> PyTorch3D X = -right, Y = up, Z = forward
    right, fwd = look[:, 0], look[:, 1]
    up = np.cross(right, fwd)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([-right, up, fwd], axis=1)
    c2w[:3, 3] = [0.3, -2.5, 2.0]
    export_sam3d(scene, tmp_path / "sam3d", np.linalg.inv(c2w), variant="glb")
    out = import_sam3d(tmp_path / "sam3d", tmp_path / "out")  # floor.json written by the exporter
    pts_in = np.concatenate([o.world_mesh().vertices for o in scene.objects])
    pts_out = np.concatenate([out.get(o.id).world_mesh().vertices for o in scene.objects])
    np.testing.assert_allclose(pts_out[:, 2], pts_in[:, 2], atol=1e-6)  # heights above the floor
    dist = lambda p: np.linalg.norm(p[:, None] - p[None], axis=2)  # noqa: E731
    np.testing.assert_allclose(dist(pts_out), dist(pts_in), atol=1e-6)  # rigid
    # and the camera sits 2 m above the origin of the imported world
    rec = json.loads((tmp_path / "out/import.json").read_text())
    W = np.asarray(rec["world_from_camera"])
    np.testing.assert_allclose(W[:3, 3], [0, 0, 2.0], atol=1e-9)
    assert out.get("o1").color == (10, 20, 30)


def test_reference_image_masks_and_camera(tmp_path):
    src = write_fixture(tmp_path / "in", "mesh")
    Image.fromarray(np.full((24, 32, 3), 90, np.uint8)).save(src / "image.png")
    for k, name in enumerate(BOXES):
        m = np.zeros((24, 32), np.uint8)
        m[k * 5:(k + 1) * 5, 2:9] = 255
        Image.fromarray(m).save(src / name / "mask.png")
    (src / "camera.json").write_text(json.dumps({"fx": 30.0, "fy": 30.0, "cx": 15.5, "cy": 11.5,
                                                 "width": 32, "height": 24}))
    scene = import_sam3d(src, tmp_path / "out", floor=make_floor(-EZ, -HEIGHT))  # flipped normal: re-oriented
    assert_matches_analytic(scene)
    seg = np.asarray(Image.open(tmp_path / "out/reference/segmentation.png").convert("RGB"))
    for o in scene.objects:  # objects are read in name order: crate, post, slab
        rows = {"crate": 0, "slab": 1, "post": 2}[o.id]
        assert tuple(seg[rows * 5 + 2, 5]) == o.color
    from phiscene.render import project, read_camera

    cam = read_camera(tmp_path / "out/reference/camera.json")
    # the pinhole projection of a world point equals the intrinsics applied to its camera coordinates
    pw = np.array([[0.2, 2.0, 0.1]])
    pc = world_to_cam(pw)[0] * [-1, -1, 1]  # PyTorch3D -> OpenCV
    np.testing.assert_allclose(project(cam, pw)[0], [30 * pc[0] / pc[2] + 15.5, 30 * pc[1] / pc[2] + 11.5], atol=1e-6)


def test_bad_inputs_name_file_and_field(tmp_path):
    src = write_fixture(tmp_path / "in", "mesh")
    pose = json.loads((src / "crate/pose.json").read_text())
    (src / "crate/pose.json").write_text(json.dumps({**pose, "scale": [0.5, 0.5, 0.7]}))
    with pytest.raises(InputError, match=r"crate/pose.json: scale: anisotropic"):
        import_sam3d(src, tmp_path / "out")
    (src / "crate/pose.json").write_text(json.dumps({**pose, "rotation": [1, 0, 0]}))
    with pytest.raises(InputError, match=r"crate/pose.json: rotation: expected 4"):
        import_sam3d(src, tmp_path / "out")
    (src / "crate/pose.json").write_text(json.dumps(pose))
    trimesh.creation.box().export(src / "crate/mesh.glb")
    with pytest.raises(InputError, match=r"crate: expected exactly one of"):
        import_sam3d(src, tmp_path / "out")
    assert not (tmp_path / "out/initial/scene.json").exists()


def test_cli_import_then_ground_end_to_end(tmp_path):
    """`phiscene import-sam3d` then `phiscene ground` on the fixture with the crate floating 3 cm: it lands."""
    import subprocess
    import sys

    from phiscene.scene import load_scene

    src = write_fixture(tmp_path / "in", "glb")
    pose = json.loads((src / "crate/pose.json").read_text())
    pose["translation"] = (np.asarray(pose["translation"]) + 0.03 * EZ).tolist()  # 3 cm above the floor
    (src / "crate/pose.json").write_text(json.dumps(pose))
    run = lambda *a: subprocess.run([sys.executable, "-m", "phiscene.cli", *a], cwd=tmp_path,  # noqa: E731
                                    capture_output=True, text=True, timeout=300)
    res = run("import-sam3d", str(src), str(tmp_path / "imp"), "--floor", *map(str, [*EZ, HEIGHT]))
    assert res.returncode == 0, res.stderr
    before = load_scene(tmp_path / "imp/initial/scene.json")
    np.testing.assert_allclose(before.get("crate").world_mesh().bounds[0, 2], 0.03, atol=1e-6)
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("proxies: {backend: convex}\ncache_dir: " + str(tmp_path / "cache") + "\n")
    res = run("ground", str(tmp_path / "imp/initial"), str(tmp_path / "grounded"), "--config", str(cfg))
    assert res.returncode == 0, res.stderr
    after = load_scene(tmp_path / "grounded/scene.json")
    for name, (_, _, _, xy) in BOXES.items():
        lo, hi = after.get(name).world_mesh().bounds
        assert abs(lo[2]) < 2e-3, (name, lo)  # resting on the floor
        np.testing.assert_allclose((lo[:2] + hi[:2]) / 2, xy, atol=0.01)  # where the image put it
    res = run("import-sam3d", str(tmp_path / "nowhere"), str(tmp_path / "x"))
    assert res.returncode == 1 and res.stderr.count("\n") == 1 and "nowhere: input folder not found" in res.stderr


def _table_top_photo(root):
    """A table-top photo as SAM 3D Objects outputs it (no floor.json): a table whose back legs the image cut off
    (reconstructed 0.3 m long of 0.71), a plate and two fruit on it, a poster on the wall behind, the camera 1.4 m
    up, pitched 35 deg down and rolled 4 deg. Returns the world -> PyTorch3D transform."""
    at = trimesh.transformations.translation_matrix
    parts = [trimesh.creation.box((1.2, 0.8, 0.04), at((0, 2.0, 0.73)))]
    for x in (-0.55, 0.55):
        for y, length in ((1.65, 0.71), (2.35, 0.30)):  # front legs to the floor, back legs cut off
            parts.append(trimesh.creation.box((0.05, 0.05, length), at((x, y, 0.71 - length / 2))))
    objs = [("table", trimesh.util.concatenate(parts), "a wooden table"),
            ("plate", trimesh.creation.cylinder(0.12, 0.02, sections=48, transform=at((0.2, 1.9, 0.76))),
             "a white plate"),
            ("pear", trimesh.creation.icosphere(2, 0.04).apply_translation((-0.2, 2.1, 0.79)), "a green pear"),
            ("apple", trimesh.creation.icosphere(2, 0.035).apply_translation((0.2, 1.9, 0.805)), "an apple"),
            ("poster", trimesh.creation.box((0.6, 0.01, 0.8), at((0.0, 2.995, 1.6))), "a poster on the wall")]
    scene_objs = []
    for name, mesh, text in objs:
        centre = mesh.bounds.mean(axis=0)
        path = save_mesh(mesh.copy().apply_translation(-centre), root / "src" / f"{name}.glb")
        scene_objs.append(SceneObject(name, path, at(centre), text))
    # camera: at (0, 0, 1.4), yawed 0, pitched 35 deg down, rolled 4 deg; PyTorch3D X = -right, Y = up, Z = forward
    look = Rotation.from_euler("XY", [-35, 4], degrees=True).as_matrix()
    right, fwd = look[:, 0], look[:, 1]
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([-right, np.cross(right, fwd), fwd], axis=1)
    c2w[:3, 3] = [0.0, 0.0, 1.4]
    w2c = np.linalg.inv(c2w)
    export_sam3d(Scene(scene_objs), root / "sam3d", w2c, variant="glb", write_floor=False)
    return w2c


def test_table_top_photo_is_levelled_by_its_table_not_by_its_lowest_facet(tmp_path):
    """No floor given: the floor is normal to the levelled up (table top and plate), at the feet of what stands on
    it, within 1 deg and 1 cm of the analytic floor, though the camera is pitched 35 deg and rolled 4 and the back
    legs end 0.41 m above it; the wall behind the poster is estimated, and not when told not to."""
    from phiscene.io.sam3d import Sam3dParams
    from phiscene.walls import WallParams

    w2c = _table_top_photo(tmp_path)
    true_up = w2c[:3, :3] @ [0.0, 0.0, 1.0]  # world +z in camera coordinates
    scene = import_sam3d(tmp_path / "sam3d", tmp_path / "out")
    rec = json.loads((tmp_path / "out/import.json").read_text())
    assert rec["floor"]["from"] == "estimated" and rec["up_estimate"]["tilt_deg"] > 30
    floor_normal = np.asarray(rec["floor"]["normal"])
    assert np.degrees(np.arccos(np.clip(floor_normal @ true_up, -1, 1))) < 1.0
    # the front legs stand on the floor: their feet at z = 0 (they are the table's lowest points), the camera 1.4 m up
    assert abs(scene.get("table").world_mesh().bounds[0, 2]) < 0.01
    np.testing.assert_allclose(rec["camera_height"], 1.4, atol=0.01)
    top = scene.get("plate").world_mesh().bounds[1, 2] - scene.get("plate").world_mesh().bounds[0, 2]
    np.testing.assert_allclose(top, 0.02, atol=1e-3)  # level: the plate's thickness is its height
    walls = [p for p in scene.structure if p.kind == "wall"]
    assert len(walls) == 1 and walls[0].estimated
    poster = scene.get("poster").world_mesh()
    back = poster.vertices[np.argmax(-poster.vertices @ np.asarray(walls[0].normal))]
    assert abs(float(np.asarray(walls[0].normal) @ back + walls[0].offset)) < 0.01  # through the poster's back
    assert np.degrees(np.arccos(abs(np.asarray(walls[0].normal)[2]))) > 89.0  # vertical
    # told not to, it estimates none
    bare = import_sam3d(tmp_path / "sam3d", tmp_path / "bare", params=Sam3dParams(walls=WallParams(enabled=False)))
    assert not bare.structure


@pytest.mark.workflow
def test_a_folder_of_runs_is_a_workflow_suite(tmp_path):
    """`source: {kind: sam3d, root: ...}`: each run a scene, levelled with the poster's wall; a run with camera.json
    also gives the photo's camera (and the faithful grounding reads it); the real-scenes table plans over the runs;
    an unknown key of the source is refused by the config check, naming it."""
    import yaml

    from phiscene.scene import load_scene
    from tests import workflow_run

    runs = tmp_path / "runs"
    runs.mkdir()
    w2c = _table_top_photo(tmp_path / "a")
    (tmp_path / "a/sam3d").rename(runs / "tabletop")
    (runs / "tabletop/camera.json").write_text(json.dumps({"fx": 50.0, "fy": 50.0, "cx": 31.5, "cy": 23.5,
                                                           "width": 64, "height": 48}))
    write_fixture(runs / "boxes", "glb")
    (runs / "notes").mkdir()  # not a run: no <object id>/pose.json
    cfg = {"suites": {"mine": {"source": {"kind": "sam3d", "root": str(runs)}}},
           "tables": {"mine": {"kind": "real", "suite": "mine", "methods": ["initial", "phi_scene"]}}}
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(cfg))

    def snakemake(*args):
        return workflow_run.snakemake(tmp_path / "wf", [tmp_path / "mine.yaml"], *args)

    plan = snakemake("-n", "results/tables/mine.csv")
    assert plan.returncode == 0, plan.stderr[-3000:]
    for rule, scenes in (("sam3d_scene_mine_camera", 1), ("sam3d_scene_mine", 1)):
        assert re.search(rf"^{rule}\s+{scenes}$", plan.stdout + plan.stderr, re.M), plan.stdout[-3000:]
    # the camera of the run that gives one is an input of its faithful grounding
    scenes = ["results/scenes/mine/tabletop/initial/scene.json", "results/scenes/mine/tabletop/reference/camera.json",
              "results/scenes/mine/boxes/initial/scene.json"]
    res = snakemake("-j2", *scenes)
    assert res.returncode == 0, res.stderr[-3000:]
    top = load_scene(tmp_path / "wf" / scenes[0])
    walls = [p for p in top.structure if p.kind == "wall"]
    assert len(walls) == 1 and abs(top.get("table").world_mesh().bounds[0, 2]) < 0.01
    assert not (tmp_path / "wf/results/scenes/mine/boxes/reference/camera.json").exists()
    assert sorted(load_scene(tmp_path / "wf" / scenes[2]).ids) == sorted(BOXES)
    floor = json.loads((tmp_path / "wf/results/scenes/mine/tabletop/import.json").read_text())["floor"]
    assert np.degrees(np.arccos(np.clip(np.asarray(floor["normal"]) @ w2c[:3, :3] @ [0.0, 0.0, 1.0], -1, 1))) < 1.0
    cfg["suites"]["mine"]["source"]["params"] = {"unit_scael": 1.0}
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(cfg))
    bad = snakemake("-n", "results/tables/mine.csv")
    said = bad.stdout + bad.stderr
    assert bad.returncode != 0 and "suites.mine.source" in said and "unit_scael" in said, said[-2000:]
