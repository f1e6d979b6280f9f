"""One place that imports open3d, without its plotly/dash web visualiser.

``import open3d`` always imports ``open3d.visualization.draw_plotly``, which
imports ``dash`` and ``plotly``: about half of open3d's import time (0.7-1 s
of CPU), paid by every workflow job that computes a signed distance or runs
ICP. phiscene uses open3d's geometry, raycasting and registration only, never
``draw_plotly``, so :func:`open3d` imports it with placeholder ``dash`` and
``plotly.graph_objects`` modules and removes the placeholders right after:
a later ``import dash`` (by the user, or by a library) gets the real package.
Only ``open3d.visualization.draw_plotly*`` is unusable in such a process;
calling it raises :class:`RuntimeError` saying why.

Set ``PHISCENE_OPEN3D_FULL_IMPORT=1`` to import open3d unchanged.

open3d 0.19+ runs its parallel loops on oneAPI TBB, which ignores
``OMP_NUM_THREADS`` and takes every core, so a workflow job running ICP or
raycasting used more cores than its ``threads:`` (a clutter metrics job alone:
about 1.1 cores). :func:`open3d` therefore bounds open3d's threads to the job's
budget (:func:`limit_threads`, from ``OMP_NUM_THREADS`` as
:func:`phiscene.runner.set_threads` sets it). On two cores this changed no
throughput (two such jobs side by side: 29.8 s each, 30.4 s before); it keeps
jobs within what the scheduler gave them (a cluster node shared with others).
"""

from __future__ import annotations

import os
import sys
import types

#: Modules that open3d's ``draw_plotly`` imports at load time and that phiscene never uses.
_WEB_MODULES = ("dash", "plotly", "plotly.graph_objects")


class _Unavailable:
    """Stands for a name of a skipped module; any use says why it is missing."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr):
        raise RuntimeError(f"{self._name} was not imported (phiscene imports open3d without its plotly "
                           f"visualiser; set PHISCENE_OPEN3D_FULL_IMPORT=1 to use it)")

    def __call__(self, *args, **kwargs):
        return self.__getattr__("__call__")


def _placeholder(name: str) -> types.ModuleType:
    mod = types.ModuleType(name)
    mod.__getattr__ = lambda attr: _Unavailable(f"{name}.{attr}")  # type: ignore[attr-defined]
    return mod


def limit_threads(o3d, threads: int | None = None) -> None:
    """Bound open3d's TBB worker threads to ``threads`` (default: ``OMP_NUM_THREADS``; unset leaves TBB's default).

    Parameters
    ----------
    o3d
        The imported ``open3d`` module.
    threads
        Most threads open3d may use, the calling thread included.
    """
    if threads is None:
        from phiscene.runner import thread_budget

        threads = thread_budget()
    setter = getattr(o3d.utility, "set_max_threads", None)  # open3d >= 0.19
    if threads > 0 and setter is not None:
        setter(max(1, int(threads)))


def open3d():
    """The ``open3d`` module, imported once without its plotly/dash visualiser, its threads bounded by the job's budget.

    See the module docstring.
    """
    if "open3d" in sys.modules or os.environ.get("PHISCENE_OPEN3D_FULL_IMPORT") == "1":
        first = "open3d" not in sys.modules
        import open3d as o3d

        if first:
            limit_threads(o3d)
        return o3d
    added = [name for name in _WEB_MODULES if name not in sys.modules]
    for name in added:
        sys.modules[name] = _placeholder(name)
    try:
        import open3d as o3d
    finally:
        for name in added:
            if isinstance(sys.modules.get(name), types.ModuleType) and sys.modules[name].__spec__ is None:
                del sys.modules[name]
    limit_threads(o3d)
    return o3d
