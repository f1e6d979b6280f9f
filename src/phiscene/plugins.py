"""Plugins: Python modules named in config ``plugins:`` that register extensions before the workflow runs.

A plugin is an importable module whose import registers entries in phiscene's registries: table kinds
(:mod:`phiscene.table_registry`), metric sections (:mod:`phiscene.metrics.sections`), drift simulators
(:mod:`phiscene.metrics.drift`), baselines (:mod:`phiscene.baselines.registry`) and topology backends
(:mod:`phiscene.topology`). The Snakefile imports them before checking the config, and the job scripts that
read a registry import them again in their own process, so a new table, metric, simulator or baseline needs no
edit of phiscene or of the workflow.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable

from phiscene.errors import PhisceneError


class PluginError(PhisceneError):
    """A plugin module that cannot be imported (one line naming it): a setup problem, not a scene's."""

    per_scene = False


def load_plugins(names: Iterable[str] | None) -> list[str]:
    """Import every plugin module (once; Python caches imports) and return their names.

    Raises
    ------
    PluginError
        ``config: plugins: cannot import '<name>' (<error>)``.
    """
    loaded = []
    for name in names or ():
        try:
            importlib.import_module(name)
        except Exception as exc:  # any import failure of user code: one line naming the module
            raise PluginError(f"config: plugins: cannot import {name!r} ({type(exc).__name__}: {exc})") from None
        loaded.append(name)
    return loaded
