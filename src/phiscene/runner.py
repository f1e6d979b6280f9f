"""Job plumbing shared by workflow scripts and the CLI: logging, threads, one-line errors."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from phiscene.errors import PhisceneError

log = logging.getLogger("phiscene")


def thread_budget() -> int:
    """This process's thread budget as :func:`set_threads` left it (``OMP_NUM_THREADS``); -1 (every core) if unset."""
    value = os.environ.get("OMP_NUM_THREADS", "")
    return int(value) if value.isdigit() and int(value) > 0 else -1


def set_threads(threads: int) -> None:
    """Limit every thread pool (BLAS, OpenMP, torch, open3d, libigl) of this process to ``threads``.

    Two parallel jobs whose pools each take every core slow each other down;
    Snakemake's ``threads:`` is the budget of one job.
    """
    threads = max(1, int(threads))
    # libigl reads IGL_NUM_THREADS at its first parallel loop
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS", "IGL_NUM_THREADS"):
        os.environ[var] = str(threads)
    # numpy's BLAS is already loaded, so environment variables come too late for it
    from threadpoolctl import threadpool_limits

    threadpool_limits(threads)
    # open3d's TBB pool ignores OMP_NUM_THREADS; phiscene.o3d bounds it on import, and here if already imported
    o3d = sys.modules.get("open3d")
    if o3d is not None:
        from phiscene.o3d import limit_threads

        limit_threads(o3d, threads)
    # torch reads OMP_NUM_THREADS when it is first imported; importing it here (1.5 s) would slow every job
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(threads)
        with contextlib.suppress(RuntimeError):
            torch.set_num_interop_threads(1)


def setup_logging(log_file: str | Path | None = None, level: int = logging.INFO) -> None:
    """Log phiscene messages to stderr and, if given, to ``log_file`` (overwritten)."""
    root = logging.getLogger()
    root.handlers.clear()
    fmt = logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s", "%H:%M:%S")
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if log_file:
        Path(log_file).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_file, mode="w"))
    for h in handlers:
        h.setFormatter(fmt)
        root.addHandler(h)
    root.setLevel(level)


@contextlib.contextmanager
def job(name: str, log_file: str | Path | None = None, threads: int = 1,
        failure_outputs: Iterable[str | Path] | None = None) -> Iterator[logging.Logger]:
    """Run one workflow job: set up logging and threads, time it, turn phiscene errors into one line.

    A :class:`~phiscene.errors.PhisceneError` (bad scene data, or an input
    that is already a failure record) is logged as a single line, no
    traceback from inside a library. What happens next depends on
    ``failure_outputs``:

    * given (per-scene jobs): a failure record (:mod:`phiscene.failures`) is
      written atomically to each of these outputs and the job succeeds, so
      the rest of the workflow and the tables go on, with this scene counted
      as failed;
    * omitted, or the error is a setup problem (``exc.per_scene`` is false): the
      process exits with status 1.

    Any other exception propagates with its traceback, since it is a bug.

    Parameters
    ----------
    name
        Job name for the log (and the failure record).
    log_file
        Log file (overwritten); stderr only when omitted.
    threads
        Thread budget (see :func:`set_threads`).
    failure_outputs
        The job's outputs, to hold failure records if the scene fails.
    """
    setup_logging(log_file)
    set_threads(threads)
    t0 = time.perf_counter()
    log.info("%s: start (threads=%d)", name, threads)
    try:
        yield log
    except PhisceneError as exc:
        if failure_outputs is None or not exc.per_scene:
            log.error("%s: %s", name, exc)
            logging.shutdown()
            raise SystemExit(1) from None
        from phiscene.failures import record_failure

        record_failure(name, exc, failure_outputs, log)
        return
    log.info("%s: done in %.2f s", name, time.perf_counter() - t0)
