"""Pose helpers, atomic writes and table aggregation against hand-computed answers."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from phiscene.atomic import atomic_path, write_json
from phiscene.metrics.evaluate import FORMAT as METRICS_FORMAT
from phiscene.tables import PHYS_COLUMNS, POSE_COLUMNS, average_rank, physical_table, to_markdown
from phiscene.transforms import (
    Y_UP_TO_Z_UP,
    Z_UP_TO_Y_UP,
    decompose,
    invert,
    make_pose,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    rigidity_error,
    rotation_angle,
    transform_points,
)


def test_pose_compose_invert():
    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    T = make_pose(R, [1, 2, 3], 1.5)
    Rd, t, s = decompose(T)
    np.testing.assert_allclose(Rd, R, atol=1e-12)
    assert s == pytest.approx(1.5)
    np.testing.assert_allclose(invert(T) @ T, np.eye(4), atol=1e-12)
    p = np.array([[0.1, 0.2, 0.3]])
    np.testing.assert_allclose(transform_points(T, p), 1.5 * p @ R.T + [1, 2, 3])
    assert rigidity_error(T) is None


def test_up_axis_conversion_is_minus_90_degrees_about_x():
    want = Rotation.from_euler("x", -90, degrees=True).as_matrix()
    np.testing.assert_allclose(Z_UP_TO_Y_UP[:3, :3], want, atol=1e-15)
    assert (Z_UP_TO_Y_UP[:3, 3] == 0).all() and (Y_UP_TO_Z_UP @ Z_UP_TO_Y_UP == np.eye(4)).all()
    # glTF: +Y up, +Z towards the viewer (phiscene's -Y front); phiscene: +Z up
    np.testing.assert_array_equal(transform_points(Z_UP_TO_Y_UP, [[0, 0, 1], [0, -1, 0]]), [[0, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError):
        Z_UP_TO_Y_UP[0, 0] = 2.0  # one shared constant: read-only


def test_quaternion_convention_wxyz():
    # 90 degrees about z: w = cos(45), z = sin(45)
    q = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]
    R = quat_wxyz_to_matrix(q)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(matrix_to_quat_wxyz(R), q, atol=1e-12)
    assert np.degrees(rotation_angle(np.eye(3), R)) == pytest.approx(90)


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError):
        write_json(target, {"x": float("nan")})
    assert list(tmp_path.iterdir()) == []


def test_average_rank_matches_paper_convention():
    # Paper Tab. 3 rows (drift trans, drift rot) -> A.R. 6.0, 5.0, 3.0, 3.0, 3.0, 1.0
    df = pd.DataFrame({"t": [5.5426, 3.6252, 0.6573, 0.7344, 0.5992, 0.0405],
                       "r": [113.2394, 81.0499, 66.1770, 52.4032, 70.0730, 6.9597]},
                      index=["SceneGen", "MIDI", "Gen3DSR", "SAM3D", "DepR", "phi"])
    ar = average_rank(df, {"t": "min", "r": "min"})
    np.testing.assert_allclose(ar.values, [6.0, 5.0, 3.0, 3.0, 3.0, 1.0])


def test_physical_table_means_over_scenes(tmp_path):
    files = {}
    for m, vals in {"a": [0.0, 0.2], "b": [0.1, 0.1]}.items():
        files[m] = []
        for k, v in enumerate(vals):
            p = tmp_path / f"{m}{k}.json"
            pose = {k: v + 1 for k in POSE_COLUMNS}
            p.write_text(json.dumps({"format": METRICS_FORMAT, "sections": ["physical", "pose_gt"], "physical": {
                "pen_depth": v, "float_dist": v, "drift_trans": v, "drift_rot": 10 * v}, "pose_gt": pose}))
            files[m].append(p)
    df = physical_table(files)
    assert df.loc["a", "pen_depth"] == pytest.approx(0.1) and df.loc["b", "drift_rot"] == pytest.approx(1.0)
    assert df.loc["a", "displacement_mean"] == pytest.approx(1.1) and df.loc["b", "gt_adds_mean"] == pytest.approx(1.1)
    assert (df["avg_rank"] == 1).all()  # ties share the better rank
    md = to_markdown(df, PHYS_COLUMNS)
    assert "**0.1000**" in md


def test_crosssim_and_runtime_tables(tmp_path):
    from phiscene.tables import crosssim_table, runtime_table

    def js(name, bullet, mujoco):
        p = tmp_path / f"{name}.json"
        p.write_text(json.dumps({"format": METRICS_FORMAT, "sections": ["physical", "mujoco"],
                                 "physical": dict(zip(("drift_trans", "drift_rot"), bullet)),
                                 "mujoco": dict(zip(("drift_trans", "drift_rot"), mujoco))}))
        return p

    df = crosssim_table({"a": [js("a", (0.1, 1.0), (0.2, 2.0))], "b": [js("b", (0.3, 3.0), (0.1, 1.0))]})
    assert df.loc["a", "drift_trans_mujoco"] == 0.2 and df.loc["a", "drift_trans_bullet"] == 0.1
    assert df.loc["b", "avg_rank"] == 1 and df.loc["a", "avg_rank"] == 2  # ranked on MuJoCo only
    for stage, secs in [("methods/phi_scene", [1.0, 3.0]), ("proxies", [2.0])]:
        for k, s in enumerate(secs):
            p = tmp_path / "bench" / stage / "contact" / f"scene_{k}.tsv"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text("s\th:m:s\tmax_rss\tcpu_time\n" f"{s}\t0:00:01\t{100 * (k + 1)}\t{s / 2}\n")
    rt = runtime_table(tmp_path / "bench")
    assert rt.loc[("methods/phi_scene", "contact"), "mean_s"] == 2.0
    assert rt.loc[("methods/phi_scene", "contact"), "max_rss_mb"] == 200
    assert rt.loc[("proxies", "contact"), "jobs"] == 1
    from phiscene.tables import to_markdown

    md = to_markdown(rt, {})
    assert "| methods/phi_scene / contact " in md and "('" not in md  # readable labels, not tuples


def test_real_table_means_per_method_and_counts_ballasts_and_bases(tmp_path):
    from phiscene.tables import REAL_COLUMNS, real_scene_rows, real_table

    def metrics(name, v, pose_extra):
        p = tmp_path / f"{name}.json"
        p.write_text(json.dumps({
            "format": METRICS_FORMAT, "sections": ["physical", "mujoco", "pose"],
            "physical": {"pen_depth": v, "float_dist": v, "drift_trans": v, "drift_rot": 10 * v},
            "mujoco": {"drift_trans": 2 * v, "drift_rot": 20 * v},
            "pose": {"displacement_mean": v, "displacement_max": 3 * v, "rotation_mean": v, "rotation_max": v,
                     "attached": 1, **pose_extra}}))
        return p

    def log(name, settled, seconds):
        p = tmp_path / f"{name}.log.json"
        objects = {f"o{k}": {"settled": s, "settle_remedy": "none"} for k, s in enumerate(settled)}
        objects["poster"] = {"settled": True, "settle_remedy": "attached"}  # not counted in the settled fraction
        objects["chair"] = {"settled": True, "settle_remedy": "hidden"}  # kept static by grounding: nor this
        p.write_text(json.dumps({"summary": {"seconds": seconds}, "objects": objects}))
        return p

    scenes = ["s0", "s1"]
    files = {"ours": [metrics("o0", 0.1, {"ballasted": 2, "bases": 1}),
                      metrics("o1", 0.3, {"ballasted": 0, "bases": 1})],
             # a metrics file older than the two counts: none
             "old": [metrics("x0", 0.2, {}), metrics("x1", 0.2, {})]}
    logs = {"ours": [log("o0", [True, False], 4.0), log("o1", [True, True], 6.0)], "old": [None, None]}
    per = real_scene_rows(files, scenes, logs)
    assert per.loc[("ours", "s0"), "settled_frac"] == pytest.approx(0.5)
    assert per.loc[("old", "s1"), "bases"] == 0 and per.loc[("old", "s1"), "ballasted"] == 0
    df = real_table(files, scenes, logs)
    assert df.loc["ours", "pen_depth"] == pytest.approx(0.2)
    assert df.loc["ours", "drift_rot_mujoco"] == pytest.approx(4.0)
    assert df.loc["ours", "displacement_max"] == pytest.approx(0.6)
    assert df.loc["ours", "ballasted"] == pytest.approx(1.0) and df.loc["ours", "bases"] == pytest.approx(1.0)
    assert df.loc["ours", "settled_frac"] == pytest.approx(0.75) and df.loc["ours", "seconds"] == pytest.approx(5.0)
    assert np.isnan(df.loc["old", "seconds"]) and df.loc["old", "n_scenes"] == 2
    assert set(REAL_COLUMNS) <= set(df.columns)
