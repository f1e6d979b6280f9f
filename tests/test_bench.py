"""Tests of the embedded benchmark generator (phiscene.bench).

Scenes are built with single-hull proxies (backend "convex") and small scenes to
stay fast; the physics oracles are independent re-simulations and closed-form
expectations.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from simcheck import resimulate

from phiscene.bench.assets import CATEGORY_CYCLE, asset_library
from phiscene.bench.build import BenchParams, build_scene, default_params, scene_seed
from phiscene.bench.cleanmesh import MAX_FACES, canonical, is_clean, remesh_union, simplify_clean
from phiscene.bench.degrade import DegradeParams, degrade_scene
from phiscene.bench.groundtruth import GTParams, ground_truth, release
from phiscene.bench.templates import TEMPLATES, template_names
from phiscene.meshes import save_mesh
from phiscene.proxies import ProxyParams, proxy_for_mesh
from phiscene.render import (
    RenderParams,
    camera_elevation,
    camera_for,
    colors_to_labels,
    hidden_objects,
    instance_labels,
    load_png,
    project,
    raised_cameras,
    read_camera,
    render_instance_mask,
)
from phiscene.scene import Scene, SceneObject, load_scene
from phiscene.schemas import read_json, validate
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, make_pose, rotation_angle

FAST = {"proxies": {"backend": "convex"}, "n_assets": 16, "n_objects": [3, 4],
        "render": {"width": 160, "height": 120, "min_visible_pixels": 10}}
CONVEX = ProxyParams(backend="convex")


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("bench-cache")


@pytest.fixture(scope="module")
def stack_scene(tmp_path_factory, cache) -> Path:
    out = tmp_path_factory.mktemp("bench") / "stack"
    build_scene(out, "contact", 0, {**FAST, "templates": ["stack"]}, cache)
    return out


@pytest.fixture(scope="module")
def leaning_scene(tmp_path_factory, cache) -> Path:
    out = tmp_path_factory.mktemp("bench") / "leaning"
    build_scene(out, "contact", 1, {**FAST, "templates": ["leaning"]}, cache)
    return out


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_canonical_joins_overlapping_shells():
    # two overlapping unit-ish boxes: one clean closed surface with the union's volume, centred on its bbox
    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = trimesh.creation.box(extents=(0.1, 0.1, 0.1)).apply_translation((0.05, 0.0, 0.0))
    m = canonical(trimesh.util.concatenate([a, b]))
    assert is_clean(m) and m.body_count == 1
    assert m.volume == pytest.approx(0.15 * 0.1 * 0.1, rel=1e-5)
    assert np.allclose(m.bounds.mean(axis=0), 0.0, atol=1e-7)


def test_remesh_union_of_touching_shells():
    # two cubes sharing a face (a union that exact booleans leave as two touching pieces)
    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = trimesh.creation.box(extents=(0.1, 0.1, 0.1)).apply_translation((0.1, 0.0, 0.0))
    m = remesh_union([a, b], pitch=0.004)
    assert m.is_volume and m.body_count == 1
    assert m.volume == pytest.approx(2e-3, rel=0.03)  # edges are bevelled by about one grid cell


def test_shape_thinner_than_the_remesh_cells_is_no_candidate():
    # a 1 mm sheet remeshed on 1 cm cells leaves nothing: simplify_clean says so (None) instead of failing on an
    # empty mesh, so canonical() tries finer cells, then reports the asset (a blob slot then takes its next blob)
    sheet = trimesh.creation.box(extents=(0.1, 0.1, 0.001))
    empty = remesh_union([sheet], pitch=0.01)
    assert len(empty.faces) == 0
    assert simplify_clean(empty, MAX_FACES) is None
    # pybullet_data's random_urdfs/297 is such a shape at every cell size tried: a clear error naming its file
    from phiscene.bench.assets import blob_mesh
    from phiscene.errors import InputError

    with pytest.raises(InputError, match="297.obj.*could not make a clean closed mesh"):
        blob_mesh(297)


def test_asset_library(tmp_path):
    lib = asset_library(3, 16, tmp_path)
    assert [a.category for a in lib] == list(CATEGORY_CYCLE) and len({a.name for a in lib}) == 16
    cheap = [a for a in lib if a.category not in ("prop", "ball")]
    for a in cheap:
        m = a.mesh
        assert is_clean(m) and len(m.faces) <= MAX_FACES
        assert np.allclose(m.bounds.mean(axis=0), 0.0, atol=1e-6)
        assert 0.01 < m.extents.max() < 0.8  # metric, tabletop sizes
    # deterministic, and a disk-cached asset is the same mesh
    again = asset_library(3, 16, tmp_path / "other")
    fresh = [b for b in again if b.category not in ("prop", "ball")]
    assert all(np.array_equal(a.mesh.vertices, b.mesh.vertices) and a.description == b.description
               for a, b in zip(cheap, fresh))
    asset_library.cache_clear()
    cached = [b for b in asset_library(3, 16, tmp_path) if b.category not in ("prop", "ball")]
    assert all(np.array_equal(a.mesh.vertices, b.mesh.vertices) for a, b in zip(cheap, cached))
    # containers are open-topped: their inner floor is below the rim
    tray = next(a for a in lib if a.category == "tray")
    assert tray.meta["floor"] < tray.mesh.bounds[1, 2] - 0.02


def test_layout_and_formats(stack_scene):
    for rel in ("gt/scene.json", "gt/topology.json", "initial/scene.json", "reference/image.png",
                "reference/segmentation.png", "reference/camera.json"):
        assert (stack_scene / rel).is_file(), rel
    gt, init = load_scene(stack_scene / "gt/scene.json"), load_scene(stack_scene / "initial/scene.json")
    assert gt.ids == init.ids == [f"obj_{k + 1:02d}" for k in range(len(gt))]
    assert [o.mesh_path for o in gt.objects] == [o.mesh_path for o in init.objects]
    assert all(o.mesh_path.parent == (stack_scene / "meshes").resolve() for o in gt.objects)
    assert gt.camera == init.camera == (stack_scene / "reference/camera.json").resolve()
    topo = read_json(stack_scene / "gt/topology.json")
    validate(topo, "topology", stack_scene / "gt/topology.json")
    assert topo["backend"] == "gt" and topo["objects"] == ["ground", *gt.ids]
    assert gt.meta["template"] == "stack" and isinstance(gt.meta["seed"], int)
    # the initial scene must not leak the template's support intent
    assert all("role" not in o.meta and "intended_supporters" not in o.meta for o in init.objects)
    # every object rests on something, and the graph only names known nodes
    assert {e["to"] for e in topo["edges"]} == set(gt.ids)
    assert {e["from"] for e in topo["edges"]} <= {"ground", *gt.ids}


def _resimulate(scene: Scene, cache: Path, seconds: float = 2.0) -> tuple[float, float]:
    """Independent re-simulation with the convex proxies: max drift (m, deg) of any object."""
    return resimulate(scene, cache, CONVEX, seconds)


def test_gt_scene_is_at_rest(stack_scene, cache):
    dt, dr = _resimulate(load_scene(stack_scene / "gt/scene.json"), cache)
    assert dt < 1e-3 and dr < 0.5
    # and nothing floats: every object's lowest point is at the ground or on another object
    gt = load_scene(stack_scene / "gt/scene.json")
    assert min(o.world_mesh().bounds[0, 2] for o in gt.objects) < 2e-3


def test_initial_scene_is_not_at_rest(stack_scene, cache):
    dt, _ = _resimulate(load_scene(stack_scene / "initial/scene.json"), cache, seconds=1.0)
    assert dt > 2e-3


def _box_scene(tmp: Path, boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]]) -> Scene:
    objs = []
    for k, (size, centre) in enumerate(boxes):
        path = save_mesh(trimesh.creation.box(extents=size), tmp / f"b{k}.glb")
        objs.append(SceneObject(f"obj_{k + 1:02d}", path.resolve(), make_pose(translation=centre), meta={}))
    return Scene(objs)


def test_two_stack_edges(tmp_path):
    # bottom box on the ground, a smaller box on top, a third box standing alone
    scene = _box_scene(tmp_path, [((0.2, 0.2, 0.1), (0, 0, 0.052)), ((0.1, 0.1, 0.1), (0.01, 0, 0.155)),
                                  ((0.1, 0.1, 0.1), (0.4, 0, 0.052))])
    intended = {"obj_01": {"ground"}, "obj_02": {"obj_01"}, "obj_03": {"ground"}}
    gt = ground_truth(scene, SimSettings(), CONVEX, tmp_path, GTParams(), intended)
    assert gt.problem is None
    edges = {(e["from"], e["to"]) for e in gt.edges}
    assert edges == {("ground", "obj_01"), ("obj_01", "obj_02"), ("ground", "obj_03")}
    assert all(e["relation"] == "supports" and e["confidence"] == 1.0 for e in gt.edges)
    # rest poses: the boxes dropped by their gaps onto their supports (within solver slop)
    z = {o.id: o.pose[2, 3] for o in gt.scene.objects}
    assert z["obj_01"] == pytest.approx(0.05, abs=1e-3) and z["obj_02"] == pytest.approx(0.15, abs=1e-3)


def test_contact_forces_balance_weights(tmp_path):
    # Newton: at rest the ground carries the weight of the whole stack
    scene = _box_scene(tmp_path, [((0.2, 0.2, 0.1), (0, 0, 0.05)), ((0.1, 0.1, 0.1), (0, 0, 0.15))])
    s = SimSettings()
    m = release(scene, s, {o.id: proxy_for_mesh(o.mesh_path, CONVEX, tmp_path) for o in scene.objects}, tmp_path,
                GTParams(verify_seconds=1.0))
    on_bottom_from_ground = sum(f if a == "obj_01" else -f for (a, b), f in m.forces.items()
                                if {a, b} == {"obj_01", "ground"})
    total = (m.masses["obj_01"] + m.masses["obj_02"]) * 9.81
    assert on_bottom_from_ground[2] == pytest.approx(total, rel=0.02)
    # flat contacts: normal forces alone carry the weights, pointing straight up
    assert m.normal_forces[("obj_02", "obj_01")] == pytest.approx([0, 0, m.masses["obj_02"] * 9.81], rel=0.02,
                                                                  abs=1e-3)
    assert m.normal_forces[("obj_01", "obj_02")] == pytest.approx(-m.normal_forces[("obj_02", "obj_01")], abs=1e-9)


def test_unstable_scene_is_rejected(tmp_path):
    # a box balanced on a thin edge far off its support topples: rejected, not silently kept
    scene = _box_scene(tmp_path, [((0.1, 0.1, 0.1), (0, 0, 0.05)), ((0.3, 0.05, 0.02), (0.13, 0, 0.112))])
    gt = ground_truth(scene, SimSettings(), CONVEX, tmp_path, GTParams(), {"obj_02": {"obj_01"}})
    assert gt.problem is not None


def test_degradation_respects_magnitudes(tmp_path):
    n = 400
    path = save_mesh(trimesh.creation.box(extents=(0.1, 0.1, 0.1)), tmp_path / "b.glb").resolve()
    rng = np.random.default_rng(0)
    gt = Scene([SceneObject(f"o{k}", path, make_pose(trimesh.transformations.random_rotation_matrix(
        rand=rng.random(3))[:3, :3], rng.uniform(-1, 1, 3))) for k in range(n)])
    p = DegradeParams()
    init = degrade_scene(gt, p, seed=7)
    d_xy, d_z, ang, scale, off = [], [], [], [], []
    for a, b in zip(gt.objects, init.objects):
        (Ra, ta, sa), (Rb, tb, sb) = decompose(a.pose), decompose(b.pose)
        err = b.meta["degrade"]
        # the recorded errors are the ones applied
        assert np.allclose(tb - ta, np.add(err["translation"], [0, 0, err["vertical_offset"]]), atol=1e-12)
        assert np.degrees(rotation_angle(Ra, Rb)) == pytest.approx(err["rotation_deg"], abs=1e-6)
        assert sb / sa == pytest.approx(err["scale"], rel=1e-9)
        d_xy += list(tb[:2] - ta[:2])
        d_z.append(err["translation"][2])
        off.append(err["vertical_offset"])
        ang.append(err["rotation_deg"])
        scale.append(sb / sa)
    d_xy, d_z, off, ang, scale = map(np.asarray, (d_xy, d_z, off, ang, scale))
    k = p.truncate * (1 + 1e-9)  # truncation at 3 sigma, up to rounding
    assert np.abs(d_xy).max() <= k * p.translation_xy_sigma and np.abs(d_z).max() <= k * p.translation_z_sigma
    assert off.min() >= p.vertical_offset_min and off.max() <= p.vertical_offset_max
    assert ang.max() <= k * p.rotation_sigma_deg and np.abs(scale - 1).max() <= k * p.scale_sigma
    # the spreads are the configured ones (400 samples: 10 % tolerance)
    assert np.std(d_xy) == pytest.approx(p.translation_xy_sigma, rel=0.1)
    assert np.std(scale) == pytest.approx(p.scale_sigma, rel=0.1)
    assert np.sqrt(np.mean(ang**2)) == pytest.approx(p.rotation_sigma_deg, rel=0.1)
    # some objects sink and some float, in proportion to the offset range
    frac_sink = np.mean(off < 0)
    assert frac_sink == pytest.approx(-p.vertical_offset_min / (p.vertical_offset_max - p.vertical_offset_min),
                                      abs=0.08)
    # the same seed gives the same scene
    again = degrade_scene(gt, p, seed=7)
    assert all(np.array_equal(a.pose, b.pose) for a, b in zip(init.objects, again.objects))


def test_same_params_give_identical_bytes(stack_scene, cache, tmp_path):
    again = tmp_path / "stack"
    build_scene(again, "contact", 0, {**FAST, "templates": ["stack"]}, cache)
    assert _files(again) == _files(stack_scene)
    # rebuilding over an existing folder replaces it atomically with the same content
    build_scene(again, "contact", 0, {**FAST, "templates": ["stack"]}, cache)
    assert _files(again) == _files(stack_scene)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_scene_seed_is_stable():
    assert scene_seed(0, "contact", 3) == scene_seed(0, "contact", 3)
    assert len({scene_seed(0, "contact", i) for i in range(100)}) == 100
    assert scene_seed(0, "contact", 3) != scene_seed(1, "contact", 3) != scene_seed(0, "rooms", 3)
    assert scene_seed(0, "contact", 3) == 8508669136180139273  # independent of PYTHONHASHSEED and platform


def test_segmentation_matches_scene_colors(stack_scene):
    gt = load_scene(stack_scene / "gt/scene.json")
    seg = load_png(stack_scene / "reference/segmentation.png")
    colors = [tuple(o.color) for o in gt.objects]
    assert len(set(colors)) == len(colors) and (0, 0, 0) not in colors
    found = {tuple(c) for c in np.unique(seg.reshape(-1, 3), axis=0)}
    assert found == set(colors) | {(0, 0, 0)}
    labels = colors_to_labels(seg, colors)
    counts = np.bincount(labels[labels >= 0], minlength=len(colors))
    assert (counts >= FAST["render"]["min_visible_pixels"]).all()
    # camera.json is right: each object's mask lies inside the projection of its mesh
    cam = read_camera(stack_scene / "reference/camera.json")
    assert (cam["width"], cam["height"]) == (160, 120) and seg.shape == (120, 160, 3)
    T = np.asarray(cam["world_to_camera"])
    assert np.allclose(T @ np.asarray(cam["camera_to_world"]), np.eye(4), atol=1e-9)
    for k, o in enumerate(gt.objects):
        uv = project(cam, o.world_mesh().vertices)
        vs, us = np.nonzero(labels == k)
        assert us.min() >= uv[:, 0].min() - 1 and us.max() <= uv[:, 0].max() + 1
        assert vs.min() >= uv[:, 1].min() - 1 and vs.max() <= uv[:, 1].max() + 1
    # re-rendering the GT scene from camera.json reproduces the segmentation
    assert np.array_equal(render_instance_mask(gt, stack_scene / "reference/camera.json"), labels)


def test_leaning_board_has_two_supporters(leaning_scene):
    gt = load_scene(leaning_scene / "gt/scene.json")
    board = next(o for o in gt.objects if o.meta["role"] == "board")
    support = next(o for o in gt.objects if o.meta["role"] == "support")
    topo = read_json(leaning_scene / "gt/topology.json")
    relations = {e["from"]: e["relation"] for e in topo["edges"] if e["to"] == board.id}
    assert relations == {"ground": "supports", support.id: "leans_on"}
    # the board really leans: tilted well away from lying flat and from standing upright
    R, _, _ = decompose(board.pose)
    long_axis = R[:, 0]
    tilt = np.degrees(np.arcsin(abs(long_axis[2])))
    assert 20 < tilt < 80


def test_default_params_round_trip():
    d = default_params()
    assert BenchParams.from_dict(d) == BenchParams()
    assert json.loads(json.dumps(d)) == d  # plain data, fit for config.yaml


def test_params_are_checked(tmp_path):
    with pytest.raises(ValueError, match="unknown benchmark parameters"):
        BenchParams.from_dict({"sed": 1})
    with pytest.raises(ValueError, match="unknown degradation parameters"):
        BenchParams.from_dict({"degrade": {"sigma": 1}})
    with pytest.raises(ValueError, match="unknown templates"):
        build_scene(tmp_path / "x", "contact", 0, {"templates": ["pyramid"]}, tmp_path)
    with pytest.raises(KeyError, match="unknown benchmark suite"):
        build_scene(tmp_path / "x", "kitchen", 0, {}, tmp_path)
    assert not (tmp_path / "x").exists()


def test_registry_is_per_suite():
    assert template_names("contact") == ["stack", "leaning", "bridge", "containment", "tabletop"]
    assert all(callable(f) for f in TEMPLATES["contact"].values())


def test_raised_cameras_see_what_the_configured_view_hides(tmp_path):
    # a 20 cm cube behind a 70 cm wall 50 cm nearer the camera: hidden at the configured 35 deg and at 45 (a line
    # of sight from its near top edge clears the wall only above tan(el) = (0.7 - 0.2) / 0.4), seen from higher up
    params = RenderParams(width=160, height=120)
    az = np.radians(params.azimuth_deg)
    toward = np.array([np.cos(az), np.sin(az), 0.0])  # horizontal direction from the cube towards the camera
    wall = trimesh.creation.box([0.04, 1.2, 0.7])
    wall.apply_transform(trimesh.transformations.rotation_matrix(az, [0, 0, 1]))
    scene = Scene([SceneObject("cube", save_mesh(trimesh.creation.box([0.2] * 3), tmp_path / "cube.glb"),
                               make_pose(translation=[0, 0, 0.1])),
                   SceneObject("wall", save_mesh(wall, tmp_path / "wall.glb"),
                               make_pose(translation=0.5 * toward + 0.35 * np.array([0, 0, 1.0])))])
    configured = camera_for(scene, params)
    assert camera_elevation(configured) == pytest.approx(35.0, abs=1e-6)
    assert hidden_objects(scene, instance_labels(scene, configured), 10) == ["cube"]
    raised = raised_cameras(scene, params)
    assert [round(camera_elevation(c), 6) for c in raised] == [45.0, 55.0, 65.0]
    seen = [not hidden_objects(scene, instance_labels(scene, c), 10) for c in raised]
    assert seen[0] is False and seen[-1] is True


def test_scene_hidden_from_the_configured_view_is_built_from_a_raised_one(tmp_path, cache):
    # a camera 20 deg below the horizon sees only the ground slab: every attempt hides every object, and the
    # scene is built from the first raised view that sees them all (at or above the horizon), not refused
    params = {**FAST, "templates": ["stack"], "max_attempts": 1,
              "render": {**FAST["render"], "elevation_deg": -20.0}}
    out = tmp_path / "low"
    build_scene(out, "contact", 0, params, cache)
    camera = read_camera(out / "reference" / "camera.json")
    assert camera_elevation(camera) >= 0.0
    scene = load_scene(out / "gt" / "scene.json")
    assert hidden_objects(scene, instance_labels(scene, camera), 10) == []
