"""Extension seams: a table, a metric section, a drift simulator and a baseline are each one registry entry.

The example plugin (tests/plugins/seam_plugin.py) registers one of each; these tests use the registries in
process (the workflow run with the plugin is in tests/test_workflow.py). Oracles: numbers fed into synthetic
metrics files, the ground contact of a dropped object, pybullet's own answer for a box at rest.
"""

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from phiscene.config import ConfigError, check_config
from phiscene.metrics.evaluate import FORMAT, MetricInputs, check_sections, scene_metrics, section_settings
from phiscene.plugins import PluginError, load_plugins
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.table_registry import TABLE_KINDS, TableInputs, heading_of, kind_of, table_kind, write_kind_table

ROOT = Path(__file__).resolve().parents[1]
CONFIG = yaml.safe_load((ROOT / "config/config.yaml").read_text())


@pytest.fixture
def plugin(monkeypatch):
    """The example plugin, registered for one test and removed afterwards."""
    from phiscene.baselines.registry import unregister_baseline
    from phiscene.metrics.drift import unregister_simulator
    from phiscene.table_registry import unregister_table

    monkeypatch.syspath_prepend(str(ROOT / "tests/plugins"))
    sys.modules.pop("seam_plugin", None)
    module = importlib.import_module("seam_plugin")
    yield module
    unregister_simulator("bullet_coarse")
    unregister_table("faithfulness")
    unregister_baseline("drop")
    sys.modules.pop("seam_plugin", None)


def _metrics_file(path: Path, **sections) -> Path:
    path.write_text(json.dumps({"format": FORMAT, "sections": list(sections), **sections}))
    return path


def _drift(t, r):
    return {"drift_trans": t, "drift_rot": r, "objects": {}}


def test_a_registered_simulator_adds_ranked_columns_to_the_crosssim_table(plugin, tmp_path):
    files = {}
    for name, (mj, pb, coarse) in {"a": (0.1, 0.2, 0.05), "b": (0.3, 0.1, 0.4)}.items():
        files[name] = [_metrics_file(tmp_path / f"{name}.json", physical=_drift(pb, 10 * pb),
                                     mujoco=_drift(mj, 10 * mj), bullet_coarse=_drift(coarse, 10 * coarse))]
    kind = table_kind("crosssim")
    assert "bullet_coarse" in kind.metric_sections()
    df = kind.build(TableInputs(files=files))
    assert list(df.columns) == ["drift_trans_mujoco", "drift_rot_mujoco", "drift_trans_bullet_coarse",
                                "drift_rot_bullet_coarse", "drift_trans_bullet", "drift_rot_bullet", "n_scenes",
                                "n_failed", "avg_rank"]
    assert df.loc["a", "drift_trans_bullet_coarse"] == pytest.approx(0.05)
    assert df.loc["b", "drift_rot_bullet_coarse"] == pytest.approx(4.0)
    # ranked on MuJoCo and the new engine (a is better on both), pybullet shown unranked
    assert set(kind.ranked()) == {"drift_trans_mujoco", "drift_rot_mujoco", "drift_trans_bullet_coarse",
                                  "drift_rot_bullet_coarse"}
    assert df.loc["a", "avg_rank"] == 1.0 and df.loc["b", "avg_rank"] == 2.0


def test_without_the_plugin_crosssim_is_mujoco_then_pybullet():
    assert "bullet_coarse" not in table_kind("crosssim").metric_sections()
    assert set(table_kind("crosssim").ranked()) == {"drift_trans_mujoco", "drift_rot_mujoco"}


def _box_scene(tmp_path: Path, z: float) -> Scene:
    path = tmp_path / "box.obj"
    trimesh.creation.box([0.2, 0.2, 0.2]).export(path)
    pose = np.eye(4)
    pose[:3, 3] = [0.3, -0.1, z]
    scene = Scene(objects=[SceneObject(id="box", mesh_path=path.resolve(), pose=pose)], ground_height=0.0)
    save_scene(scene, tmp_path / "scene.json")
    return load_scene(tmp_path / "scene.json")


def test_a_registered_simulator_section_is_computed_like_any_section(plugin, tmp_path):
    from phiscene.proxies import Proxy, write_proxies

    scene = _box_scene(tmp_path, 0.1)  # resting on the ground
    box = scene.objects[0].mesh()
    write_proxies(tmp_path / "proxies.npz", {"box": Proxy(hulls=[box.vertices.copy()], volume_ratio=1.0,
                                                          max_outside=0.0, seconds=0.0)})
    assert "bullet_coarse" in check_sections(["bullet_coarse"])
    assert section_settings(["bullet_coarse"]) == ["physical", "sim"]
    out = scene_metrics(tmp_path / "scene.json", ["bullet_coarse"],
                        MetricInputs(proxies=tmp_path / "proxies.npz", cache_dir=tmp_path / "cache"),
                        {"physical": {"frames": 60}})
    # a box at rest on the ground stays there with coarse solver settings too (lifted 1 cm, it falls back)
    assert out["sections"] == ["bullet_coarse"]
    assert out["bullet_coarse"]["drift_trans"] < 2e-3 and out["bullet_coarse"]["drift_rot"] < 0.5


def test_a_registered_table_kind_writes_its_table_with_heading_and_ranks(plugin, tmp_path):
    files = {
        "initial": [_metrics_file(tmp_path / "i0.json", pose_gt={"displacement_mean": 0.0,
                                                                 "gt_translation_mean": 0.05})],
        "ours": [_metrics_file(tmp_path / "o0.json", pose_gt={"displacement_mean": 0.02,
                                                              "gt_translation_mean": 0.01})],
    }
    spec = {"kind": "faithfulness", "suite": "clutter", "methods": ["initial", "ours"]}
    kind = kind_of("faithfulness_clutter", spec)
    assert kind is TABLE_KINDS["faithfulness"]
    write_kind_table(kind, TableInputs(files=files), tmp_path / "t.csv", tmp_path / "t.md",
                     heading=heading_of("faithfulness_clutter", spec))
    md = (tmp_path / "t.md").read_text()
    assert md.startswith("# Faithfulness to the input (clutter suite)")
    import pandas as pd

    df = pd.read_csv(tmp_path / "t.csv", index_col=0)
    assert df.loc["ours", "gt_translation_mean"] == pytest.approx(0.01)
    assert df.loc["initial", "avg_rank"] == 1.5 and df.loc["ours", "avg_rank"] == 1.5


def test_a_registered_baseline_runs_through_the_generic_stage(plugin, tmp_path):
    from phiscene.pipeline import run_baseline

    scene = _box_scene(tmp_path, 0.35)  # floating 25 cm
    run_baseline("drop", tmp_path / "scene.json", tmp_path / "out/scene.json", tmp_path / "out/log.json",
                 {"clearance": 0.01}, {}, tmp_path / "cache")
    out = load_scene(tmp_path / "out/scene.json")
    low = out.objects[0].world_mesh().vertices[:, 2].min()
    assert low == pytest.approx(0.01, abs=1e-9)
    np.testing.assert_allclose(out.objects[0].pose[:2, 3], scene.objects[0].pose[:2, 3])
    with pytest.raises(ValueError, match="drop baseline parameters"):
        run_baseline("drop", tmp_path / "scene.json", tmp_path / "o2/scene.json", tmp_path / "o2/log.json",
                     {"clearence": 0.01}, {}, tmp_path / "cache")


def test_config_checks_tables_and_registered_baseline_params(plugin):
    good = {**CONFIG, "methods": {**CONFIG["methods"], "dropped": {"kind": "drop", "params": {"clearance": 0.0}}},
            "tables": {**CONFIG["tables"], "faithfulness": {"suite": "contact", "methods": ["initial", "dropped"]}}}
    check_config(good)
    bad = {**good, "methods": {**good["methods"], "dropped": {"kind": "drop", "params": {"clearence": 0.0}}}}
    with pytest.raises(ConfigError, match=r"methods\.dropped\.params.*clearence"):
        check_config(bad)
    for table, match in [({"kind": "nope", "suite": "contact", "methods": ["gt"]}, "unknown table kind 'nope'"),
                         ({"kind": "phys", "suite": "kitchen", "methods": ["gt"]}, "unknown suite 'kitchen'"),
                         ({"kind": "phys", "suite": "contact", "methods": ["gt", "ours"]}, "unknown method 'ours'"),
                         ({"kind": "topology", "suite": "contact"}, "needs a list of backends")]:
        with pytest.raises(ConfigError, match=match):
            check_config({**good, "tables": {**good["tables"], "extra": table}})


def test_a_plugin_that_cannot_be_imported_is_one_line():
    with pytest.raises(PluginError, match=r"config: plugins: cannot import 'no_such_phiscene_plugin' "
                                          r"\(ModuleNotFoundError"):
        load_plugins(["no_such_phiscene_plugin"])


def test_every_builtin_table_kind_is_consistent():
    """Kinds reading metrics files name known sections and list methods; the others read no section."""
    for kind in TABLE_KINDS.values():
        if kind.reads == "metrics":
            assert kind.metric_sections(), kind.name
            check_sections(kind.metric_sections())
            assert kind.rows == "methods"
        else:
            assert not kind.metric_sections(), kind.name
