"""Attached objects through each other (phiscene.assembly.fixtures, penetration.fixture_clearance).

Oracle: thin boxes against the wall x = 0 (room on x > 0), whose shortest clearing moves are known in closed
form: out from the wall by the depth of the overlap plus the clearance eps, or sideways by its width plus eps.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scenes import box_scene, convex_proxies

from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.assembly.fixtures import summary
from phiscene.assembly.penetration import PenetrationParams, fixture_clearance, overlaps_deeper, sdf_body
from phiscene.meshes import save_mesh
from phiscene.scene import Plane
from phiscene.sim.settings import SimSettings
from phiscene.transforms import make_pose

torch.set_num_threads(1)
#: phi_scene's search settings (config/config.yaml), eps 5 mm, search steps of 1 cm
PP = PenetrationParams(optimizer="steepest", search_directions=32, rotate_over=0.02)
WALL = Plane("wall_0", "wall", (1.0, 0.0, 0.0), 0.0)
#: a poster 2 cm thick, 40 cm wide (y), 30 cm tall, its back on the wall x = 0 at height 1.5 m
POSTER = trimesh.creation.box((0.02, 0.4, 0.3))


def at(x: float, y: float) -> np.ndarray:
    return make_pose(translation=(x, y, 1.5))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("fixtures")


def body(name: str, pose: np.ndarray, cache, n: int = 2048):
    return sdf_body(name, POSTER, pose, n, PP, cache)


def test_a_poster_through_another_moves_out_from_the_wall_by_the_depth_of_the_overlap(cache):
    # both flat on the wall, overlapping over 20 cm of width: out by the 2 cm thickness + eps (the shortest way),
    # not sideways by 20 cm + eps
    behind = body("a", at(0.01, 0.0), cache)
    active = body("b", at(0.01, 0.2), cache)
    assert overlaps_deeper(active, [behind], 0.004)
    move = fixture_clearance(active, [behind], 0.0, PP, np.array([1.0, 0.0, 0.0]))
    assert move is not None
    assert np.allclose(move, (0.02 + PP.eps, 0.0, 0.0), atol=0.002)


def test_it_never_moves_into_its_wall_even_where_that_is_shorter(cache):
    # the one placed before stands 1 cm off the wall: backwards (1.5 cm, into the wall) would be shorter than
    # out in front of it (x from 0 to 0.03 + eps: 3.5 cm); the wall's normal forbids it; without the wall the
    # shortest move is taken
    before = body("a", at(0.02, 0.0), cache)
    active = body("b", at(0.01, 0.2), cache)
    move = fixture_clearance(active, [before], 0.0, PP, np.array([1.0, 0.0, 0.0]))
    assert move is not None and np.allclose(move, (0.03 + PP.eps - 0.0, 0.0, 0.0), atol=0.002)
    free = fixture_clearance(active, [before], 0.0, PP, None)
    assert free is not None and np.linalg.norm(free) < np.linalg.norm(move) - 0.01


def test_an_overlap_within_the_tolerance_is_left_alone(cache):
    # edges overlapping by 3 mm sideways: under the 4 mm contact tolerance
    a = body("a", at(0.01, 0.0), cache)
    b = body("b", at(0.01, 0.4 - 0.003), cache)
    assert not overlaps_deeper(b, [a], 0.004)
    assert overlaps_deeper(b, [a], 0.002)


@pytest.mark.parametrize("fixtures", [True, False])
def test_grounding_takes_the_later_of_two_posters_clear_of_the_first(cache, fixtures):
    path = save_mesh(POSTER, cache / "poster.obj")
    scene = box_scene({"poster": path}, {"a": ("poster", at(0.01, 0.0)), "b": ("poster", at(0.01, 0.2))})
    scene.structure = [WALL]
    params = AssemblyParams.from_dict({"faithful": {"enabled": True, "fixtures": fixtures},
                                       "penetration_params": {"optimizer": "steepest", "search_directions": 32}})
    out, rec = ground_scene(scene, ["a", "b"], convex_proxies(scene, cache), params, SimSettings(), cache,
                            attached={"a": "wall_0", "b": "wall_0"})
    a, b = out.get("a").pose, out.get("b").pose
    assert np.allclose(a, at(0.01, 0.0))  # the first one stays where it was put
    if not fixtures:
        assert np.allclose(b, at(0.01, 0.2)) and rec["objects"]["b"].get("fixture_clear") is None
        return
    # the second one in front of it, clear by eps (its back 2 cm + eps off the wall), not moved sideways or up
    assert b[0, 3] - 0.01 == pytest.approx(0.02 + PP.eps, abs=0.002)
    assert b[1, 3] == pytest.approx(0.2, abs=1e-9) and b[2, 3] == pytest.approx(1.5, abs=1e-9)
    assert rec["objects"]["b"]["fixture_clear"][0] == pytest.approx(b[0, 3] - 0.01, abs=1e-6)
    assert rec["objects"]["a"]["fixture_clear"] is None
    # the progress line says what moved it
    moved = float(np.linalg.norm(b[:3, 3] - at(0.01, 0.2)[:3, 3]))
    assert summary(rec["objects"]["b"], moved, 0.0) == (f"moved {moved:.3f} m, turned 0.0 deg (clear of the fixed "
                                                        "objects before it)")
    assert summary(rec["objects"]["a"], 0.0, 0.0) == "kept in place"


def test_no_clearing_move_within_reach_leaves_it_and_says_so(cache):
    # 2 cm of thickness to clear, a search that reaches 1 cm: the pose stays as it came, the log says why
    path = save_mesh(POSTER, cache / "poster.obj")
    scene = box_scene({"poster": path}, {"a": ("poster", at(0.01, 0.0)), "b": ("poster", at(0.01, 0.2))})
    scene.structure = [WALL]
    params = AssemblyParams.from_dict({"faithful": {"enabled": True},
                                       "penetration_params": {"optimizer": "steepest", "search_directions": 32,
                                                              "search_reach": 0.01}})
    out, rec = ground_scene(scene, ["a", "b"], convex_proxies(scene, cache), params, SimSettings(), cache,
                            attached={"a": "wall_0", "b": "wall_0"})
    assert np.allclose(out.get("b").pose, at(0.01, 0.2)) and rec["objects"]["b"]["fixture_clear"] == "none found"
