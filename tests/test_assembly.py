"""Assembly: SDF grids, penetration resolution, settling and the sequential loop.

Oracles are analytic box geometry, the exact SDF of :mod:`phiscene.sdf`,
closed-form statics (a box whose centre of mass is over its support stays,
one whose centre of mass overhangs tips) and a free release in a fresh world.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
import torch
import trimesh
from scenes import box_meshes, box_scene, clearance, convex_proxies

from phiscene.assembly import (
    AssemblyParams,
    PenetrationParams,
    SettleParams,
    full_order,
    ground_scene,
    resolve_penetration,
    sdf_body,
    settle_object,
)
from phiscene.assembly.penetration import (
    AdamState,
    min_translation_search,
    minimize_hinge,
    search_directions,
    upward_clearance,
)
from phiscene.errors import InputError
from phiscene.inertia import rigid_props
from phiscene.meshes import mesh_hash
from phiscene.proxies import ProxyParams, scene_proxies
from phiscene.scene import Scene
from phiscene.sdf import signed_distance
from phiscene.sdf_grid import GridParams, clear_memory_cache, grid_box, near_surface_points, sdf_grid
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.transforms import make_pose, random_rotation, rotation_z

torch.set_num_threads(1)
SIM = SimSettings()
EPS = PenetrationParams().eps


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A folder with box meshes (name -> path) and a shared cache."""
    root = tmp_path_factory.mktemp("assembly")
    sizes = {"big": (0.4, 0.4, 0.2), "cube": (0.1, 0.1, 0.1), "plank": (0.4, 0.1, 0.02), "slab": (0.6, 0.6, 0.1)}
    return {"root": root, "cache": root / "cache", "meshes": box_meshes(root, sizes), "sizes": sizes}


def make_scene(work, placements: dict[str, tuple[str, np.ndarray]]) -> Scene:
    """A scene of box meshes: id -> (mesh name, pose)."""
    return box_scene(work["meshes"], placements)


def ground(work, scene: Scene, order=None, **params):
    proxies = convex_proxies(scene, work["cache"])
    return ground_scene(scene, scene.ids if order is None else order, proxies, AssemblyParams.from_dict(params),
                        SIM, work["cache"])


def bottom(scene: Scene, oid: str) -> float:
    return float(scene.get(oid).world_mesh().bounds[0, 2])


def top(scene: Scene, oid: str) -> float:
    return float(scene.get(oid).world_mesh().bounds[1, 2])


# -- SDF grid --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mesh, max_err, mean_err", [
    (trimesh.creation.box((0.3, 0.2, 0.1)), 3e-3, 1e-4),
    (trimesh.creation.icosphere(2, 0.1), 1e-3, 1e-4),
    (trimesh.creation.box((0.8, 0.3, 0.02)), 6e-3, 3e-4),  # a plank: thin axis refined
])
def test_grid_matches_exact_sdf_near_surface(mesh, max_err, mean_err):
    grid = sdf_grid(mesh, GridParams(), None)
    pts = near_surface_points(mesh, 0.02, 5000, seed=7)
    err = np.abs(grid.query_numpy(pts) - signed_distance(mesh, pts))
    assert err.max() < max_err and err.mean() < mean_err, (err.max(), err.mean())
    assert err.max() <= grid.cell_diagonal  # the interpolation bound
    assert grid.error["max_abs"] < max_err and grid.error["band"] == 0.02


def test_grid_exact_near_faces_and_lower_bound_outside():
    mesh = trimesh.creation.box((0.2, 0.2, 0.2))
    grid = sdf_grid(mesh, GridParams(exact_margin=None), None)  # exact at every node
    # over a face centre the SDF is linear: trilinear interpolation is exact, inside and outside
    z = np.linspace(-0.05, 0.05, 41)
    pts = np.column_stack([np.full_like(z, 0.01), np.full_like(z, -0.02), 0.1 + z])
    assert np.allclose(grid.query_numpy(pts), z, atol=1e-9)
    # far outside the grid box: lookup grows with distance and stays a lower bound up to one cell diagonal
    far = np.array([[3.0, 0.0, 0.0], [0.0, -2.0, 1.0], [5.0, 5.0, 5.0]])
    exact = signed_distance(mesh, far)
    got = grid.query_numpy(far)
    assert np.all(got >= exact - grid.cell_diagonal) and np.allclose(got, exact, atol=0.01)
    assert got[0] == pytest.approx(2.9, abs=1e-9)
    line = np.column_stack([np.linspace(0.5, 4.0, 8), np.zeros(8), np.zeros(8)])
    assert np.all(np.diff(grid.query_numpy(line)) > 0.49)


def _open_box() -> trimesh.Trimesh:
    """A 0.4 m box without its top: inside it the winding number crosses 1/2 far from every wall."""
    box = trimesh.creation.box((0.4, 0.4, 0.4))
    keep = box.face_normals[:, 2] < 0.5
    return trimesh.Trimesh(box.vertices, box.faces[keep], process=False)


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(3, 0.1), trimesh.creation.annulus(0.05, 0.12, 0.1),
                                  _open_box()], ids=["sphere", "ring", "open box"])
def test_narrow_band_grid_reads_as_the_exact_grid_to_every_hinge(mesh):
    exact = sdf_grid(mesh, GridParams(exact_margin=None), None)
    band = sdf_grid(mesh, GridParams(), None)  # exact_margin 0.02
    diff = exact.values != band.values
    assert diff.mean() > 0.2  # the band does skip nodes
    # only nodes outside and farther than the band differ, and they keep a lower bound beyond it
    assert np.all(exact.values[diff] > 0.02 + band.cell_diagonal)
    assert np.all(band.values[diff] <= exact.values[diff] + 1e-12)
    assert np.all(band.values[diff] > 0.02 + band.cell_diagonal)
    # every hinge relu(eps - sdf) with eps <= 0.02 has the same value and gradient, in and around the box
    rng = np.random.default_rng(0)
    pts = rng.uniform(exact.lo - 0.1, exact.hi + 0.1, size=(20000, 3))
    for eps in (0.0, 0.005, 0.02):
        grads, losses = [], []
        for g in (exact, band):
            p = torch.tensor(pts, requires_grad=True)
            loss = torch.relu(eps - g.query_local(p))
            loss.sum().backward()
            losses.append(loss.detach().numpy())
            grads.append(p.grad.numpy())
        assert np.array_equal(losses[0], losses[1]) and np.array_equal(grads[0], grads[1])
        assert (losses[0] > 0).any()


def test_grid_margin_follows_the_callers_clearance():
    mesh = trimesh.creation.icosphere(3, 0.1)
    exact = sdf_grid(mesh, GridParams(exact_margin=None), None)
    wide = sdf_grid(mesh, GridParams(), None, clearance=0.06)  # e.g. eps 6 mm on a mesh scaled by 0.1
    assert wide.params_hash == GridParams(exact_margin=0.06).digest()
    assert np.array_equal(wide.values[exact.values <= 0.06 + wide.cell_diagonal],
                          exact.values[exact.values <= 0.06 + wide.cell_diagonal])
    assert sdf_grid(mesh, GridParams(), None, clearance=0.01).params_hash == GridParams().digest()
    body = sdf_body("s", mesh, make_pose(np.eye(3), (0, 0, 0), scale=0.1), 64, PenetrationParams(eps=0.006), None)
    assert body.grid.params_hash == wide.params_hash
    with pytest.raises(ValueError, match="exact_margin"):
        GridParams.from_dict({"exact_margin": 0.01})  # below error_band: the error would not be the exact grid's
    with pytest.raises(ValueError, match="coarse_stride"):
        GridParams.from_dict({"coarse_stride": 1})


def test_grid_gradient_is_face_normal():
    mesh = trimesh.creation.box((0.2, 0.2, 0.2))
    grid = sdf_grid(mesh, GridParams(), None)
    p = torch.tensor([[0.02, 0.01, 0.103], [0.099, 0.0, 0.0]], dtype=torch.float64, requires_grad=True)
    grid.query_local(p).sum().backward()
    assert np.allclose(p.grad.numpy(), [[0, 0, 1], [1, 0, 0]], atol=1e-9)


def test_grid_query_follows_pose_and_scale():
    mesh = trimesh.creation.icosphere(2, 0.1)
    grid = sdf_grid(mesh, GridParams(), None)
    pose = make_pose(random_rotation(np.random.default_rng(0), np.pi), (0.3, -0.2, 0.5), scale=1.7)
    world = mesh.copy()
    world.apply_transform(pose)
    pts = near_surface_points(world, 0.02, 2000, seed=3)
    err = np.abs(grid.query_numpy(pts, pose) - signed_distance(world, pts))
    assert err.max() < 1.7e-3


def test_grid_box_refines_thin_axes():
    lo, hi, shape = grid_box(trimesh.creation.box((1.0, 0.3, 0.02)), GridParams(resolution=64, cells_across=8))
    spacing = (hi - lo) / (np.asarray(shape) - 1)
    assert shape[0] == 64 and spacing[2] <= 0.02 / 8 + 1e-12
    assert np.all(lo < [-0.5, -0.15, -0.01]) and np.all(hi > [0.5, 0.15, 0.01])


def test_grid_disk_cache_roundtrip_and_corrupt_entry(tmp_path, caplog):
    mesh = trimesh.creation.box((0.1, 0.2, 0.3))
    params = GridParams(resolution=24)
    clear_memory_cache()
    g1 = sdf_grid(mesh, params, tmp_path)
    files = list((tmp_path / "sdf_grids").glob("*.npz"))
    assert len(files) == 1 and not list((tmp_path / "sdf_grids").glob(".*"))  # no temporary left behind
    clear_memory_cache()
    g2 = sdf_grid(mesh, params, tmp_path)
    assert np.array_equal(g1.values, g2.values) and g2.error == g1.error
    files[0].write_bytes(b"not an npz")
    clear_memory_cache()
    with caplog.at_level(logging.WARNING):
        g3 = sdf_grid(mesh, params, tmp_path)
    assert "rebuilding" in caplog.text
    assert np.array_equal(g1.values, g3.values)
    assert sdf_grid(mesh, params, tmp_path) is g3  # memory cache
    # an entry stored under another mesh's key is detected by its stored hash and rebuilt
    other = trimesh.creation.box((0.3, 0.2, 0.1))
    other_path = files[0].with_name(f"{mesh_hash(other)}-{params.digest()}.npz")
    other_path.write_bytes(files[0].read_bytes())
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        g4 = sdf_grid(other, params, tmp_path)
    assert "does not match" in caplog.text and g4.mesh_hash == mesh_hash(other)
    assert g4.values.shape != g1.values.shape


def test_grid_params_reject_unknown_keys():
    with pytest.raises(ValueError, match="resolutoin"):
        GridParams.from_dict({"resolutoin": 10})
    with pytest.raises(ValueError, match="bogus"):
        PenetrationParams.from_dict({"grid": {"bogus": 1}})
    with pytest.raises(ValueError, match="bogus"):
        AssemblyParams.from_dict({"settle_params": {"bogus": 1}})
    p = AssemblyParams.from_dict({"settle": False, "penetration_params": {"eps": 0.01, "grid": {"resolution": 32}}})
    assert not p.settle and p.penetration_params.eps == 0.01 and p.penetration_params.grid.resolution == 32
    assert AssemblyParams.from_dict(p.to_dict()) == p


# -- penetration -----------------------------------------------------------------------------------------------------
def _body(oid, mesh, pose, cache):
    pp = PenetrationParams()
    return sdf_body(oid, mesh, pose, pp.n_active, pp, cache)


def test_cube_penetrating_cube_ends_at_clearance_eps(work):
    big, cube = trimesh.creation.box((0.4, 0.4, 0.2)), trimesh.creation.box((0.1, 0.1, 0.1))
    lower = _body("lower", big, make_pose(translation=(0, 0, 0.1)), work["cache"])
    pose = make_pose(rotation_z(0.4), (0.03, -0.02, 0.2 + 0.05 - 0.02))  # 2 cm into the lower box
    upper = _body("upper", cube, pose, work["cache"])
    x, info = resolve_penetration(upper, [lower], 0.0, PenetrationParams())
    assert info["final_loss"] == 0.0 and 0 < info["iterations"] <= 300 and info["context"] == ["lower"]
    moved = cube.copy()
    moved.apply_transform(make_pose(rotation_z(0.4), pose[:3, 3] + x))
    world_lower = big.copy()
    world_lower.apply_translation((0, 0, 0.1))
    assert clearance(moved, world_lower) == pytest.approx(EPS, abs=1e-3)
    assert x[2] == pytest.approx(0.02 + EPS, abs=1e-3)


def test_direction_search_clears_where_gradient_steps_stall():
    """Two overlapping balls pushing the origin out along +x and -x: the gradient at the start is exactly zero, so
    gradient steps never move; the search leaves along y, by the analytic sqrt(r^2 - c^2) (along x it would take
    r + c)."""
    r, c = 0.1, 0.03
    centres = torch.tensor([[c, 0.0, 0.0], [-c, 0.0, 0.0]], dtype=torch.float64)

    def loss(x):
        return torch.relu(r - torch.linalg.vector_norm(x - centres, dim=1)).sum()

    x, info = minimize_hinge(loss, (3,), 0.005, 300, 12, "steepest")
    assert info["iterations"] == 300 and info["final_loss"] > 0 and np.all(x == 0.0)
    found = min_translation_search(loss, np.zeros(3), search_directions(16, planar=True), 0.01, 0.6, 30)
    assert abs(found[0]) < 1e-12 and found[2] == 0.0
    assert abs(found[1]) == pytest.approx(np.sqrt(r * r - c * c), abs=1e-9)
    assert min_translation_search(loss, np.zeros(3), search_directions(16, planar=True), 0.01, 0.05, 30) is None


def test_direction_search_resumed_farther_out_finds_the_same_way_out():
    """The search of the test above, marched to 5 cm only (nothing clears), then resumed beyond 5 cm with a coarser
    step, along the axes (3 cm: its probes at 8 and 11 cm find the way out along y, 9.5 cm, before the one along x,
    13 cm): the same way out, bisected to the analytic sqrt(r^2 - c^2)."""
    r, c = 0.1, 0.03
    centres = torch.tensor([[c, 0.0, 0.0], [-c, 0.0, 0.0]], dtype=torch.float64)

    def loss(x):
        return torch.relu(r - torch.linalg.vector_norm(x - centres, dim=1)).sum()

    dirs = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    assert min_translation_search(loss, np.zeros(3), dirs, 0.01, 0.05, 30) is None
    found = min_translation_search(loss, np.zeros(3), dirs, 0.03, 0.2, 30, start=0.05)
    assert abs(found[0]) < 1e-12 and abs(found[1]) == pytest.approx(np.sqrt(r * r - c * c), abs=1e-9)


@pytest.mark.parametrize("doublings", [3, 0])
def test_an_object_deep_inside_a_neighbour_is_searched_out_beyond_the_reach(work, monkeypatch, doublings):
    """A 10 cm cube on the floor in the middle of a 1.6 m wide, 20 cm thick slab (a reconstruction that put a chair
    through a table), pushed horizontally only: the nearest way out is 0.8 + 0.05 m + eps along x or y, farther
    than ``search_reach`` (0.6 m). The search goes on beyond it and finds it; without the doublings the cube stays
    inside."""
    from phiscene.assembly import penetration

    monkeypatch.setattr(penetration, "SEARCH_DOUBLINGS", doublings)
    slab_m, cube_m = trimesh.creation.box((1.6, 1.6, 0.2)), trimesh.creation.box((0.1, 0.1, 0.1))
    slab = _body("slab", slab_m, make_pose(translation=(0, 0, 0.1)), work["cache"])
    cube = _body("cube", cube_m, make_pose(translation=(0.01, 0.02, 0.05)), work["cache"])
    pp = PenetrationParams(optimizer="steepest", search_directions=32)
    x, info = resolve_penetration(cube, [slab], 0.0, pp, planar=True)
    if doublings == 0:
        assert info["final_loss"] > 0
        return
    assert info["final_loss"] == 0.0 and info["searched"] and x[2] == pytest.approx(EPS, abs=1e-9)  # off the floor
    # the nearest face is 0.78 m away along +y (the cube is 1 cm off centre in x, 2 cm in y)
    assert np.linalg.norm(x[:2]) == pytest.approx(0.8 - 0.02 + 0.05 + EPS, abs=0.03)
    moved = cube_m.copy().apply_translation(np.array([0.01, 0.02, 0.05]) + x)
    assert clearance(moved, slab_m.copy().apply_translation((0, 0, 0.1))) > EPS - 3e-3


def test_plank_jammed_across_a_gap_turns_free(work):
    """A 1 m plank whose two ends are each 1 cm inside a block from opposite sides (+x end from -y, -x end from +y,
    the blocks covering 0.3-0.8 m from the centre): no short translation clears both (sideways pushes cancel,
    out of the blocks lengthwise or over them is over 20 cm), a turn about z by (1 cm + eps) / 0.3 m does."""
    plank = trimesh.creation.box((1.0, 0.04, 0.04))
    block = trimesh.creation.box((0.5, 0.5, 0.4))
    a = _body("a", block, make_pose(translation=(0.55, -0.25 - 0.01, 0.5)), work["cache"])  # y up to -0.01
    b = _body("b", block, make_pose(translation=(-0.55, 0.25 + 0.01, 0.5)), work["cache"])  # y from +0.01
    active = _body("plank", plank, make_pose(translation=(0, 0, 0.5)), work["cache"])
    only, info = resolve_penetration(active, [a, b], None, PenetrationParams(optimizer="steepest"))
    assert info["final_loss"] > 0 or np.linalg.norm(only) > 0.2
    pp = PenetrationParams(optimizer="steepest", rotate_over=0.01)
    x, info = resolve_penetration(active, [a, b], None, pp)
    assert info["final_loss"] == 0.0
    w = np.asarray(info["rotation"])
    assert abs(w[0]) < 1e-3 and abs(w[1]) < 1e-3
    assert w[2] == pytest.approx((0.01 + EPS) / 0.3, abs=0.01)  # counter-clockwise about z
    assert np.linalg.norm(x) < 0.01
    # the pose the assembly makes of it clears both blocks by eps, up to the grids' error
    from phiscene.transforms import turned_about

    pose = turned_about(active.pose, w, np.asarray(info["pivot"]))
    pose[:3, 3] += x
    moved = plank.copy().apply_transform(pose)
    for body in (a, b):
        assert clearance(moved, block.copy().apply_transform(body.pose)) > EPS - 2e-3


def test_upward_clearance_goes_straight_up_or_around_an_overhang_and_rests(work):
    """A 10 cm cube sunk 3 cm into a slab: straight up clears it by the analytic 3 cm + eps. With an overhang 2 cm
    above its top, reaching 3 cm past its centre, straight up would have to pass the overhang (22.5 cm); the cube
    goes up and sideways past the overhang's edge instead (8 cm + eps in x) and is lowered back onto the slab,
    resting on it by eps."""
    slab_m, cube_m = trimesh.creation.box((0.6, 0.6, 0.06)), trimesh.creation.box((0.1, 0.1, 0.1))
    over_m = trimesh.creation.box((0.3, 0.6, 0.1))
    slab = _body("slab", slab_m, make_pose(translation=(0, 0, 0.03)), work["cache"])  # top at 0.06
    over = _body("over", over_m, make_pose(translation=(-0.12, 0, 0.2)), work["cache"])  # x up to 0.03, z from 0.15
    pose = make_pose(translation=(0, 0, 0.08))  # bottom 0.03 (3 cm into the slab), top 0.13
    cube = _body("cube", cube_m, pose, work["cache"])
    pp = PenetrationParams(search_directions=32)
    up = upward_clearance(cube, [slab], 0.0, pp, reach=0.3)
    assert up[0] == 0.0 and up[1] == 0.0 and up[2] == pytest.approx(0.03 + EPS, abs=1e-3)
    around = upward_clearance(cube, [slab, over], 0.0, pp, reach=0.3)
    assert around is not None and np.linalg.norm(around) < 0.2  # not over the overhang (22.5 cm straight up)
    moved = cube_m.copy().apply_transform(make_pose(translation=pose[:3, 3] + around))
    assert moved.bounds[0, 0] >= 0.03 + EPS - 2e-3  # past the overhang's edge
    assert clearance(moved, slab_m.copy().apply_translation((0, 0, 0.03))) == pytest.approx(EPS, abs=2e-3)  # rests
    assert clearance(moved, over_m.copy().apply_translation((-0.12, 0, 0.2))) > EPS - 2e-3
    assert upward_clearance(cube, [slab, over], 0.0, pp, reach=0.02) is None


def test_search_directions_are_unit_and_planar_ones_horizontal():
    sphere, ring = search_directions(32), search_directions(16, planar=True)
    np.testing.assert_allclose(np.linalg.norm(sphere, axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(ring, axis=1), 1.0)
    assert np.all(ring[:, 2] == 0.0) and abs(sphere.mean(axis=0)).max() < 0.05  # spread evenly


def test_plain_adam_overshoots_but_clears(work):
    big, cube = trimesh.creation.box((0.4, 0.4, 0.2)), trimesh.creation.box((0.1, 0.1, 0.1))
    lower = _body("lower", big, make_pose(translation=(0, 0, 0.1)), work["cache"])
    upper = _body("upper", cube, make_pose(translation=(0, 0, 0.23)), work["cache"])
    x, info = resolve_penetration(upper, [lower], 0.0, PenetrationParams(backtrack_steps=0))
    assert info["final_loss"] == 0.0 and info["backtracked"] == 0
    assert 0.02 + EPS - 1e-9 <= x[2] <= 0.02 + EPS + 2 * PenetrationParams().lr


def test_functional_adam_matches_torch_optim_adam():
    target = torch.tensor([0.3, -0.2, 0.05], dtype=torch.float64)
    a = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    b = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    ours, reference = AdamState(a, 0.005), torch.optim.Adam([b], lr=0.005)
    for _ in range(50):
        ((a - target) ** 3).abs().sum().backward()
        ours.step()
        reference.zero_grad()
        ((b - target) ** 3).abs().sum().backward()
        reference.step()
    assert torch.equal(a, b)


def test_sunk_box_is_lifted_straight_up_by_the_ground():
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    body = _body("c", cube, make_pose(translation=(0.5, 0.2, 0.02 + 0.2)), None)  # 3 cm below ground z = 0.2
    x, info = resolve_penetration(body, [], 0.2, PenetrationParams())
    assert info["final_loss"] == 0.0
    assert np.allclose(x[:2], 0.0, atol=1e-12)  # the ground gradient has no horizontal part
    assert x[2] == pytest.approx(0.03 + EPS, abs=1e-4)


def test_planar_push_clears_a_table_top_sideways_and_keeps_the_height(work):
    # a table top (fixed) 40-44 cm above the floor; a 43 cm box standing on the floor (2 eps above it, so the
    # ground term is idle) reaches 3 cm up into the top and 2 cm in under its edge at x = 0.2
    top = trimesh.creation.box((0.4, 0.4, 0.04))
    post = trimesh.creation.box((0.1, 0.1, 0.43))
    slab = _body("top", top, make_pose(translation=(0, 0, 0.42)), work["cache"])
    pose = make_pose(translation=(0.23, 0, 0.215 + 2 * EPS))
    active = _body("post", post, pose, work["cache"])
    x, info = resolve_penetration(active, [slab], 0.0, PenetrationParams(optimizer="steepest"), planar=True)
    assert info["final_loss"] == 0.0
    assert x[2] == 0.0  # its height is the floor's
    moved, world_top = post.copy(), top.copy()
    moved.apply_translation(pose[:3, 3] + x)
    world_top.apply_translation((0, 0, 0.42))
    # the shortest horizontal way out: 2 cm + eps along +x (the top's edge), to within one step
    assert x[0] == pytest.approx(0.02 + EPS, abs=PenetrationParams().lr) and abs(x[1]) < 0.005
    assert clearance(moved, world_top) >= EPS - 1e-3
    # the ground still pushes in every direction: the same box sunk 1 cm into the floor rises out of it by
    # 1 cm + eps (its top then 4 cm into the table top), and leaves the table top sideways
    sunk = _body("post", post, make_pose(translation=(0.23, 0, 0.215 - 0.01)), work["cache"])
    x2, info2 = resolve_penetration(sunk, [slab], 0.0, PenetrationParams(optimizer="steepest"), planar=True)
    assert info2["final_loss"] == 0.0
    lr = PenetrationParams().lr  # steepest descent moves in steps of lr: within one step of the exit
    assert 0.01 + EPS - 1e-4 <= x2[2] <= 0.01 + EPS + lr and x2[0] >= 0.02 + EPS - 1e-3


def test_clear_object_does_not_move_and_far_objects_are_pruned(work):
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    a = _body("a", cube, make_pose(translation=(0, 0, 0.3)), work["cache"])
    far = _body("far", cube, make_pose(translation=(2.0, 0, 0.05)), work["cache"])
    near = _body("near", cube, make_pose(translation=(0, 0, 0.3 - 0.1 - 0.01)), work["cache"])  # 1 cm below a
    x, info = resolve_penetration(a, [far, near], 0.0, PenetrationParams())
    assert info["iterations"] == 0 and info["initial_loss"] == 0.0 and np.all(x == 0.0)
    assert info["context"] == ["near"]  # evaluated (within reach) but clear; "far" pruned


def test_pruning_does_not_change_the_solution(work):
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    lower = _body("lower", cube, make_pose(translation=(0, 0, 0.05)), work["cache"])
    upper = _body("upper", cube, make_pose(translation=(0.01, 0, 0.14)), work["cache"])
    distant = [_body(f"d{i}", cube, make_pose(translation=(1.0 + i, 0, 0.05)), work["cache"]) for i in range(3)]
    x1, i1 = resolve_penetration(upper, [lower], 0.0, PenetrationParams())
    x2, i2 = resolve_penetration(upper, [lower, *distant], 0.0, PenetrationParams())
    assert np.array_equal(x1, x2) and i1["iterations"] == i2["iterations"] and i2["context"] == ["lower"]


# -- settling --------------------------------------------------------------------------------------------------------
def test_box_on_box_settles_without_penetration_or_drift(work):
    scene = make_scene(work, {"base": ("big", make_pose(translation=(0, 0, 0.095))),  # 5 mm into the ground
                              "top": ("cube", make_pose(rotation_z(0.3), (0.05, 0.02, 0.2 + 0.05 - 0.02)))})
    out, rec = ground(work, scene)
    for oid in ("base", "top"):
        assert rec["objects"][oid]["settled"] is True and rec["objects"][oid]["settle_remedy"] == "none"
    assert bottom(out, "base") == pytest.approx(0.0, abs=1e-4)
    assert bottom(out, "top") - top(out, "base") == pytest.approx(0.0, abs=1e-4)  # resting contact, no penetration
    assert clearance(out.get("top").world_mesh(), out.get("base").world_mesh()) > -1e-4
    # release everything together for 120 frames in a fresh world: nothing moves
    proxies = scene_proxies(out, ProxyParams(backend="convex"), work["cache"])
    with BulletWorld(SIM, work["cache"]) as world:
        world.add_ground(0.0)
        for o in out.objects:
            world.add_body(o.id, proxies[o.id].hulls, o.pose, rigid_props(o.mesh(), proxies[o.id].hulls, SIM.density))
        world.step_frames(120)
        for o in out.objects:
            assert np.linalg.norm(world.pose(o.id)[:3, 3] - o.pose[:3, 3]) < 1e-4
    json.dumps(rec, allow_nan=False)


def test_floating_box_falls_to_the_ground(work):
    scene = make_scene(work, {"c": ("cube", make_pose(rotation_z(0.2), (0.1, 0.1, 0.05 + 0.03)))})
    out, rec = ground(work, scene)
    r = rec["objects"]["c"]
    assert r["sdf_iterations"] == 0 and r["settled"] is True
    assert bottom(out, "c") == pytest.approx(0.0, abs=1e-3)
    assert r["displacement"] == pytest.approx(0.03, abs=1e-3)


def test_overhanging_plank_tips_and_supported_plank_stays(work):
    support = make_pose(translation=(0, 0, 0.05))
    plank_z = 0.1 + 0.01  # resting exactly on the support
    stable = make_scene(work, {"s": ("cube", support), "p": ("plank", make_pose(translation=(0.0, 0, plank_z)))})
    tipping = make_scene(work, {"s": ("cube", support), "p": ("plank", make_pose(translation=(0.17, 0, plank_z)))})
    _, rec_s = ground(work, stable, penetration=False)
    _, rec_t = ground(work, tipping, penetration=False)
    s, t = rec_s["objects"]["p"], rec_t["objects"]["p"]
    assert s["settled"] is True and s["settle_translation"] < 1e-4 and s["settle_rotation"] < 1e-3
    assert t["settle_translation"] > 0.02 and t["settle_rotation"] > 0.2  # fell off the support edge


def test_unsettled_object_is_reported(work):
    scene = make_scene(work, {"c": ("cube", make_pose(translation=(0, 0, 1.0)))})
    tiny = {"window": 5, "max_frames": 10, "extra_frames": 0, "ramp_frames": 0}
    _, rec = ground(work, scene, settle_params=tiny)
    r = rec["objects"]["c"]
    assert r["settled"] is False and r["settle_remedy"] == "failed" and r["settle_frames"] == 10
    assert r["residual_translation"] > 1e-2  # still falling
    assert rec["summary"]["unsettled"] == ["c"]
    # the same object given extra frames settles through the first remedy
    _, rec = ground(work, scene, settle_params={**tiny, "extra_frames": 200})
    assert rec["objects"]["c"]["settled"] is True and rec["objects"]["c"]["settle_remedy"] == "extra_frames"


def test_damping_ramp_remedy_is_verified(work):
    cube = trimesh.creation.box((0.1, 0.1, 0.1))
    hulls = [np.asarray(cube.vertices)]
    params = SettleParams(window=5, max_frames=6, extra_frames=0, ramp_frames=120, ramp_damping=0.95)
    with BulletWorld(SIM, work["cache"]) as world:
        world.add_ground(0.0)
        world.add_body("c", hulls, make_pose(translation=(0, 0, 0.3)), rigid_props(cube, hulls, SIM.density))
        res = settle_object(world, "c", params)
    assert res.settled and res.remedy == "damping"
    assert res.pose[2, 3] == pytest.approx(0.05, abs=1e-3)  # on the ground, not frozen in mid air
    assert res.residual_translation < params.eps_pos


def test_incremental_world_matches_a_fresh_world(work):
    big, cube = trimesh.creation.box((0.4, 0.4, 0.2)), trimesh.creation.box((0.1, 0.1, 0.1))
    hb, hc = [np.asarray(big.vertices)], [np.asarray(cube.vertices)]
    pose_c = make_pose(rotation_z(0.3), (0.05, 0, 0.26))
    with BulletWorld(SIM, work["cache"]) as world:
        world.add_ground(0.0)
        world.add_body("b", hb, make_pose(translation=(0, 0, 0.105)), rigid_props(big, hb, SIM.density))
        settled_b = settle_object(world, "b", SettleParams()).pose
        world.set_static("b")
        world.add_body("c", hc, pose_c, rigid_props(cube, hc, SIM.density))
        incremental = settle_object(world, "c", SettleParams())
    with BulletWorld(SIM, work["cache"]) as world:
        world.add_ground(0.0)
        world.add_body("b", hb, settled_b, None)
        world.add_body("c", hc, pose_c, rigid_props(cube, hc, SIM.density))
        fresh = settle_object(world, "c", SettleParams())
    assert incremental.frames == fresh.frames
    assert np.allclose(incremental.pose, fresh.pose, atol=1e-9)


# -- the loop ---------------------------------------------------------------------------------------------------------
def test_order_is_validated_and_completed(work, caplog):
    scene = make_scene(work, {"a": ("big", make_pose(translation=(0, 0, 0.1))),
                              "b": ("cube", make_pose(translation=(1, 0, 0.05)))})
    assert full_order(scene, ["ground", "b"]) == (["b", "a"], ["a"])
    with pytest.raises(InputError, match="order.*nope"):
        full_order(scene, ["a", "nope"])
    with pytest.raises(InputError, match="more than once"):
        full_order(scene, ["a", "a", "b"])
    with caplog.at_level(logging.WARNING):
        _, rec = ground(work, scene, order=["b"], settle=False)
    assert rec["order"] == ["b", "a"] and rec["appended"] == ["a"] and "appended" in caplog.text


def test_ablation_switches(work):
    scene = make_scene(work, {"a": ("big", make_pose(translation=(0, 0, 0.09)))})  # 1 cm into the ground
    out, rec = ground(work, scene, settle=False)
    r = rec["objects"]["a"]
    assert r["settled"] is None and r["settle_frames"] == 0
    assert bottom(out, "a") == pytest.approx(EPS, abs=1e-4)  # SDF only: lifted to the clearance
    assert np.allclose(out.get("a").pose[:3, 3], scene.get("a").pose[:3, 3] + r["sdf_translation"])
    out, rec = ground(work, scene, penetration=False)
    r = rec["objects"]["a"]
    assert r["sdf_iterations"] == 0 and r["sdf_final_loss"] is None and r["settled"] is True
    assert bottom(out, "a") == pytest.approx(0.0, abs=1e-3)  # sim only: pushed out by the contact solver
    assert np.allclose(out.get("a").mesh().vertices, scene.get("a").mesh().vertices)  # poses only


def test_missing_proxies_is_an_input_error(work):
    scene = make_scene(work, {"a": ("cube", make_pose(translation=(0, 0, 0.05)))})
    with pytest.raises(InputError, match="proxies"):
        ground_scene(scene, ["a"], {}, AssemblyParams(), SIM, work["cache"])
