"""Placed-mesh import, the REST3D layout and gravity levelling, on generated scenes with analytic answers."""

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from phiscene.errors import InputError
from phiscene.io.placed import Camera, PlacedObject, PlacedParams, import_placed, level_objects, read_placed_dir
from phiscene.io.rest3d import import_rest3d, read_rest3d, reference_up, scene_ids
from phiscene.levelling import LevelParams, angle_deg, estimate_up, floor_height, levelling_transform, resting_bottom
from phiscene.scene import load_scene
from tests.rest3d_fixture import objects, write_scene


def source_up(levelling) -> np.ndarray:
    """The up direction (source frame) that a levelling transform sends to +z."""
    return levelling.transform[:3, :3].T @ np.array([0.0, 0.0, 1.0])


@pytest.mark.parametrize("tilt", [(12.0, 4.0), (-20.0, 2.0), (3.0, -6.0), (0.0, 0.0)])
@pytest.mark.parametrize("poster", [True, False])
def test_tilted_scene_is_levelled_within_one_degree(tmp_path, tilt, poster):
    R = write_scene(tmp_path, "s", tilt, with_poster=poster)
    data = read_rest3d(tmp_path, "s", "sam3d")
    lev = level_objects(data.objects, PlacedParams(), data.camera)
    truth = R @ np.array([0.0, 1.0, 0.0])
    assert angle_deg(source_up(lev), truth) < 1.0
    assert lev.rotation_deg == pytest.approx(angle_deg(truth, [0.0, 1.0, 0.0]), abs=1.0)


@pytest.mark.parametrize("tilt,warned", [((5.0, 2.0), False), ((36.0, 0.0), True)])
def test_large_levelling_is_warned(tmp_path, caplog, tilt, warned):
    # a scene levelled by more than any camera tilt of a real scene (here the fixture tilted 36 deg) is warned
    # about, naming --up (files whose up axis is not the one given level onto whatever lies near it)
    import logging

    R = write_scene(tmp_path, "s", tilt)
    data = read_rest3d(tmp_path, "s", "sam3d")
    with caplog.at_level(logging.WARNING, logger="phiscene.io.placed"):
        lev = level_objects(data.objects, PlacedParams(), data.camera)
    assert angle_deg(source_up(lev), R @ np.array([0.0, 1.0, 0.0])) < 1.0
    assert any("--up" in r.getMessage() for r in caplog.records) == warned


@pytest.mark.parametrize("unit_scale,warned", [(1.0, False), (10.0, True), (0.012, True)])
def test_a_scene_not_in_metres_is_warned(tmp_path, caplog, unit_scale, warned):
    # the fixture's table, box, plate and poster (median 0.72 m across) scaled by 10 (a 16 m table, as a scene in
    # decimetres read as metres) or by 0.012 (a 2 cm table): the import warns, naming --unit-scale; as is, it does not
    import logging

    write_scene(tmp_path, "s", (5.0, 2.0))
    with caplog.at_level(logging.WARNING, logger="phiscene.io.placed"):
        import_rest3d(tmp_path, "s", tmp_path / "out", params=PlacedParams(unit_scale=unit_scale, level=False))
    assert any("--unit-scale" in r.getMessage() for r in caplog.records) == warned


def test_table_top_only_scene_without_floor(tmp_path):
    """A close-up: only things on a table top, no table legs, no floor: the plate and box tops still vote."""
    R = Rotation.from_euler("xz", [15.0, -3.0], degrees=True).as_matrix()
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name, mesh in objects(with_poster=False).items():
        if name == "wooden_table_000":
            mesh = trimesh.creation.box([1.2, 0.04, 0.8], transform=trimesh.transformations.translation_matrix(
                [0, 0.73, 0]))
        mesh.vertices = mesh.vertices @ R.T
        mesh.export(folder / f"{name}.glb")
    lev = level_objects(read_placed_dir(folder), PlacedParams())
    assert angle_deg(source_up(lev), R @ [0.0, 1.0, 0.0]) < 1.0


def test_import_reproduces_placements_and_levels(tmp_path):
    R = write_scene(tmp_path, "s", (10.0, 5.0))
    scene = import_rest3d(tmp_path, "s", tmp_path / "out", "sam3d")
    levelled = {n: m for n, m in objects().items()}
    # the table's feet on the ground, its top horizontal at its height above the feet (0.75 m)
    table = scene.get("wooden_table_000").world_mesh()
    assert table.bounds[0, 2] == pytest.approx(0.0, abs=2e-3)
    top = table.vertices[:, 2].max()
    assert top == pytest.approx(0.75, abs=5e-3)
    # every object keeps its shape and its place relative to the table (rigid transform of the fixture)
    for oid, mesh in levelled.items():
        w = scene.get(oid).world_mesh()
        assert w.extents[2] == pytest.approx(mesh.extents[1], abs=5e-3)  # y-up height -> z-up height
        rel = w.bounds.mean(axis=0)[2] - table.bounds[0, 2]
        assert rel == pytest.approx(mesh.bounds.mean(axis=0)[1], abs=5e-3)
    info = json.loads((tmp_path / "out" / "import.json").read_text())
    assert info["levelling_rotation_deg"] == pytest.approx(angle_deg(R @ [0, 1, 0], [0, 1, 0]), abs=1.0)
    cam = json.loads((tmp_path / "out" / "reference" / "camera.json").read_text())
    # camera eye was 1.8 m above the feet in the levelled fixture
    assert cam["eye"][2] == pytest.approx(1.8, abs=0.02)
    assert load_scene(tmp_path / "out" / "initial" / "scene.json").ids == scene.ids


def test_unit_scale_imports_a_millimetre_scene_as_the_metric_one(tmp_path):
    """The same scene in millimetres: refused before anything is written, then imported with unit_scale 0.001
    exactly as the metric scene (same levelling, same poses and extents, same camera)."""
    write_scene(tmp_path, "s", (10.0, 5.0))
    data = read_rest3d(tmp_path, "s", "sam3d")
    metric = import_placed(data.objects, tmp_path / "m", PlacedParams(), data.camera)
    mm = [PlacedObject(o.id, o.mesh.copy().apply_scale(1000.0), o.description, o.source) for o in data.objects]
    cam = Camera(np.asarray(data.camera.eye) * 1000.0, np.asarray(data.camera.target) * 1000.0,
                 data.camera.fov_y_deg)
    with pytest.raises(InputError, match=r"\.glb: object is .* m across .*--unit-scale 0\.001"):
        import_placed(mm, tmp_path / "refused", PlacedParams(), cam)
    assert not (tmp_path / "refused").exists()
    scaled = import_placed(mm, tmp_path / "mm", PlacedParams(unit_scale=0.001), cam)
    for o in metric.objects:
        assert np.allclose(scaled.get(o.id).pose, o.pose, atol=1e-6)
        assert np.allclose(scaled.get(o.id).world_mesh().extents, o.world_mesh().extents, atol=1e-6)
    cams = [json.loads((tmp_path / d / "reference" / "camera.json").read_text()) for d in ("m", "mm")]
    assert np.allclose(cams[0]["eye"], cams[1]["eye"], atol=1e-6)
    with pytest.raises(ValueError, match="unit_scale"):
        PlacedParams.from_dict({"unit_scale": 0.0})


@pytest.mark.parametrize("offset", [(120.0, -40.0, 7.0), (5.0e5, 3.0, 4.0e6)])
def test_a_scene_far_from_its_frame_origin_is_centred_not_refused(tmp_path, offset):
    """The same scene 127 m or 4,000 km from the origin of its frame (a scan in a building's or a map's
    coordinates), camera included: imported, not refused as not in metres, with the levelling of the scene at the
    origin (the same rotation, objects and camera in the same places relative to each other within 1e-6 m), its
    bounding box centred horizontally on the origin, and the transform taking each source vertex to its place."""
    write_scene(tmp_path, "s", (10.0, 5.0))
    data = read_rest3d(tmp_path, "s", "sam3d")
    near = import_placed(data.objects, tmp_path / "near", PlacedParams(), data.camera)
    shift = np.asarray(offset)
    moved = [PlacedObject(o.id, o.mesh.copy().apply_translation(shift), o.description, o.source)
             for o in data.objects]
    cam = Camera(np.asarray(data.camera.eye) + shift, np.asarray(data.camera.target) + shift, data.camera.fov_y_deg)
    far = import_placed(moved, tmp_path / "far", PlacedParams(), cam)
    T_near, T_far = (np.asarray(json.loads((tmp_path / d / "import.json").read_text())["transform"])
                     for d in ("near", "far"))
    assert np.allclose(T_far[:3, :3], T_near[:3, :3], atol=1e-9)
    worlds = {o.id: o.world_mesh() for o in far.objects}
    lo = np.min([w.bounds[0] for w in worlds.values()], axis=0)
    hi = np.max([w.bounds[1] for w in worlds.values()], axis=0)
    assert np.allclose(0.5 * (lo + hi)[:2], 0.0, atol=1e-6)
    step = far.objects[0].pose[:3, 3] - near.get(far.objects[0].id).pose[:3, 3]
    assert abs(step[2]) < 1e-6  # the same ground
    for o in moved:
        assert np.allclose(far.get(o.id).pose[:3, 3], near.get(o.id).pose[:3, 3] + step, atol=1e-6)
        assert np.allclose(trimesh.transform_points(o.mesh.vertices, T_far).min(axis=0),
                           worlds[o.id].bounds[0], atol=1e-6)
    cams = [json.loads((tmp_path / d / "reference" / "camera.json").read_text()) for d in ("near", "far")]
    assert np.allclose(np.asarray(cams[1]["eye"]), np.asarray(cams[0]["eye"]) + step, atol=1e-6)


def test_reference_levelling_is_the_kabsch_rotation(tmp_path):
    R = write_scene(tmp_path, "s", (14.0, 0.0), variant="sam3d")
    write_scene(tmp_path, "s", (0.0, 0.0), variant="ours")
    assert angle_deg(reference_up(tmp_path, "s"), R @ [0, 1, 0]) < 1e-6
    assert scene_ids(tmp_path) == ["s"]


def test_another_methods_reconstruction_is_levelled_and_listed(tmp_path):
    # a Gen3DSR result (the same layout, tilted 10 deg) of scene t, which has no SAM 3D Objects result: imported
    # levelled within a degree of the tilt; listed for the variant gen3dsr, not for the real suites' sam3d + ours
    from phiscene.io.rest3d import ALL_VARIANTS, Rest3dSource

    write_scene(tmp_path, "s", (14.0, 0.0), variant="sam3d")
    write_scene(tmp_path, "s", (0.0, 0.0), variant="ours")
    write_scene(tmp_path, "t", (10.0, 0.0), variant="gen3dsr")
    assert scene_ids(tmp_path) == ["s"] and scene_ids(tmp_path, "gen3dsr") == ["t"] and scene_ids(tmp_path, "sg") == []
    scene = import_rest3d(tmp_path, "t", tmp_path / "out", "gen3dsr")
    assert scene.meta["levelling"]["rotation_deg"] == pytest.approx(10.0, abs=1.0)
    assert Rest3dSource.from_dict({"root": "r", "variant": "sg"}).variant == "sg"
    with pytest.raises(ValueError, match="variant must be one of"):
        Rest3dSource.from_dict({"root": "r", "variant": "midi"})
    import argparse

    from phiscene.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    variant = next(a for a in sub.choices["import-rest3d"]._actions if a.dest == "variant")
    assert tuple(variant.choices) == ALL_VARIANTS


def test_missing_data_names_the_path(tmp_path):
    with pytest.raises(InputError, match="REST3D data not found.*git clone --branch gh-pages"):
        read_rest3d(tmp_path / "nowhere", "custom_viga")
    write_scene(tmp_path, "s")
    with pytest.raises(InputError, match="has no ours result"):
        read_rest3d(tmp_path, "s", "ours")


def test_no_votes_keeps_the_prior():
    sphere = trimesh.creation.icosphere(3, 0.1)
    est = estimate_up({"ball": sphere}, [0, 0, 1], LevelParams(box_weight=0.0))
    assert est.tilt_deg == 0.0 and est.votes == {}


def test_own_frame_method_rotation_by_icp(tmp_path):
    """A peer result with its own meshes in its own frame: aligned by centres, each object's turn found by ICP."""
    from phiscene.meshes import save_mesh
    from phiscene.metrics.pose import pose_metrics
    from phiscene.scene import Scene, SceneObject
    from phiscene.transforms import make_pose, rotation_z

    box = trimesh.creation.box([0.4, 0.2, 0.1])
    a, b = save_mesh(box, tmp_path / "a.glb"), save_mesh(box, tmp_path / "b.glb")  # same shape, other files
    centres = [[0, 0, 0.05], [1, 0, 0.05], [0, 1, 0.05], [1, 1.5, 0.05]]
    initial = Scene([SceneObject(f"o{i}", a, make_pose(translation=c)) for i, c in enumerate(centres)])
    frame = make_pose(rotation_z(2.0), [5.0, -3.0, 0.0])  # the peer's own frame: turned and shifted
    turn = [0.0, np.radians(20.0), 0.0, np.radians(5.0)]
    peer = Scene([SceneObject(f"o{i}", b, frame @ make_pose(rotation_z(t), c)) for i, (c, t) in
                  enumerate(zip(centres, turn))])
    m = pose_metrics(peer, initial, align=True)
    assert m["displacement_max"] < 1e-6
    assert m["rotation_max"] == pytest.approx(20.0, abs=0.5)
    assert m["rotation_mean"] == pytest.approx(np.degrees(sum(turn)) / 4, abs=0.5)


def _box(lo, hi) -> np.ndarray:
    return trimesh.creation.box(bounds=np.array([lo, hi], dtype=float)).vertices


def test_floor_is_where_the_standing_objects_stand():
    # five objects on the floor whose bottoms err by depth (one sunk 15 cm), a book on one of them, a chair tucked
    # under a table and a poster high on a wall: the ground is the median of the five floor bottoms and the two
    # under/over the table, neither the sunk object's bottom (the lowest point) nor the book's or the poster's
    standing = {"a": 0.0, "b": 0.02, "sunk": -0.15, "c": 0.01, "d": 0.03}
    parts = [_box((3 * k, 0, z), (3 * k + 1, 1, z + 0.5)) for k, z in enumerate(standing.values())]
    parts.append(_box((0.2, 0.2, 0.5), (0.6, 0.6, 0.55)))  # book on "a" (its top 0.5 is below the book's middle)
    parts.append(_box((20, 0, 0.04), (21.2, 0.8, 0.8)))  # table (its top above the chair's middle) ...
    parts.append(_box((20.3, 0.2, 0.0), (20.7, 0.6, 0.9)))  # ... and the chair under it: both stand on the ground
    parts.append(_box((30, 0, 1.2), (30.6, 0.02, 1.8)))  # poster: nothing beneath, but 1.35 m above the lowest
    expected = float(np.median([*standing.values(), 0.04, 0.0]))
    assert floor_height(parts, 0.25) == pytest.approx(expected)
    assert floor_height(parts, 0.0) == pytest.approx(-0.15)  # band 0: the lowest point
    # levelling_transform puts that height at z = 0 (up already +z: a pure vertical shift)
    T = levelling_transform(parts, [0.0, 0.0, 1.0], floor_band=0.25)
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)
    assert T[2, 3] == pytest.approx(-expected)


def _tilted_slab(length: float, thickness: float, tilt_deg: float, centre_z: float) -> np.ndarray:
    """Vertices of a box ``length`` x 1 x ``thickness`` m turned ``tilt_deg`` about y through its centre."""
    slab = trimesh.creation.box((length, 1.0, thickness))
    slab.apply_transform(trimesh.transformations.rotation_matrix(np.radians(tilt_deg), [0, 1, 0]))
    slab.apply_translation([0.0, 0.0, centre_z])
    return np.asarray(slab.vertices)


@pytest.mark.parametrize("tilt", [1.5, 2.6, 8.0])
def test_floor_is_where_a_tilted_slab_would_rest(tilt):
    # a table-top slab 2.5 m long, 14 cm thick, centre at 0.5 m, tilted by a rotation error: its corner sinks
    # 1.25 sin(t) + 0.07 cos(t) below the centre, but turned flush about its centre (its resting facet, the bottom
    # face) its bottom is 0.07 below it. A plate above it does not stand on the ground (the rule for what is
    # beneath compares the slab's box top, its highest corner, with the plate's mid-height)
    slab = _tilted_slab(2.5, 0.14, tilt, 0.5)
    corner = 0.5 - 1.25 * np.sin(np.radians(tilt)) - 0.07 * np.cos(np.radians(tilt))
    assert slab[:, 2].min() == pytest.approx(corner)
    assert resting_bottom(slab, 20.0) == pytest.approx(0.43, abs=1e-9)
    assert resting_bottom(slab, 0.0) == pytest.approx(corner)  # 0: as it came
    plate = _box((-0.2, -0.2, 0.78), (0.2, 0.2, 0.81))
    assert floor_height([slab, plate], 0.25, 20.0) == pytest.approx(0.43, abs=1e-9)
    assert floor_height([slab, plate], 0.25) == pytest.approx(corner)
    T = levelling_transform([slab, plate], [0.0, 0.0, 1.0], floor_band=0.25, floor_rest_deg=20.0)
    assert T[2, 3] == pytest.approx(-0.43, abs=1e-9)


def test_resting_bottom_beyond_the_turn_or_flat_is_the_lowest_point():
    # tilted 30 deg, past the 20 deg turn: it rests as it came; a poster's quad has no volume to rest on
    slab = _tilted_slab(1.0, 0.1, 30.0, 1.0)
    assert resting_bottom(slab, 20.0) == pytest.approx(slab[:, 2].min())
    quad = np.array([[0.0, 0.0, 1.2], [0.6, 0.0, 1.2], [0.6, 0.0, 1.8], [0.0, 0.0, 1.8]])
    assert resting_bottom(quad, 20.0) == pytest.approx(1.2)
    assert resting_bottom(np.array([[0.0, 0.0, 0.3], [1.0, 0.0, 0.2], [2.0, 0.0, 0.1]]), 20.0) == pytest.approx(0.1)


@pytest.mark.parametrize("power", [1.0, 0.5, 0.0])
def test_votes_weigh_area_to_the_power(power):
    # a large table top tilted 6 deg about x and two small level boxes: each votes its top's normal with weight
    # area ** power, and the estimate is the normalised weighted sum of the votes (all within the inlier cone)
    R = trimesh.transformations.rotation_matrix(np.radians(6.0), [1, 0, 0])
    slab = trimesh.creation.box([2.0, 1.0, 0.05]).subdivide().subdivide()  # enough faces for a planar region
    slab.apply_transform(R)
    cubes = [trimesh.creation.box([0.2, 0.2, 0.2]).subdivide().subdivide() for _ in range(2)]
    est = estimate_up({"slab": slab, "c1": cubes[0], "c2": cubes[1]}, [0, 0, 1],
                      LevelParams(weight_power=power, inlier_deg=20.0))
    areas = {"slab": 2.0, "c1": 0.04, "c2": 0.04}
    ups = {"slab": R[:3, :3] @ [0, 0, 1], "c1": np.array([0, 0, 1.0]), "c2": np.array([0, 0, 1.0])}
    for oid, area in areas.items():
        assert est.votes[oid]["kind"] == "plane"
        assert est.votes[oid]["area"] == pytest.approx(area, rel=1e-4)
        assert est.votes[oid]["weight"] == pytest.approx(area ** power, rel=1e-4)
    expected = sum(areas[o] ** power * ups[o] for o in areas)
    assert angle_deg(est.up, expected) < 0.01
    # the large object's tilt weighs 2 / 2.08 of the estimate at power 1, a third at power 0
    share = areas["slab"] ** power / sum(a ** power for a in areas.values())
    assert est.tilt_deg == pytest.approx(angle_deg(expected, [0, 0, 1]), abs=0.01)
    assert est.tilt_deg == pytest.approx(6.0 * share, abs=0.1)


def test_estimate_is_the_mode_with_most_votes_not_the_mean_of_all():
    # one large board leaning 30 deg about x (its face is the heaviest vote) and two small boxes tilted 2 and 4 deg
    # about y: the votes form two groups 30 deg apart, farther than the inlier cone (10 deg). The estimate is the
    # weighted mean of the group that holds more votes (the two boxes). Started from the mean of all votes alone,
    # the mean shift ends on the board, whose weight pulls that mean within its cone
    def tilted(mesh, angle, axis):
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(angle), axis))
        return mesh

    board = tilted(trimesh.creation.box([1.2, 1.2, 0.02]).subdivide().subdivide(), 30.0, [1, 0, 0])
    c1 = tilted(trimesh.creation.box([0.2, 0.2, 0.2]).subdivide().subdivide(), 2.0, [0, 1, 0])
    c2 = tilted(trimesh.creation.box([0.2, 0.2, 0.2]).subdivide().subdivide(), 4.0, [0, 1, 0])
    est = estimate_up({"board": board, "c1": c1, "c2": c2}, [0, 0, 1], LevelParams())
    assert all(est.votes[o]["kind"] == "plane" for o in ("board", "c1", "c2"))
    assert est.votes["board"]["weight"] > est.votes["c1"]["weight"] + est.votes["c2"]["weight"]
    ups = {o: np.asarray(est.votes[o]["up"]) for o in ("c1", "c2")}
    expected = sum(est.votes[o]["weight"] * ups[o] for o in ups)
    assert angle_deg(est.up, expected) < 0.01
    assert angle_deg(est.up, [0, 0, 1]) == pytest.approx(3.0, abs=0.3)  # between 2 and 4 deg, about y
    assert [o for o, v in est.votes.items() if v["inlier"]] == ["c1", "c2"]
    mean = sum(est.votes[o]["weight"] * np.asarray(est.votes[o]["up"]) for o in est.votes)
    assert angle_deg(mean, est.votes["board"]["up"]) < 10.0


def test_a_refused_import_writes_nothing_and_keeps_the_last_one(tmp_path):
    """Each refusal names the source file and the problem, and the output folder keeps the earlier import whole:
    two actors whose names keep the same id (only [A-Za-z0-9_.-] of a name is kept), no actors, a camera whose eye
    is its target, a mesh with no volume, an output path that is a file."""
    import shutil

    write_scene(tmp_path, "s")
    out = tmp_path / "out"
    import_rest3d(tmp_path, "s", out)
    before = {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert any(p.suffix == ".glb" for p in before)
    folder = tmp_path / "assets/s/sam3d"
    pristine = json.loads((folder / "simulation.json").read_text())

    def broken(edit, match):
        shutil.rmtree(tmp_path / "assets/bad", ignore_errors=True)
        shutil.copytree(tmp_path / "assets/s", tmp_path / "assets/bad")
        sim = json.loads(json.dumps(pristine))
        edit(sim, tmp_path / "assets/bad/sam3d")
        (tmp_path / "assets/bad/sam3d/simulation.json").write_text(json.dumps(sim))
        with pytest.raises(InputError, match=match):
            import_rest3d(tmp_path, "bad", out)
        after = {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
        assert after == before
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".out")] == []  # no staging folder left

    def twin(sim, f):  # "Kiste 1" and "Kiste_1" both keep the id Kiste_1
        for name in ("Kiste 1", "Kiste_1"):
            shutil.copy(f / "meshes/cardboard_box_000.glb", f / "meshes" / f"{name}.glb")
            sim["actors"].append(name)
            sim["tracks"][name] = sim["tracks"]["cardboard_box_000"]

    broken(twin, r"Kiste_1.glb: object id 'Kiste_1' is also the id of .*Kiste 1.glb")
    broken(lambda sim, f: sim.update(actors=[]), r"simulation.json: actors: no actors")
    broken(lambda sim, f: sim["camera"].update(target=sim["camera"]["position"]), r"camera: .* finite and apart")

    def flat(sim, f):
        trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).export(f / "meshes/white_plate_000.glb")

    broken(flat, r"white_plate_000.glb: mesh has no volume")
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match=r"afile: output folder is an existing file"):
        import_rest3d(tmp_path, "s", tmp_path / "afile")


@pytest.mark.parametrize("tilt", [(50.0, 0.0), (-45.0, 20.0), (0.0, -50.0), (48.0, 8.0)])
def test_a_steeply_tilted_scene_is_levelled_from_a_steeper_prior(tmp_path, monkeypatch, tilt):
    # a camera looking steeply down puts the scene's up farther from the camera's up than the votes' cone reaches
    # (max_tilt_deg 40): too few votes agree there, and the estimate from a prior STEEP_PRIOR_DEG steeper finds the
    # analytic up within a degree; without that retry it does not. (This four-object fixture is levelled at up to 50
    # deg of tilt, not at 54; the real scenes of benchmarks/levelling_tilts.py reach farther on some, less on others)
    R = write_scene(tmp_path, "s", tilt)
    data = read_rest3d(tmp_path, "s", "sam3d")
    truth = R @ np.array([0.0, 1.0, 0.0])
    lev = level_objects(data.objects, PlacedParams(), data.camera)
    assert angle_deg(source_up(lev), truth) < 1.0
    assert lev.estimate.steep_prior is not None and "steep_prior" in lev.estimate.to_dict()
    monkeypatch.setattr("phiscene.levelling.MIN_AGREEMENT", 0)  # never retried
    assert angle_deg(source_up(level_objects(data.objects, PlacedParams(), data.camera)), truth) > 5.0
