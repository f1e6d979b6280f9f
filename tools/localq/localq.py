#!/usr/bin/env python3
"""localq: a minimal batch queue on this machine, for Snakemake's cluster-generic executor.

It stands in for a real scheduler (sbatch/squeue/scancel) so that the
cluster code path of the workflow (job scripts, submission, status polling,
a shared filesystem) can be exercised without a cluster::

    localq.py submit JOBSCRIPT   start the job script detached, print its job id
    localq.py status JOBID       print running | success | failed
    localq.py cancel JOBID...    terminate jobs (their whole process group)

The wrappers ``submit``, ``status`` and ``cancel`` beside this file are what
``profiles/cluster-generic-local`` names (the executor calls the
cancel command without arguments of its own, so each needs its own file).

State lives in ``$LOCALQ_DIR`` (default ``.snakemake/localq`` under the
current directory, which is the workflow's working directory): for job ``N``
``N.sh`` (a copy of the job script, as a scheduler spools it), ``N.out``
(stdout and stderr), ``N.pid`` and, once it ends, ``N.rc`` (exit status).
Every submission appends one line to ``jobs.tsv``: job id, rule, Snakemake
job id, threads, mem_mb, runtime (minutes), taken from the ``# properties``
line Snakemake writes into every job script. ``runtime`` is enforced as a
wall-clock limit (the job's process group is terminated, exit status 124);
memory and threads are recorded, not enforced. Standard library only.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

FIELDS = ("localq_id", "rule", "snakemake_jobid", "threads", "mem_mb", "runtime", "submitted")


def queue_dir() -> Path:
    """The queue's state folder (created)."""
    d = Path(os.environ.get("LOCALQ_DIR", ".snakemake/localq")).resolve()
    d.mkdir(parents=True, exist_ok=True)
    return d


def job_properties(jobscript: Path) -> dict:
    """The JSON of the ``# properties = {...}`` line of a Snakemake job script ({} if absent)."""
    for line in jobscript.read_text().splitlines():
        m = re.match(r"# properties = (.*)", line)
        if m:
            return json.loads(m.group(1))
    return {}


def _next_id(d: Path) -> int:
    """Allocate the next job id under an exclusive lock (safe for parallel submissions)."""
    with open(d / "counter.lock", "a+") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        counter = d / "counter"
        n = int(counter.read_text()) + 1 if counter.exists() else 1
        counter.write_text(str(n))
        return n


def submit(jobscript: str) -> int:
    """Spool and start ``jobscript`` detached (own session); record it; return its job id."""
    d = queue_dir()
    src = Path(jobscript)
    props = job_properties(src)
    resources = props.get("resources", {})
    jid = _next_id(d)
    script = d / f"{jid}.sh"
    script.write_text(src.read_text())
    runtime = resources.get("runtime")
    limit = float(runtime) * 60 if runtime not in (None, "", 0) else 0.0
    with open(os.devnull, "rb") as devnull:
        proc = subprocess.Popen([sys.executable, __file__, "_run", str(d / str(jid)), str(limit)],
                                stdin=devnull, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True, close_fds=True)
    (d / f"{jid}.pid").write_text(str(proc.pid))
    row = [jid, props.get("rule", ""), props.get("jobid", ""), props.get("threads", ""),
           resources.get("mem_mb", ""), runtime if runtime is not None else "", f"{time.time():.3f}"]
    with open(d / "jobs.tsv", "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        if f.tell() == 0:
            f.write("\t".join(FIELDS) + "\n")
        f.write("\t".join(str(v) for v in row) + "\n")
    return jid


def run(stem: str, limit_s: float) -> None:
    """Run ``stem.sh`` (output to ``stem.out``), then write its exit status to ``stem.rc``.

    The job is killed (its whole process group: this runner's session) after ``limit_s``
    seconds (0 = no limit), exit status 124 as with ``timeout``.
    """
    with open(f"{stem}.out", "wb") as out:
        job = subprocess.Popen(["sh", f"{stem}.sh"], stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
        try:
            rc = job.wait(timeout=limit_s or None)
        except subprocess.TimeoutExpired:
            out.write(f"localq: runtime limit of {limit_s:.0f} s reached, job killed\n".encode())
            out.flush()
            signal.signal(signal.SIGTERM, signal.SIG_IGN)  # this runner outlives the kill to record it
            os.killpg(os.getpgrp(), signal.SIGTERM)
            job.wait()
            rc = 124
    Path(f"{stem}.rc.part").write_text(f"{rc}\n")
    os.replace(f"{stem}.rc.part", f"{stem}.rc")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def status(jid: str) -> str:
    """``success`` / ``failed`` once job ``jid`` has ended (by its exit status), else ``running``."""
    d = queue_dir()
    rc = d / f"{jid}.rc"
    if rc.exists():
        return "success" if rc.read_text().strip() == "0" else "failed"
    pid = d / f"{jid}.pid"
    if not pid.exists():
        return "failed"  # unknown job
    if _alive(int(pid.read_text())):
        return "running"
    time.sleep(0.2)  # the runner may be between the job's end and the rename
    if rc.exists():
        return "success" if rc.read_text().strip() == "0" else "failed"
    return "failed"  # killed without an exit status (cancelled, lost)


def cancel(jids: list[str]) -> None:
    """Terminate each job's process group (SIGTERM); unknown or finished jobs are skipped."""
    d = queue_dir()
    for jid in jids:
        pid = d / f"{jid}.pid"
        if pid.exists():
            try:
                os.killpg(int(pid.read_text()), signal.SIGTERM)
            except ProcessLookupError:
                pass


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "_run":  # internal: the detached runner of one job
        run(argv[1], float(argv[2]))
        return 0
    if len(argv) < 2 or argv[0] not in ("submit", "status", "cancel"):
        print(f"usage: {Path(__file__).name} submit JOBSCRIPT | status JOBID | cancel JOBID...", file=sys.stderr)
        return 2
    cmd, args = argv[0], argv[1:]
    if cmd == "submit":
        print(submit(args[-1]))  # the executor appends the job script as the last argument
    elif cmd == "status":
        print(status(args[0]))
    else:
        cancel(args)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
