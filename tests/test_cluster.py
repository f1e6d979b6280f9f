"""Scale-out: the cluster profiles, and a real run through an external batch queue.

``profiles/cluster-generic-local`` submits every job with Snakemake's
cluster-generic executor to ``tools/localq`` (a minimal queue on this machine);
its tables must be byte-identical to a local run of the same config, and every
job the local scheduler plans must have gone through the queue with the
resources its rule declares.
"""

import collections
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
LOCALQ = ROOT / "tools/localq"
PROFILES = ROOT / "profiles"
TARGET = "results/tables/phys.csv"


def _job_script(path: Path, body: str, rule: str = "r", mem_mb: int = 100, runtime: float = 1.0) -> Path:
    """A job script as Snakemake writes one (``# properties`` line with the rule's resources)."""
    props = json.dumps({"rule": rule, "jobid": 7, "threads": 1, "resources": {"mem_mb": mem_mb, "runtime": runtime}})
    path.write_text(f"#!/bin/sh\n# properties = {props}\n{body}\n")
    return path


def _localq(cmd: str, *args, cwd: Path) -> str:
    res = subprocess.run([str(LOCALQ / cmd), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=30)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip()


def _wait(jid: str, cwd: Path, timeout: float = 20.0) -> str:
    t0 = time.monotonic()
    while (state := _localq("status", jid, cwd=cwd)) == "running" and time.monotonic() - t0 < timeout:
        time.sleep(0.2)
    return state


def test_localq_reports_exit_status_runtime_limit_and_cancel(tmp_path):
    ok = _localq("submit", _job_script(tmp_path / "ok.sh", "echo done"), cwd=tmp_path)
    bad = _localq("submit", _job_script(tmp_path / "bad.sh", "exit 3"), cwd=tmp_path)
    slow = _localq("submit", _job_script(tmp_path / "slow.sh", "sleep 30", runtime=0.02), cwd=tmp_path)  # 1.2 s
    hang = _localq("submit", _job_script(tmp_path / "hang.sh", "sleep 30", runtime=5), cwd=tmp_path)
    assert len({ok, bad, slow, hang}) == 4
    assert _localq("status", hang, cwd=tmp_path) == "running"
    _localq("cancel", hang, cwd=tmp_path)
    q = tmp_path / ".snakemake/localq"
    assert _wait(ok, tmp_path) == "success" and (q / f"{ok}.out").read_text() == "done\n"
    assert _wait(bad, tmp_path) == "failed" and (q / f"{bad}.rc").read_text().strip() == "3"
    assert _wait(slow, tmp_path) == "failed" and (q / f"{slow}.rc").read_text().strip() == "124"
    assert _wait(hang, tmp_path) == "failed" and not (q / f"{hang}.rc").exists()
    rows = [line.split("\t") for line in (q / "jobs.tsv").read_text().splitlines()]
    assert rows[0][:6] == ["localq_id", "rule", "snakemake_jobid", "threads", "mem_mb", "runtime"]
    assert [r[0] for r in rows[1:]] == [ok, bad, slow, hang] and {r[4] for r in rows[1:]} == {"100"}


def test_cluster_profiles_keep_cluster_keys_out_of_rules():
    """Rules declare generic resources only; partition/account/namespace/image live in the profiles."""
    rules = "\n".join(p.read_text() for p in sorted((ROOT / "workflow/rules").rglob("*.smk")))
    for key in ("slurm_partition", "slurm_account", "kubernetes", "container_image", "namespace"):
        assert key not in rules
    with_resources = re.findall(r"resources:\n\s+mem_mb=\d+,\n\s+runtime=\d+,", rules)
    scripted = re.findall(r"^\s+script:", rules, flags=re.M)
    assert len(with_resources) == len(scripted)  # every job rule that runs a script declares both
    slurm = yaml.safe_load((PROFILES / "slurm/config.yaml").read_text())
    k8s = yaml.safe_load((PROFILES / "kubernetes/config.yaml").read_text())
    assert slurm["executor"] == "slurm" and k8s["executor"] == "kubernetes"


def _job_stats(log: str) -> collections.Counter:
    """Jobs per rule from Snakemake's "Job stats" table."""
    block = log.split("Job stats:", 1)[1].split("total", 1)[0]
    return collections.Counter({m[0]: int(m[1]) for m in re.findall(r"^(\w+)\s+(\d+)$", block, flags=re.M)})


def _resources(log: str) -> dict[str, tuple[str, str]]:
    """Rule -> (mem_mb, runtime) from the job descriptions Snakemake prints."""
    out = {}
    for rule, body in re.findall(r"^(?:local)?rule (\w+):\n((?:    .*\n)+)", log, flags=re.M):
        m = re.search(r"resources: (.*)", body)
        res = dict(kv.split("=", 1) for kv in m.group(1).split(", ")) if m else {}
        out[rule] = (res.get("mem_mb"), res.get("runtime"))
    return out


@pytest.mark.workflow
def test_cluster_generic_profile_matches_local_run(tmp_path):
    cfg = ROOT / "tests/data/cluster_tiny.yaml"
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    env.pop("SNAKEMAKE_PROFILE", None)
    common = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile")]
    runs = {
        "local": common + ["--directory", str(tmp_path / "local"), "-j1", TARGET, "--configfile", str(cfg)],
        "cluster": common + ["--directory", str(tmp_path / "cluster"), "--workflow-profile",
                             str(PROFILES / "cluster-generic-local"), "--jobs", "1", TARGET, "--configfile", str(cfg)],
    }
    procs = {k: subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for k, cmd in runs.items()}
    logs = {k: p.communicate(timeout=600)[0] for k, p in procs.items()}
    for k, p in procs.items():
        assert p.returncode == 0, f"{k} run failed:\n{logs[k][-4000:]}"
    local, cluster = tmp_path / "local", tmp_path / "cluster"
    for name in ("phys.csv", "phys.md"):
        assert (cluster / "results/tables" / name).read_bytes() == (local / "results/tables" / name).read_bytes()

    # every job the local scheduler ran went through the queue, and only those
    q = cluster / ".snakemake/localq"
    rows = [dict(zip(*(line.split("\t") for line in (header, row))))
            for header in [(q / "jobs.tsv").read_text().splitlines()[0]]
            for row in (q / "jobs.tsv").read_text().splitlines()[1:]]
    planned = _job_stats(logs["local"])
    assert collections.Counter(r["rule"] for r in rows) == planned and sum(planned.values()) >= 5
    submitted = re.findall(r"Submitted job (\d+) with external jobid '(\d+)'", logs["cluster"])
    assert sorted(int(e) for _, e in submitted) == sorted(int(r["localq_id"]) for r in rows)
    assert all((q / f"{r['localq_id']}.rc").read_text().strip() == "0" for r in rows)
    # each queued job carried its rule's declared resources (as the local run printed them)
    declared = _resources(logs["local"])
    for r in rows:
        assert (r["mem_mb"], r["runtime"]) == declared[r["rule"]], r
        assert int(r["mem_mb"]) > 0 and float(r["runtime"]) > 0
