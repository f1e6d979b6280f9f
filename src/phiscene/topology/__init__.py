"""Support topology (paper §3.1.1): support graph type, placement order, and inference backends.

Backends are looked up by name; each is a function ``infer(scene, params) ->
SupportGraph`` (with the order filled) plus a parameter dataclass with
``from_dict``. Built in:

``geometric``
    Load-bearing support from near-contact geometry of the initial scene (offline default).
``height``
    The paper's Z-topo baseline (order by mean vertex height).
``given``
    A topology file (e.g. the benchmark's ground truth), checked against the scene.
``mllm``
    A multimodal LLM (Gemini or any OpenAI-compatible endpoint) with the paper's prompts.

A new backend plugs in with :func:`register_backend`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path

from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph, check_graph, load, save

__all__ = ["GROUND", "SupportEdge", "SupportGraph", "check_graph", "load", "save", "infer",
           "register_backend", "backend_names", "get_backend"]


@dataclass(frozen=True)
class Backend:
    """A registered backend.

    Attributes
    ----------
    infer
        ``infer(scene, params) -> SupportGraph``.
    params_cls
        Its parameter dataclass (with ``from_dict(dict)``).
    takes_path
        Whether it reads a topology file (``params.path``, filled from ``given_path``).
    """

    infer: Callable
    params_cls: type
    takes_path: bool = False


#: Built-in backends: name -> (module, function, params class, takes a path).
_BUILTIN = {
    "geometric": ("phiscene.topology.geometric", "infer", "GeometricParams", False),
    "height": ("phiscene.topology.height", "infer", "HeightParams", False),
    "given": ("phiscene.topology.given", "infer", "GivenParams", True),
    "mllm": ("phiscene.topology.mllm", "infer", "MllmParams", False),
}
_REGISTRY: dict[str, Backend] = {}


def register_backend(name: str, infer_fn: Callable, params_cls: type, takes_path: bool = False) -> None:
    """Make a backend available to :func:`infer` under ``name`` (replacing one of that name)."""
    _REGISTRY[name] = Backend(infer_fn, params_cls, takes_path)


def backend_names() -> list[str]:
    """Names of every available backend, sorted."""
    return sorted(set(_BUILTIN) | set(_REGISTRY))


def get_backend(name: str) -> Backend:
    """The backend called ``name`` (built-ins are imported on first use).

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    if name not in _REGISTRY:
        if name not in _BUILTIN:
            raise ValueError(f"unknown topology backend {name!r}; known: {backend_names()}")
        module, fn, cls, takes_path = _BUILTIN[name]
        mod = import_module(module)
        register_backend(name, getattr(mod, fn), getattr(mod, cls), takes_path)
    return _REGISTRY[name]


def infer(scene, backend: str, params: dict | None = None, given_path: str | Path | None = None,
          attached: dict | None = None) -> SupportGraph:
    """Infer the support graph of ``scene`` with the named backend.

    Parameters
    ----------
    scene
        A :class:`phiscene.scene.Scene`.
    backend
        A name from :func:`backend_names`.
    params
        The backend's parameters (``config.yaml`` ``topology.<backend>``); unknown keys raise ``ValueError``.
    given_path
        Topology file for backends that read one (``given``); overrides ``params['path']``.
    attached
        Settings of the attachment decision (:class:`phiscene.topology.attached.AttachedParams`), run on the
        graph of every backend that infers one (not on a given file's graph, which says what it says).

    Returns
    -------
    The graph, acyclic, with ``order`` and ``dropped_edges`` filled.
    """
    from phiscene.topology.attached import AttachedParams, mark_attached

    b = get_backend(backend)
    params = dict(params or {})
    if given_path is not None:
        if not b.takes_path:
            raise ValueError(f"topology backend {backend!r} does not read a file (given_path={str(given_path)!r})")
        params["path"] = str(given_path)
    graph = b.infer(scene, b.params_cls.from_dict(params))
    return graph if b.takes_path else mark_attached(scene, graph, AttachedParams.from_dict(attached or {}))
