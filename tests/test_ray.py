"""Remedy ``ray``: a gap to the supporter closed along the camera ray, where a depth error puts it.

Oracles: the pinhole projection (a point moved along the ray through it projects to the same pixel), closed-form
heights of boxes on boxes, and the statics of a box resting on a table (it settles where it is lowered to).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scenes import convex_proxies

from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.assembly.beneath import vertical_gap
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.starts import along_ray, ray_corrected
from phiscene.meshes import save_mesh
from phiscene.render import camera_eye, look_at_camera, project
from phiscene.scene import Scene, SceneObject
from phiscene.sim.settings import SimSettings
from phiscene.topology.graph import SupportEdge, SupportGraph
from phiscene.transforms import make_pose, transform_points

torch.set_num_threads(1)
SIM = SimSettings()

#: A camera 2 m back and 1.5 m up, looking at the table top: rays pitched about 37 deg down.
CAMERA = look_at_camera(np.array([0.0, -2.0, 2.0]), np.array([0.0, 0.0, 0.5]), 320, 240, 45.0, 0.05, 20.0)
EYE = camera_eye(CAMERA)

TABLE_TOP = 0.5  # m, the table (a 1 x 1 x 0.5 box on the ground)
CUBE = 0.1  # m, side of the object


def table() -> trimesh.Trimesh:
    return trimesh.creation.box((1.0, 1.0, TABLE_TOP), make_pose(translation=(0.0, 0.0, TABLE_TOP / 2)))


def cube_points() -> np.ndarray:
    return trimesh.creation.box((CUBE, CUBE, CUBE)).vertices


def cube_pose(x: float, y: float, bottom: float) -> np.ndarray:
    return make_pose(translation=(x, y, bottom + CUBE / 2))


def test_camera_eye_is_the_look_at_centre():
    np.testing.assert_allclose(EYE, [0.0, -2.0, 2.0], atol=1e-6)


def test_vertical_gap_is_the_height_above_the_surface_under_the_object():
    pts = transform_points(cube_pose(0.1, 0.0, TABLE_TOP + 0.03), cube_points())
    assert vertical_gap(pts, {"table": table()}, 0.0) == pytest.approx(0.03, abs=1e-9)
    sunk = transform_points(cube_pose(0.1, 0.0, TABLE_TOP - 0.02), cube_points())
    assert vertical_gap(sunk, {"table": table()}, 0.0) == pytest.approx(-0.02, abs=1e-9)
    assert vertical_gap(pts, {"ground": None}, 0.1) == pytest.approx(TABLE_TOP + 0.03 - 0.1, abs=1e-9)
    beside = transform_points(cube_pose(0.8, 0.0, TABLE_TOP + 0.03), cube_points())
    assert vertical_gap(beside, {"table": table()}, 0.0) is None  # nothing of the table under it


def test_vertical_gap_is_to_the_shelf_board_under_the_object_not_the_one_above():
    lower = trimesh.creation.box((0.6, 0.4, 0.02), make_pose(translation=(0.0, 0.0, 0.29)))
    upper = trimesh.creation.box((0.6, 0.4, 0.02), make_pose(translation=(0.0, 0.0, 0.69)))
    shelf = trimesh.util.concatenate([lower, upper])
    pts = transform_points(cube_pose(0.0, 0.0, 0.30 + 0.04), cube_points())
    assert vertical_gap(pts, {"shelf": shelf}, 0.0) == pytest.approx(0.04, abs=1e-9)


def test_a_shift_along_the_ray_keeps_the_object_on_the_same_pixel_and_drops_it_by_the_gap():
    pose = cube_pose(0.1, 0.1, TABLE_TOP + 0.04)
    com = np.zeros(3)
    moved, t = along_ray(pose, com, EYE, 0.04, 1.0, 10.0, 0.15)
    assert t > 0  # floating: it was put too far, it goes away from the camera
    assert moved[2, 3] == pytest.approx(pose[2, 3] - 0.04, abs=1e-12)
    np.testing.assert_allclose(project(CAMERA, moved[None, :3, 3]), project(CAMERA, pose[None, :3, 3]), atol=1e-6)
    half, t_half = along_ray(pose, com, EYE, 0.04, 0.5, 10.0, 0.15)
    assert t_half == pytest.approx(t / 2) and half[2, 3] == pytest.approx(pose[2, 3] - 0.02, abs=1e-12)
    up, t_up = along_ray(cube_pose(0.1, 0.1, TABLE_TOP - 0.02), com, EYE, -0.02, 1.0, 10.0, 0.15)
    assert t_up < 0 and up[2, 3] == pytest.approx(TABLE_TOP - 0.02 + CUBE / 2 + 0.02, abs=1e-12)


def test_no_shift_past_the_bound_or_along_a_flat_ray():
    pose = cube_pose(0.1, 0.1, TABLE_TOP + 0.3)
    # closing 30 cm along a ray pitched ~37 deg takes ~0.5 m: more than a depth error explains
    assert along_ray(pose, np.zeros(3), EYE, 0.3, 0.5, 10.0, 0.15)[1] == 0.0
    level_eye = np.array([0.1, -2.0, pose[2, 3]])
    out, t = along_ray(pose, np.zeros(3), level_eye, 0.03, 1.0, 10.0, 0.15)
    assert t == 0.0 and out is pose


def test_ray_correction_is_not_made_where_it_would_leave_the_supporter():
    fp = FaithfulParams(enabled=True, ray=True, ray_share=1.0)
    inside = cube_pose(0.0, 0.0, TABLE_TOP + 0.04)
    moved, t = ray_corrected(inside, cube_points(), np.zeros(3), {"table": table()}, 0.0, EYE, fp)
    assert t > 0 and moved[2, 3] == pytest.approx(inside[2, 3] - 0.04, abs=1e-9)
    # at the back edge: the shift away from the camera would take it past the edge (the surface under it ends)
    edge = cube_pose(0.0, 0.5 - CUBE / 2 - 0.01, TABLE_TOP + 0.04)
    kept, t_edge = ray_corrected(edge, cube_points(), np.zeros(3), {"table": table()}, 0.0, EYE, fp)
    assert t_edge == 0.0 and kept is edge


@pytest.fixture(scope="module")
def table_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("ray")
    return {"cache": root / "cache", "table": save_mesh(table().apply_translation((0, 0, -TABLE_TOP / 2)),
                                                        root / "table.obj"),
            "cube": save_mesh(trimesh.creation.box((CUBE, CUBE, CUBE)), root / "cube.obj")}


def run(table_scene, ray: bool, eye=EYE):
    cube = cube_pose(0.05, 0.0, TABLE_TOP + 0.03)  # floats 3 cm above the table
    scene = Scene([SceneObject("table", table_scene["table"], make_pose(translation=(0, 0, TABLE_TOP / 2)), "table"),
                   SceneObject("cube", table_scene["cube"], cube, "box")])
    graph = SupportGraph(objects=["table", "cube"], edges=[SupportEdge("ground", "table", "supports"),
                                                           SupportEdge("table", "cube", "supports")],
                         order=["table", "cube"])
    proxies = convex_proxies(scene, table_scene["cache"])
    params = AssemblyParams.from_dict({"faithful": {"enabled": True, "ray": ray, "ray_share": 1.0}})
    out, rec = ground_scene(scene, ["table", "cube"], proxies, params, SIM, table_scene["cache"], graph=graph,
                            eye=eye)
    return cube, np.asarray(out.get("cube").pose), rec["objects"]["cube"]


def test_a_floating_box_lands_on_the_table_on_the_pixel_it_was_seen_at(table_scene):
    start, end, rec = run(table_scene, ray=True)
    assert rec["certificate"]["settled"] and rec["certificate"]["supporters_kept"]
    assert end[2, 3] == pytest.approx(TABLE_TOP + CUBE / 2, abs=3e-3)  # on the table
    shift = np.linalg.norm(project(CAMERA, end[None, :3, 3]) - project(CAMERA, start[None, :3, 3]))
    assert shift < 1.0  # px: it moved along the ray, where the image cannot tell
    # the same drop straight down moves it in the image by the drop's projection
    _, down, rec_off = run(table_scene, ray=False)
    assert "ray_shift" not in rec_off
    moved = np.linalg.norm(project(CAMERA, down[None, :3, 3]) - project(CAMERA, start[None, :3, 3]))
    assert moved > 5.0 * max(shift, 0.2)
    d = start[:3, 3] - EYE
    assert rec["ray_shift"] == pytest.approx(0.03 * np.linalg.norm(d) / -d[2], rel=0.02)  # the whole 3 cm gap


def test_without_a_camera_the_remedy_is_skipped(table_scene):
    start, end, rec = run(table_scene, ray=True, eye=None)
    assert "ray_shift" not in rec
    np.testing.assert_allclose(end[:2, 3], start[:2, 3], atol=3e-3)  # straight down
