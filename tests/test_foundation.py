"""The `foundation` degradation: reconstructed open meshes, camera-ray pose errors, a tilted frame levelled back.

Oracles: trimesh's own watertightness and closest-point queries, the known camera ray, the drawn tilt against
the levelling's estimate, the parameters' medians against many draws.
"""

import math

import numpy as np
import pytest
import trimesh
from scenes import box_meshes

from phiscene.bench.degrade import DegradeParams, degrade_scene
from phiscene.bench.foundation import (
    FoundationParams,
    foundation_scene,
    pose_error,
    reconstruct_mesh,
    subdivided,
    visible_faces,
)
from phiscene.render import RenderParams, camera_for, instance_labels
from phiscene.scene import Scene, SceneObject
from phiscene.transforms import decompose, make_pose, rotation_angle

SMALL = FoundationParams(faces=2000)


@pytest.fixture(scope="module")
def boxes(tmp_path_factory):
    """Three boxes resting on the ground, their reference camera and instance labels."""
    root = tmp_path_factory.mktemp("foundation")
    meshes = box_meshes(root, {"a": (0.3, 0.2, 0.1), "b": (0.15, 0.15, 0.25), "c": (0.4, 0.1, 0.05)})
    placements = {"a": ("a", make_pose(translation=(0.0, 0.0, 0.05))),
                  "b": ("b", make_pose(translation=(0.35, 0.1, 0.125))),
                  "c": ("c", make_pose(translation=(-0.2, 0.3, 0.025)))}
    gt = Scene([SceneObject(oid, meshes[name], pose, color=(40 * i, 80, 120))
                for i, (oid, (name, pose)) in enumerate(placements.items())])
    camera = camera_for(gt, RenderParams(width=320, height=240))
    labels = instance_labels(gt, camera)
    return {"root": root, "gt": gt, "camera": camera, "labels": labels}


def test_reconstruction_is_open_dense_and_keeps_the_visible_side(boxes):
    gt, camera, labels = boxes["gt"], boxes["camera"], boxes["labels"]
    world = gt.objects[1].world_mesh()
    visible = visible_faces(world, camera, labels, 1)
    assert 0 < visible.sum() < len(visible)  # a box shows some faces, never all
    recon, rec = reconstruct_mesh(world, np.asarray(camera["eye"]), visible, np.random.default_rng(0), SMALL)
    assert not recon.is_watertight and rec["holes"] >= 1
    assert 1000 < len(recon.faces) <= 4000  # nearest power-of-4 refinement of the 2000 asked
    # vertices on visible faces of the original stay on the ground-truth surface; the hidden side moved
    _, dist, _ = trimesh.proximity.closest_point(world, recon.vertices)
    fine = subdivided(world, SMALL.faces)
    assert np.allclose(fine.vertices[:len(world.vertices)][world.faces[visible].ravel()],
                       recon.vertices[:len(world.vertices)][world.faces[visible].ravel()])
    # the hidden back is flattened: along the view ray the reconstruction ends short of the ground truth, by at
    # most hidden_flatten x (GT far end - farthest visible point) (the visible side's edge is a subdivision
    # step deeper than the original visible faces), up to the bumps
    eye = np.asarray(camera["eye"])
    ray = world.bounding_box.centroid - eye
    ray /= np.linalg.norm(ray)
    gt_far = (world.vertices @ ray).max()
    vis_far = (world.vertices[world.faces[visible].ravel()] @ ray).max()
    expected = gt_far - SMALL.hidden_flatten * (gt_far - vis_far)
    bump = SMALL.hidden_noise * np.linalg.norm(world.extents) * 1.8
    assert gt_far - vis_far > 0.01
    recon_far = (recon.vertices @ ray).max()
    assert expected - bump < recon_far < gt_far - 0.25 * SMALL.hidden_flatten * (gt_far - vis_far)
    assert dist.max() > 1e-3


def test_pose_error_lies_mostly_along_the_camera_ray_with_the_configured_medians():
    p = FoundationParams()
    eye = np.array([0.0, -2.0, 1.0])
    pose = make_pose(translation=(0.0, 0.0, 0.0))
    rng = np.random.default_rng(3)
    dist = float(np.linalg.norm(eye))
    ray = -eye / dist
    depth, lateral, rot, scale = [], [], [], []
    for _ in range(3000):
        out, err = pose_error(pose, eye, rng, p)
        shift = decompose(out)[1]
        depth.append(shift @ ray)
        lateral.append(np.linalg.norm(shift - (shift @ ray) * ray))
        rot.append(math.degrees(rotation_angle(np.eye(3), decompose(out)[0])))
        scale.append(decompose(out)[2])
    depth, lateral, rot = np.abs(depth), np.array(lateral), np.array(rot)
    assert np.median(depth) == pytest.approx(p.depth_median, rel=0.1)
    assert depth.max() <= p.depth_max + 1e-9
    assert np.median(depth) > 2 * np.median(lateral)
    assert np.median(rot) == pytest.approx(p.rotation_median_deg, rel=0.1)
    assert np.percentile(rot, 90) == pytest.approx(
        p.rotation_median_deg * math.exp(1.2816 * p.rotation_log_sigma), rel=0.15)
    assert rot.max() <= p.rotation_max_deg + 1e-9
    assert p.scale[0] <= min(scale) and max(scale) <= p.scale[1]


def test_tilted_frame_is_levelled_back_within_a_few_degrees(boxes, tmp_path):
    made = foundation_scene(boxes["gt"], boxes["camera"], boxes["labels"], SMALL, 7, tmp_path / "meshes")
    rec = made.record
    assert SMALL.tilt_min_deg - 1e-6 <= rec["tilt_deg"] <= SMALL.tilt_max_deg + 1e-6
    assert rec["residual_deg"] < 3.0  # box faces vote for the true up
    # the camera-frame scene is the levelled one turned by the tilt: its floor normal is off by the tilt
    T = np.asarray(made.camera_frame.meta["tilt_transform"])
    assert math.degrees(rotation_angle(np.eye(3), T[:3, :3])) == pytest.approx(rec["tilt_deg"], abs=1e-6)
    # meshes are the reconstructions, not the ground truth's files
    for o, g in zip(made.initial.objects, boxes["gt"].objects):
        assert o.mesh_path != g.mesh_path
        assert o.meta["degrade"]["faces"] >= SMALL.faces / 2
        # open reconstructions have holes; the others are closed once their vertices are merged
        merged = trimesh.Trimesh(o.mesh().vertices, o.mesh().faces, process=True)
        assert merged.is_watertight == (o.meta["degrade"]["holes"] == 0)


def test_same_seed_same_scene_other_seed_other_scene(boxes, tmp_path):
    a = foundation_scene(boxes["gt"], boxes["camera"], boxes["labels"], SMALL, 11, tmp_path / "a")
    b = foundation_scene(boxes["gt"], boxes["camera"], boxes["labels"], SMALL, 11, tmp_path / "b")
    c = foundation_scene(boxes["gt"], boxes["camera"], boxes["labels"], SMALL, 12, tmp_path / "c")
    for x, y, z in zip(a.initial.objects, b.initial.objects, c.initial.objects):
        np.testing.assert_array_equal(x.pose, y.pose)
        np.testing.assert_array_equal(x.mesh().vertices, y.mesh().vertices)
        assert not np.allclose(x.pose, z.pose)


def test_clean_stays_the_default_and_its_record_unchanged(boxes):
    p = DegradeParams()
    assert p.kind == "clean"
    out = degrade_scene(boxes["gt"], p, 0)
    assert set(out.meta["degrade"]) == {"translation_xy_sigma", "translation_z_sigma", "vertical_offset_min",
                                        "vertical_offset_max", "rotation_sigma_deg", "scale_sigma", "truncate"}
    assert [o.mesh_path for o in out.objects] == [o.mesh_path for o in boxes["gt"].objects]
    with pytest.raises(ValueError, match="degradation kind"):
        DegradeParams.from_dict({"kind": "sam3d"})


def test_workflow_gives_the_gt_row_its_own_proxies_only_on_reconstructed_suites(tmp_path):
    """On a `foundation` suite the initial meshes are not the GT's: the gt row's simulated metrics need proxies of
    the GT meshes (rule gt_proxies); on a `clean` suite they share the scene's proxies."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import yaml

    root = Path(__file__).resolve().parents[1]

    def dry(kind):
        cfg = tmp_path / f"{kind}.yaml"
        suite = {"n_scenes": 1, "benchmark": {"degrade": {"kind": kind}}}
        cfg.write_text(yaml.safe_dump({"suites": {"contact": suite}}))
        cmd = [sys.executable, "-m", "snakemake", "-s", str(root / "Snakefile"), "--directory", str(tmp_path / kind),
               "-n", "-j1", "--configfile", str(cfg), "--", "results/tables/phys.csv"]
        res = subprocess.run(cmd, cwd=root, env={**os.environ, "PYTHONHASHSEED": "0"}, capture_output=True,
                             text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-3000:]
        return res.stdout + res.stderr

    assert "results/proxies/contact/scene_000.gt.npz" in dry("foundation")
    assert ".gt.npz" not in dry("clean")


def test_hollow_reconstructions_are_double_walls_that_the_solid_test_fills(boxes, tmp_path):
    from phiscene.bench.foundation import inner_wall
    from phiscene.sdf import SignedDistance, winding_number_exact

    params = FoundationParams(faces=2000, hollow_share=1.0, open_share=0.0)
    made = foundation_scene(boxes["gt"], boxes["camera"], boxes["labels"], params, 7, tmp_path / "meshes")
    hollow = 0
    for o, g in zip(made.initial.objects, boxes["gt"].objects):
        mesh = o.mesh()
        wall = params.wall * float(np.linalg.norm(o.world_mesh().extents))
        thinnest = float(min(g.world_mesh().extents))
        centre = mesh.bounding_box.centroid[None]
        if o.meta["degrade"]["inner_faces"] == 0:
            assert thinnest < 2.5 * wall  # only a part thinner than two walls (plus the shape errors) stays solid
            continue
        hollow += 1
        # the raw mesh holds a cavity with winding number 0 (the oracle: the brute-force solid-angle sum) ...
        assert abs(winding_number_exact(mesh.triangles, centre)[0]) < 0.05
        # ... that the solid-aware signed distance counts as inside, about half the thinnest extent deep
        assert SignedDistance(mesh)(centre)[0] < -0.3 * thinnest
    assert hollow >= 2
    # the inner wall lies `wall` inside a box (closed form: the box shrunk by the wall on every side)
    box = trimesh.creation.box([0.3, 0.2, 0.1])
    inner = inner_wall(box, 0.01)
    np.testing.assert_allclose(inner.extents, [0.28, 0.18, 0.08], atol=0.01 / 2.0)
    assert inner.volume < 0  # it faces the cavity
