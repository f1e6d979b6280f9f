"""The per-scene metrics file: sections computed in one pass, one method's bad scene isolated from the others."""

from __future__ import annotations

import json

import pytest
from test_physical_metrics import FAST, at, box, proxies_of, write_scene

from phiscene.errors import InputError
from phiscene.failures import failure_record, is_failure_record
from phiscene.metrics.evaluate import (
    FORMAT,
    MetricInputs,
    MetricTask,
    methods_metrics,
    read_section,
    required_inputs,
    scene_metrics,
)
from phiscene.proxies import write_proxies
from phiscene.sim.settings import SimSettings

SETTINGS = {"physical": FAST.to_dict(), "sim": SimSettings().to_dict(), "mujoco": {}}


def _stack(tmp_path, name="scene", gap=0.0):
    # a 10 cm cube resting on a 20 cm slab, the cube lifted by `gap`
    return write_scene(tmp_path, [("slab", box(0.4, 0.4, 0.2), at(0, 0, 0.1)),
                                  ("cube", box(0.1, 0.1, 0.1), at(0, 0, 0.25 + gap))], name=name)


def test_sections_in_one_pass(tmp_path):
    scene = _stack(tmp_path, gap=0.01)
    write_proxies(proxies := tmp_path / "p.npz", proxies_of(scene, tmp_path))
    inputs = MetricInputs(proxies=proxies, cache_dir=tmp_path / "cache")
    out = scene_metrics(scene.source, ["mujoco", "physical"], inputs, SETTINGS)
    assert out["format"] == FORMAT and out["sections"] == ["physical", "mujoco"]  # computing order
    # the cube floats 10 mm above the slab: the physical section measures it (analytic answer)
    assert out["physical"]["float_dist"] == pytest.approx(0.01 / 2, abs=5e-4)  # scene mean over two objects
    # both simulators let the cube fall the 10 mm and come to rest on the slab
    for engine in ("physical", "mujoco"):
        assert out[engine]["drift_trans"] == pytest.approx(0.01 / 2, abs=1.5e-3), engine
    assert required_inputs(["physical"]) == ["cache_dir", "proxies"]
    with pytest.raises(ValueError, match="unknown metric sections \\['clip'\\]"):
        scene_metrics(scene.source, ["clip"], inputs, SETTINGS)
    with pytest.raises(ValueError, match="need \\['gt'\\]"):
        scene_metrics(scene.source, ["recon"], inputs, SETTINGS)


def test_a_bad_scene_fails_alone(tmp_path):
    good = _stack(tmp_path, "good")
    bad = _stack(tmp_path, "bad")
    (bad.source.parent / "meshes" / "cube.glb").write_bytes(b"glTF\x02\x00\x00\x00 truncated")
    upstream = tmp_path / "upstream.json"
    upstream.write_text(json.dumps(failure_record("phi_scene contact/s", "it broke")))
    write_proxies(proxies := tmp_path / "p.npz", proxies_of(good, tmp_path))
    tasks = [MetricTask("a", good.source, tmp_path / "a.json", ("physical",)),
             MetricTask("b", bad.source, tmp_path / "b.json", ("physical",)),
             MetricTask("c", upstream, tmp_path / "c.json", ("physical",))]
    done = methods_metrics(tasks, MetricInputs(proxies=proxies, cache_dir=tmp_path / "cache"), SETTINGS, "m s")
    assert done == {"a": True, "b": False, "c": False}
    a = json.loads((tmp_path / "a.json").read_text())
    assert a["physical"]["pen_depth"] < 1e-6 and a["physical"]["float_dist"] < 1e-6
    b = json.loads((tmp_path / "b.json").read_text())
    assert is_failure_record(b) and "objects[1].mesh: cannot read mesh" in b["error"] and b["job"] == "m s b"
    c = json.loads((tmp_path / "c.json").read_text())
    assert is_failure_record(c) and c["failed_in"] == "phi_scene contact/s"  # the root cause travels on
    # reading sections: a failure record passes through, a missing section or a foreign file is a clear error
    assert read_section(c, "physical") is c
    with pytest.raises(InputError, match="a.json.*no 'mujoco' section"):
        read_section(a, "mujoco", tmp_path / "a.json")
    with pytest.raises(InputError, match="x.json.*not a metrics file"):
        read_section({"pen_depth": 0.0}, "physical", tmp_path / "x.json")
