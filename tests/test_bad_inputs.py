"""The bad-input corpus (tests/bad_inputs) through the `phiscene` command and through a workflow job.

Every error case must give, on the CLI, exit status 1 and exactly one line on
stderr naming the file and the field, with no output file left behind; in
the workflow, the job that first reads the damaged file (the same job
wrapper and stage function a workflow script runs) must succeed and leave a
failure record with the same message in its output. Graceful cases are
grounded end to end and their result is checked against an analytic answer.
"""

import json
import warnings

import pytest
import yaml
from bad_inputs import CASES, Case, build, mllm_params, topology_path

from phiscene import cli, pipeline
from phiscene.failures import FORMAT, read_failure
from phiscene.runner import job

ERRORS = [c for c in CASES if not c.graceful]
GRACEFUL = [c for c in CASES if c.graceful]


@pytest.fixture(autouse=True)
def _restore_logging(keep_logging):
    """Every test here runs code that reconfigures logging (see conftest.keep_logging)."""


def config_file(tmp_path, case: Case, root) -> str:
    cfg = {"cache_dir": str(tmp_path / "cache"), "proxies": {"backend": "convex"},
           "topology": {"mllm": mllm_params(root)}, **case.config}
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return str(path)


def run_cli(case: Case, tmp_path, capsys):
    """``phiscene ground`` on the case, in process; numeric warnings would be extra stderr lines, so none may occur."""
    root, out = tmp_path / "case", tmp_path / "out"
    scene = build(case, root)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rc = cli.main(["ground", str(scene.parent), str(out), "--topology", case.topology,
                       "--given", str(topology_path(root)), "--config", config_file(tmp_path, case, root)])
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    return rc, capsys.readouterr(), root, out


def assert_names(msg: str, case: Case) -> None:
    assert case.file in msg, msg
    if case.field is not None:
        assert f": {case.field}: " in msg, msg
    assert case.words in msg, msg


def test_corpus_is_large_and_covers_every_category():
    names = {c.name for c in CASES}
    assert len(CASES) >= 25 and len(names) == len(CASES)
    for word in ("scene_", "objects_missing", "mesh_missing", "mesh_corrupt", "mesh_empty", "zero_volume",
                 "non_watertight", "multi_shell", "pose_inf", "pose_shear", "duplicate_ids", "far_below_ground",
                 "kilometres", "millimetres", "zero_objects", "one_object", "fifty_objects", "topology_cyclic",
                 "dangling", "topology_missing_object", "mllm_"):
        assert any(word in n for n in names), word


@pytest.mark.parametrize("case", ERRORS, ids=lambda c: c.name)
def test_error_case(case, tmp_path, capsys):
    # the CLI: one line naming file and field, exit status 1, no output written
    rc, captured, root, out = run_cli(case, tmp_path, capsys)
    err = captured.err.strip()
    assert rc == 1, captured
    assert err.count("\n") == 0 and err.startswith("phiscene: error: "), err
    assert "Traceback" not in err
    assert_names(err, case)
    assert not (out / "scene.json").exists() and not (out / "topology.json").exists()
    assert not [p for p in out.rglob(".*")] if out.exists() else True  # no temporary file left behind

    # the workflow job that first reads the damaged file records the failure and succeeds
    result = tmp_path / "job" / ("proxies.npz" if case.stage == "proxies" else "topology.json")
    log_file = tmp_path / "job" / "job.log"
    with job(f"{case.stage} {case.name}", log_file, 1, failure_outputs=[result]):
        if case.stage == "proxies":
            pipeline.run_proxies(root / "initial" / "scene.json", result, {"backend": "convex"}, tmp_path / "cache")
        else:
            params = mllm_params(root) if case.topology == "mllm" else {}
            pipeline.run_topology(root / "initial" / "scene.json", result, case.topology, params,
                                  given_path=topology_path(root) if case.topology == "given" else None)
    record = read_failure(result)
    assert record is not None and record["format"] == FORMAT and record["failed"] is True
    assert record["failed_in"] == f"{case.stage} {case.name}"
    assert_names(record["error"], case)
    assert record["error"] in err or case.name == "topology_missing"  # the CLI checks --given itself
    errors = [line for line in log_file.read_text().splitlines() if " ERROR " in line]
    assert len(errors) == 1 and case.words in errors[0]


@pytest.mark.parametrize("case", GRACEFUL, ids=lambda c: c.name)
def test_graceful_case(case, tmp_path, capsys):
    rc, captured, root, out = run_cli(case, tmp_path, capsys)
    assert rc == 0, captured.err
    assert "Traceback" not in captured.err
    assert case.handling
    record = json.loads((out / "assembly.json").read_text())
    assert sorted(record["order"]) == sorted(json.loads((out / "scene.json").read_text())["objects"][i]["id"]
                                             for i in range(len(record["order"])))
    case.check(root, out)
