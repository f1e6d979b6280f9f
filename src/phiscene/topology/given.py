"""``given`` backend: a topology read from a file (e.g. the benchmark's ``gt/topology.json``).

The file is validated against the scene's object ids, its edges are kept,
and the placement order is recomputed from the scene's footprints (the
file's own order is ignored); cycles, if any, are broken as for every
backend, and newly dropped edges are appended to the file's ``dropped_edges``.
"""

from __future__ import annotations

from dataclasses import dataclass

from phiscene.topology.graph import SupportGraph, load
from phiscene.topology.order import finalize
from phiscene.topology.params import BackendParams


@dataclass(frozen=True)
class GivenParams(BackendParams):
    """Parameters of the ``given`` backend.

    Attributes
    ----------
    path
        The topology JSON to use (``topology.infer(..., given_path=...)`` fills it).
    """

    path: str | None = None


def infer(scene, params: GivenParams) -> SupportGraph:
    """The topology in ``params.path``, checked against ``scene``, with a fresh order.

    Raises
    ------
    ValueError
        When no path is given.
    InputError
        When the file is malformed or does not list exactly the scene's objects.
    """
    if not params.path:
        raise ValueError("the 'given' topology backend needs a file (given_path)")
    graph = load(params.path, scene_ids=scene.ids)
    meta = {**graph.meta, "source": str(params.path), "source_backend": graph.backend}
    graph = SupportGraph(objects=graph.objects, edges=graph.edges, dropped_edges=graph.dropped_edges,
                         backend="given", meta=meta, structure=graph.structure)
    return finalize(graph, scene=scene)
