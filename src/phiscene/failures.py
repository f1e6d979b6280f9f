"""Failure records: a scene that cannot be processed is a result, not a crash.

When a per-scene workflow job (proxies, topology, a method, a metric) fails
for a reason that belongs to the scene's data, i.e. a
:class:`~phiscene.errors.PhisceneError` such as a corrupt mesh or a
malformed pose, the job does not die: :func:`phiscene.runner.job` writes a
*failure record* to each of its declared outputs (atomically) and succeeds.
Snakemake therefore keeps building the rest of the DAG, and the failure
travels downstream like data:

* every loader that reads a stage output (:func:`phiscene.schemas.read_json`,
  so ``load_scene`` and ``topology.load``, and
  :func:`phiscene.proxies.read_proxies`) raises :class:`FailedInput` when it
  is handed a failure record, so the next job records the failure in turn;
* the tables count the scene in ``n_failed`` instead of dropping it
  (:mod:`phiscene.tables`).

Any other exception is a bug and still fails the job with its traceback.

A failure record is one small JSON document (also at an ``.npz`` path: the
readers look at the content, not the suffix)::

    {"format": "phiscene.failure/1", "status": "failed", "failed": true,
     "job": "proxies contact/scene_001",            # the job that wrote this record
     "failed_in": "proxies contact/scene_001",      # the job where the failure started
     "error": "results/scenes/.../initial/scene.json: objects[2].mesh: cannot read mesh (...)"}

To retry failed scenes after fixing their data, force their records to be
rebuilt, e.g. ``snakemake -R $(phiscene failures results)``.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from pathlib import Path

from phiscene.atomic import write_json
from phiscene.errors import PhisceneError

FORMAT = "phiscene.failure/1"
#: Failure records are small; a larger file is never parsed to check whether it is one.
_MAX_RECORD_BYTES = 1 << 16


class FailedInput(PhisceneError):
    """An input of a job is a failure record: the scene already failed upstream.

    Attributes
    ----------
    path
        The failure record that was read.
    record
        Its content (see the module docstring).
    """

    def __init__(self, path: str | Path, record: dict):
        self.path = str(path)
        self.record = record
        super().__init__(f"{path}: upstream job '{record.get('failed_in', '?')}' failed: {record.get('error', '?')}")


def is_failure_record(data) -> bool:
    """Whether parsed JSON ``data`` is a failure record."""
    return isinstance(data, dict) and data.get("format") == FORMAT


def failure_record(job: str, error: str, failed_in: str | None = None) -> dict:
    """The failure record of ``job``.

    Parameters
    ----------
    job
        Name of the job writing the record.
    error
        One-line message of the root cause.
    failed_in
        The job where the failure started (``job`` itself when omitted).
    """
    return {"format": FORMAT, "status": "failed", "failed": True, "job": job, "failed_in": failed_in or job,
            "error": error}


def record_for(job: str, exc: PhisceneError) -> dict:
    """The failure record of ``job`` failing with ``exc`` (an upstream failure keeps its root cause)."""
    if isinstance(exc, FailedInput):
        return failure_record(job, exc.record.get("error", str(exc)), exc.record.get("failed_in"))
    return failure_record(job, str(exc))


def write_failure(paths: Iterable[str | Path], record: dict) -> None:
    """Write ``record`` atomically to every path (a half-written record never exists)."""
    for p in paths:
        write_json(p, record)


def record_failure(job: str, exc: PhisceneError, outputs: Iterable[str | Path], logger: logging.Logger) -> None:
    """Write ``job``'s failure record (root cause from ``exc``) to every output and log it as one line."""
    outputs = [str(p) for p in outputs]
    write_failure(outputs, record_for(job, exc))
    logger.error("%s: FAILED (recorded in %s): %s", job, ", ".join(outputs), exc)


def read_failure(path: str | Path) -> dict | None:
    """The failure record stored at ``path``, or ``None`` if the file is something else (or absent).

    Only small files that start with ``{`` are parsed, so checking a large
    ``.npz`` or mesh costs one read of a few bytes.
    """
    path = Path(path)
    try:
        if path.stat().st_size > _MAX_RECORD_BYTES:
            return None
        raw = path.read_bytes()
    except OSError:
        return None
    if not raw.lstrip().startswith(b"{"):
        return None
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return data if is_failure_record(data) else None


def raise_if_failed(path: str | Path) -> None:
    """Raise :class:`FailedInput` if ``path`` holds a failure record."""
    record = read_failure(path)
    if record is not None:
        raise FailedInput(path, record)


def find_failures(root: str | Path) -> list[Path]:
    """Every failure record under ``root`` (JSON and ``.npz`` outputs), sorted.

    Parameters
    ----------
    root
        A results folder.
    """
    root = Path(root)
    found = []
    for pattern in ("*.json", "*.npz"):
        for p in root.rglob(pattern):
            if p.is_file() and not p.name.startswith(".") and read_failure(p) is not None:
                found.append(p)
    return sorted(found)
