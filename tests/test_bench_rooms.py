"""Tests of the rooms suite of the embedded benchmark (phiscene.bench.furniture, phiscene.bench.rooms).

Oracles: exact union volumes of axis-aligned boxes (inclusion-exclusion), exact polygon
distances and grid sampling for footprints, an independent re-simulation for rest, and
the templates' own intent (which piece should carry which object) for the GT edges.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from simcheck import resimulate

from phiscene.bench.build import build_scene, with_suite_defaults
from phiscene.bench.cleanmesh import is_clean
from phiscene.bench.furniture import DESIGNS, FURNITURE_CYCLE, TOP_CATEGORIES, design_meta, furniture_asset
from phiscene.bench.rooms import ROOMS_DEFAULTS, Footprint, separation
from phiscene.bench.templates import TEMPLATES, TemplateParams, template_names
from phiscene.proxies import ProxyParams
from phiscene.render import project, read_camera
from phiscene.scene import Scene, load_scene
from phiscene.schemas import read_json
from phiscene.sim.settings import SimSettings
from phiscene.transforms import make_pose, rotation_angle, rotation_z

#: A bedroom of six objects: bed, two nightstands, wardrobe, and (top_object_p = 1) two small objects.
BEDROOM = {"n_assets": 16, "n_objects": [6, 6], "templates": ["bedroom"], "template": {"top_object_p": 1.0}}
COACD = ProxyParams()
FURNITURE = sorted(set(FURNITURE_CYCLE) - {"lamp", "vase"})


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("rooms-cache")


@pytest.fixture(scope="module")
def bedroom(tmp_path_factory, cache) -> Path:
    out = tmp_path_factory.mktemp("rooms") / "bedroom"
    build_scene(out, "rooms", 0, BEDROOM, cache)
    return out


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _box_union_volume(boxes: list[np.ndarray]) -> float:
    """Exact volume of a union of axis-aligned boxes ((2, 3) bounds each), by inclusion-exclusion."""
    total = 0.0
    for k in range(1, len(boxes) + 1):
        for subset in itertools.combinations(boxes, k):
            lo = np.max([b[0] for b in subset], axis=0)
            hi = np.min([b[1] for b in subset], axis=0)
            total += (-1) ** (k + 1) * float(np.prod(np.clip(hi - lo, 0.0, None)))
    return total


@pytest.mark.parametrize("category", sorted(DESIGNS))
def test_furniture_is_one_clean_solid_at_real_size(category):
    rng_seed = [7, sorted(DESIGNS).index(category)]
    design = DESIGNS[category](np.random.default_rng(rng_seed))
    asset = furniture_asset(category, category, np.random.default_rng(rng_seed))
    m = asset.mesh
    assert is_clean(m) and m.body_count == 1 and m.is_watertight
    assert np.allclose(m.bounds.mean(axis=0), 0.0, atol=1e-6)
    assert np.allclose(m.extents, design_meta(design)["size"], atol=1e-4)
    if all(p.shape == "box" for p in design.parts):
        # the union of the boxes, exactly (float32 vertices: 1e-4 relative)
        assert m.volume == pytest.approx(_box_union_volume([p.bounds for p in design.parts]), rel=1e-4)
    size = {"bed": (1.9, 2.2), "wardrobe": (1.7, 2.2), "sofa": (1.5, 2.4), "dining_table": (1.1, 1.9),
            "bookcase": (1.4, 2.1), "lamp": (0.2, 0.6), "vase": (0.15, 0.35), "chair": (0.8, 1.0),
            "nightstand": (0.4, 0.65)}
    if category in size:  # longest side at real furniture scale (m)
        lo, hi = size[category]
        assert lo <= m.extents.max() <= hi, (category, m.extents)
    top = asset.meta.get("top")
    if top is not None:  # the carrying surface is the top of the mesh, inside its outline
        assert top["z"] == pytest.approx(m.bounds[1, 2], abs=1e-5)
        c, h = np.asarray(top["center"]), np.asarray(top["half"])
        assert (c - h >= m.bounds[0, :2] - 1e-5).all() and (c + h <= m.bounds[1, :2] + 1e-5).all()
        # mesh vertices reach that height all over the rectangle's corners
        v = m.vertices[np.abs(m.vertices[:, 2] - top["z"]) < 1e-5][:, :2]
        assert (v.min(axis=0) <= c - h + 1e-5).all() and (v.max(axis=0) >= c + h - 1e-5).all()


def test_descriptions_read_like_captions():
    bed = furniture_asset("bed", "bed", np.random.default_rng(0))
    words = bed.description.split()
    assert words[-1] == "m" and "bed" in words and ("double" in words or "single" in words)
    assert float(words[-2]) == pytest.approx(bed.extents[1], abs=0.06)  # "wooden double bed 2.0 m": its length


def _exact_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two disjoint convex polygons ((4, 2) corners): min vertex-to-edge distance."""
    def point_segment(p, s0, s1):
        t = np.clip(np.dot(p - s0, s1 - s0) / np.dot(s1 - s0, s1 - s0), 0, 1)
        return np.linalg.norm(p - (s0 + t * (s1 - s0)))

    out = np.inf
    for P, Q in ((a, b), (b, a)):
        for p in P:
            for k in range(4):
                out = min(out, point_segment(p, Q[k], Q[(k + 1) % 4]))
    return float(out)


def _inside(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Points (n, 2) inside a counter-clockwise convex polygon."""
    edges = np.roll(corners, -1, axis=0) - corners
    rel = points[:, None, :] - corners[None]
    return ((edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]) >= 0).all(axis=1)


def _fp(center, yaw, half) -> Footprint:
    return Footprint(np.asarray(center, float), rotation_z(yaw)[:2, :2], np.asarray(half, float))


def test_footprint_separation():
    # analytic: unit squares 0.3 m apart along x; a 45-degree square's corner 0.2 m from a face
    assert separation(_fp((0, 0), 0, (0.5, 0.5)), _fp((1.3, 0.2), 0, (0.5, 0.5))) == pytest.approx(0.3)
    r = 0.5 * np.sqrt(2)
    assert separation(_fp((0, 0), 0, (0.5, 0.5)), _fp((0.7 + r, 0), np.pi / 4, (0.5, 0.5))) == pytest.approx(0.2)
    # random pairs: overlapping (a grid point inside both) => separation <= 0;
    # separated => a lower bound on the exact distance
    rng = np.random.default_rng(3)
    grid = np.stack(np.meshgrid(np.linspace(-2, 2, 161), np.linspace(-2, 2, 161)), -1).reshape(-1, 2)
    seen = set()
    for _ in range(200):
        a = _fp(rng.uniform(-0.8, 0.8, 2), rng.uniform(-np.pi, np.pi), rng.uniform(0.1, 0.6, 2))
        b = _fp(rng.uniform(-0.8, 0.8, 2), rng.uniform(-np.pi, np.pi), rng.uniform(0.1, 0.6, 2))
        s = separation(a, b)
        overlap = bool((_inside(grid, a.corners()) & _inside(grid, b.corners())).any())
        seen.add(overlap)
        if overlap:
            assert s <= 0
        elif s > 0:
            assert s <= _exact_distance(a.corners(), b.corners()) + 1e-9
    assert seen == {True, False}


@pytest.mark.parametrize("name", ["bedroom", "living", "dining", "office"])
def test_templates_place_isolated_furniture(name, cache):
    from phiscene.bench.furniture import rooms_library

    lib = rooms_library(0, 16, cache)
    params = TemplateParams.from_dict(ROOMS_DEFAULTS["template"])
    for seed in range(4):
        n = 3 + seed
        pl = TEMPLATES["rooms"][name](lib, n, np.random.default_rng([seed, 5]), params)
        assert len(pl) == n
        ground = [p for p in pl if p.supporters == (-1,)]
        tops = [p for p in pl if p.supporters != (-1,)]
        assert all(p.asset.category in TOP_CATEGORIES for p in tops)
        assert all(p.asset.category not in TOP_CATEGORIES for p in ground)
        for a, b in itertools.combinations(ground, 2):
            assert separation(Footprint.of(a.asset, a.pose), Footprint.of(b.asset, b.pose)) >= params.clearance - 1e-9
        for p in ground:  # upright, a few millimetres above the floor
            lowest = (p.asset.mesh.vertices @ p.pose[:3, :3].T + p.pose[:3, 3])[:, 2].min()
            assert params.gap_min - 1e-9 <= lowest <= params.gap_max + 1e-9
            assert p.pose[2, 2] == pytest.approx(1.0)
        for t in tops:  # inside the host's top, just above it
            host = pl[t.supporters[0]]
            w = t.asset.mesh.vertices @ t.pose[:3, :3].T + t.pose[:3, 3]
            local = (w[:, :2] - host.pose[:2, 3]) @ host.pose[:2, :2]
            top = host.asset.meta["top"]
            assert (np.abs(local - top["center"]) <= np.asarray(top["half"]) + 1e-9).all()
            assert w[:, 2].min() - (host.pose[2, 3] + top["z"]) == pytest.approx(0.0035, abs=0.0016)
        if name == "dining":  # chairs put at the table (not moved elsewhere) face it; their front is local -y
            table = pl[0]
            near = [p for p in ground if p.asset.category == "chair" and separation(
                Footprint.of(p.asset, p.pose), Footprint.of(table.asset, table.pose)) <= 3 * params.clearance + 1e-9]
            assert near
            for c in near:
                to_table = table.pose[:2, 3] - c.pose[:2, 3]
                front = -c.pose[:2, 1]
                assert np.dot(front, to_table) > 0


def test_suite_defaults_merge():
    assert with_suite_defaults("contact", {"seed": 3}) == {"seed": 3}
    merged = with_suite_defaults("rooms", {"n_objects": [4, 5], "degrade": {"scale_sigma": 0.01}})
    assert merged["n_objects"] == [4, 5] and merged["template"] == ROOMS_DEFAULTS["template"]
    assert merged["degrade"] == {**ROOMS_DEFAULTS["degrade"], "scale_sigma": 0.01}
    assert template_names("rooms") == ["bedroom", "living", "dining", "office"]


def _resimulate(scene: Scene, cache: Path, seconds: float = 2.0) -> tuple[float, float]:
    """Independent re-simulation with the coacd proxies: max drift (m, deg) of any object."""
    return resimulate(scene, cache, COACD, seconds)


def test_bedroom_scene(bedroom, cache):
    gt = load_scene(bedroom / "gt/scene.json")
    cats = {o.id: o.meta["category"] for o in gt.objects}
    assert len(gt) == 6 and sorted(cats.values()).count("nightstand") == 2
    assert {"bed", "wardrobe"} <= set(cats.values())
    # at rest
    dt, dr = _resimulate(gt, cache)
    assert dt < 1e-3 and dr < 0.5
    # GT edges: the ground carries the furniture, each small object stands on the piece meant for it
    topo = read_json(bedroom / "gt/topology.json")
    edges = {(e["from"], e["to"]) for e in topo["edges"]}
    intended = {(s, o.id) for o in gt.objects for s in o.meta["intended_supporters"]}
    assert edges == intended
    tops = [o for o in gt.objects if o.meta["role"] == "top"]
    assert len(tops) == 2 and all(cats[o.id] in TOP_CATEGORIES for o in tops)
    assert all(cats[o.meta["intended_supporters"][0]] == "nightstand" for o in tops)
    assert {(a, b) for a, b in edges if a == "ground"} == {("ground", i) for i, c in cats.items()
                                                             if c not in TOP_CATEGORIES}
    # footprints (convex hulls of the world meshes' top views) overlap only for a top and its piece
    world = {o.id: o.world_mesh() for o in gt.objects}
    hull = {i: m.vertices[ConvexHull(m.vertices[:, :2]).vertices, :2] for i, m in world.items()}
    for a, b in itertools.combinations(gt.ids, 2):
        grid_lo = np.maximum(hull[a].min(axis=0), hull[b].min(axis=0))
        grid_hi = np.minimum(hull[a].max(axis=0), hull[b].max(axis=0))
        related = (a, b) in edges or (b, a) in edges
        if (grid_hi <= grid_lo).any():
            assert not related
            continue
        g = np.stack(np.meshgrid(*[np.linspace(grid_lo[k], grid_hi[k], 60) for k in range(2)]), -1).reshape(-1, 2)
        both = (_inside(g, _ccw(hull[a])) & _inside(g, _ccw(hull[b]))).mean()
        assert (both > 0) == related, (a, b, both)
    for o in tops:  # resting on the nightstand's top
        host = world[o.meta["intended_supporters"][0]]
        assert world[o.id].bounds[0, 2] == pytest.approx(host.bounds[1, 2], abs=2e-3)
    # the camera frames the whole room
    cam = read_camera(bedroom / "reference/camera.json")
    for m in world.values():
        uv = project(cam, m.vertices)
        assert (uv >= -0.5).all() and (uv[:, 0] <= cam["width"] - 0.5).all() and (uv[:, 1] <= cam["height"] - 0.5).all()


def _ccw(points: np.ndarray) -> np.ndarray:
    """Polygon vertices (n, 2) in counter-clockwise order."""
    c = points.mean(axis=0)
    return points[np.argsort(np.arctan2(points[:, 1] - c[1], points[:, 0] - c[0]))]


def test_rooms_initial_scene_is_degraded_at_furniture_scale(bedroom):
    gt, init = load_scene(bedroom / "gt/scene.json"), load_scene(bedroom / "initial/scene.json")
    d = ROOMS_DEFAULTS["degrade"]
    assert init.meta["degrade"] == d
    for a, b in zip(gt.objects, init.objects):
        err = b.meta["degrade"]
        assert d["vertical_offset_min"] <= err["vertical_offset"] <= d["vertical_offset_max"]
        assert np.allclose(b.pose[:3, 3] - a.pose[:3, 3], np.add(err["translation"], [0, 0, err["vertical_offset"]]))


def test_rooms_scene_is_deterministic(bedroom, cache, tmp_path):
    again = tmp_path / "bedroom"
    build_scene(again, "rooms", 0, BEDROOM, cache)
    assert _files(again) == _files(bedroom)


def test_every_furniture_kind_stands_still(tmp_path, cache):
    # each kind alone on the floor, dropped from 3 mm with its CoACD proxies: it lands and stays put
    from phiscene.bench.groundtruth import GTParams, ground_truth
    from phiscene.meshes import save_mesh
    from phiscene.scene import SceneObject

    objs = []
    for k, cat in enumerate(FURNITURE):
        a = furniture_asset(cat, cat, np.random.default_rng([11, k]))
        pose = make_pose(rotation_z(0.3 * k), (3.0 * (k % 4), 3.0 * (k // 4), a.extents[2] / 2 + 0.003))
        objs.append(SceneObject(f"obj_{k + 1:02d}", save_mesh(a.mesh, tmp_path / f"{cat}.glb").resolve(), pose,
                                meta={"category": cat}))
    gt = ground_truth(Scene(objs), SimSettings(), COACD, cache, GTParams(verify_seconds=1.0),
                      {o.id: {"ground"} for o in objs})
    assert gt.problem is None
    for o, r in zip(objs, gt.scene.objects):  # settled by the gap, without tipping
        assert r.pose[2, 3] == pytest.approx(o.pose[2, 3] - 0.003, abs=1e-3)
        assert np.degrees(rotation_angle(o.pose[:3, :3], r.pose[:3, :3])) < 0.5
