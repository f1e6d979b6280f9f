"""Levelling from the floor: scenes whose objects have no flat face and no upright frame (``levelling.floor_up``)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from phiscene.levelling import LevelParams, angle_deg, estimate_up, floor_up

Z = np.array([0.0, 0.0, 1.0])
#: (x, y) of six objects on a floor about 1.5 m across
SPOTS = [(-0.7, 0.2), (-0.2, -0.5), (0.3, 0.4), (0.8, -0.3), (0.1, 1.0), (-0.6, 1.1)]


def toys(seed: int, spots, lift=None) -> dict[str, trimesh.Trimesh]:
    """Ellipsoids with random axes and turns, each resting on z = 0 (lifted by ``lift[k]`` m) at its spot."""
    rng = np.random.default_rng(seed)
    out = {}
    for k, (x, y) in enumerate(spots):
        m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        m.apply_scale(rng.uniform(0.05, 0.15, size=3))
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
        m.apply_transform(turn)
        m.apply_translation([x, y, -m.vertices[:, 2].min() + (0.0 if lift is None else lift[k])])
        out[f"toy_{k}"] = m
    return out


def tilted(meshes: dict[str, trimesh.Trimesh], deg: float, heading: float) -> tuple[dict, np.ndarray]:
    """The scene turned by ``deg`` about the horizontal axis at ``heading`` (deg), and its up direction then."""
    axis = np.array([np.cos(np.radians(heading)), np.sin(np.radians(heading)), 0.0])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix()
    return {k: m.copy().apply_transform(T) for k, m in meshes.items()}, T[:3, :3] @ Z


@pytest.mark.parametrize("deg,heading", [(17.0, 30.0), (12.0, 200.0), (25.0, 110.0)])
def test_a_floor_of_round_objects_is_levelled_from_their_lowest_points(monkeypatch, deg, heading):
    # the box votes of turned ellipsoids point anywhere, and too few agree: the floor under them gives the answer
    # (on a level floor each touches it at its lowest point, whatever its shape or turn)
    scene, truth = tilted(toys(3, SPOTS), deg, heading)
    est = estimate_up(scene, Z, LevelParams())
    assert est.floor is not None and sorted(est.floor.objects) == sorted(scene)
    assert angle_deg(est.up, truth) < 0.5
    assert est.floor.rms < 1e-3 and "floor" in est.to_dict()
    monkeypatch.setattr("phiscene.levelling.floor_up", lambda *a, **k: None)  # the votes alone
    assert angle_deg(estimate_up(scene, Z, LevelParams()).up, truth) > 2.0


def test_depth_errors_tilt_the_floor_by_the_slope_they_make():
    # each object lifted or sunk by up to 1 cm: the least-squares plane through six points 1.5 m apart turns by
    # about 0.01 / 0.6 rad at most, well under a degree
    lift = np.random.default_rng(5).uniform(-0.01, 0.01, size=len(SPOTS))
    scene, truth = tilted(toys(3, SPOTS, lift), 15.0, 60.0)
    est = estimate_up(scene, Z, LevelParams())
    assert est.floor is not None and angle_deg(est.up, truth) < 1.0
    assert 0.001 < est.floor.rms < 0.01
    # the RMS bound refuses a floor that is not one plane
    assert estimate_up(scene, Z, LevelParams(floor_plane_rms=0.001)).floor is None


def test_no_floor_from_too_few_objects_or_from_a_row():
    parts = {k: np.asarray(m.vertices) for k, m in toys(3, SPOTS[:2]).items()}
    assert floor_up(parts, Z, 0.25) is None
    row = [(-0.8, 0.0), (-0.3, 0.01), (0.2, -0.01), (0.7, 0.0)]  # on one line: the plane may turn about it
    assert floor_up({k: np.asarray(m.vertices) for k, m in toys(3, row).items()}, Z, 0.25) is None
    # what stands on another object is not on the floor: a ball on a slab leaves the slab and two others
    slab = trimesh.creation.box((0.6, 0.6, 0.3))
    slab.apply_translation([0.0, 0.0, 0.15])
    ball = trimesh.creation.icosphere(radius=0.1)
    ball.apply_translation([0.0, 0.0, 0.4])
    others = toys(4, [(1.0, 0.5), (-0.9, 0.7)])
    plane = floor_up({"slab": slab.vertices, "ball": ball.vertices,
                      **{k: m.vertices for k, m in others.items()}}, Z, 0.25)
    assert plane is not None and sorted(plane.objects) == sorted(["slab", *others])
    assert angle_deg(plane.up, Z) < 1e-6


def test_agreeing_votes_are_not_overruled_by_the_floor():
    # boxes on a level floor: their top faces agree, the floor is not consulted
    boxes = {}
    for k, (x, y) in enumerate(SPOTS[:4]):
        b = trimesh.creation.box((0.3, 0.2, 0.25))
        b.apply_translation([x, y, 0.125])
        boxes[f"box_{k}"] = b
    scene, truth = tilted(boxes, 14.0, 10.0)
    est = estimate_up(scene, Z, LevelParams())
    assert est.floor is None and angle_deg(est.up, truth) < 1e-6
