"""Placement order: cycle breaking and Kahn's algorithm with a footprint tie-break (paper §3.1.1).

The paper removes the ground node and runs Kahn's algorithm on the
object-only graph, breaking ties among nodes of zero in-degree by descending
top-down footprint area (the area of the object's OBB projected onto the
ground plane), then by id so the order is deterministic. A support graph
from a backend may contain cycles (e.g. two objects leaning on each other);
:func:`break_cycles` removes, while a cycle exists, the least confident edge
on the cycle that :func:`networkx.find_cycle` reports.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Sequence

import numpy as np

from phiscene.tolerances import TOL
from phiscene.topology.graph import SupportEdge, SupportGraph


def footprint_area(mesh) -> float:
    """Top-down footprint of a world-frame mesh: the area of its OBB projected onto the ground.

    The oriented bounding box is the minimum-volume box of the mesh (:func:`phiscene.meshes.oriented_box`); see
    :func:`box_footprint_area`.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object in world coordinates.

    Returns
    -------
    area : float
        Square metres.
    """
    from phiscene.meshes import oriented_box

    return box_footprint_area(np.asarray(oriented_box(mesh).vertices, dtype=float))


def box_footprint_area(corners: np.ndarray) -> float:
    """Area of the 2D convex hull of box corners projected to xy (0 for a degenerate projection).

    Parameters
    ----------
    corners : (8, 3) float
        World corners of an oriented box.
    """
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(np.asarray(corners, dtype=float)[:, :2]).volume)  # 2D "volume" is area
    except QhullError:
        return 0.0


def footprint_areas(scene) -> dict[str, float]:
    """:func:`footprint_area` of every object of a :class:`~phiscene.scene.Scene`, by id."""
    return {o.id: footprint_area(o.world_mesh()) for o in scene.objects}


def footprint_key(areas: dict[str, float]) -> Callable[[str], tuple]:
    """Priority key of Kahn's algorithm: larger footprint first, then id.

    Areas are compared after rounding to ``TOL.footprint_resolution`` so that
    equal objects tie exactly (and fall back to id order) on every platform.
    """
    res = TOL.footprint_resolution

    def key(node: str) -> tuple:
        return (-round(areas.get(node, 0.0) / res), node)

    return key


def _edge_rank(e: SupportEdge) -> tuple:
    """Which edge of a cycle goes first: lowest confidence, then ``leans_on`` before ``supports``, then names."""
    return (e.confidence, e.relation != "leans_on", e.source, e.target)


def break_cycles(edges: Sequence[SupportEdge]) -> tuple[list[SupportEdge], list[SupportEdge]]:
    """Remove edges until the support graph is acyclic.

    While :func:`networkx.find_cycle` finds a cycle (the graph is built from
    the edges sorted by name, so the result does not depend on input order),
    the cycle's edge with the lowest confidence is dropped; ties prefer a
    ``leans_on`` edge, then the lexicographically smallest ``(from, to)``.
    Edges from the ground or a wall are never on a cycle (nothing points into them).

    Returns
    -------
    kept
        The remaining edges, in input order.
    dropped
        The removed edges, in the order they were removed.
    """
    import networkx as nx

    by_pair = {e.pair: e for e in edges}
    g = nx.DiGraph()
    g.add_edges_from(sorted(by_pair))
    dropped: list[SupportEdge] = []
    while True:
        try:
            cycle = nx.find_cycle(g)
        except nx.NetworkXNoCycle:
            break
        worst = min((by_pair[(u, v)] for u, v, *_ in cycle), key=_edge_rank)
        g.remove_edge(*worst.pair)
        dropped.append(worst)
    gone = {e.pair for e in dropped}
    return [e for e in edges if e.pair not in gone], dropped


def kahn_order(nodes: Iterable[Hashable], edges: Iterable[tuple[Hashable, Hashable]],
               key: Callable[[Hashable], tuple]) -> list:
    """Kahn's topological sort with a priority among ready nodes.

    :func:`networkx.lexicographical_topological_sort` is Kahn's algorithm
    whose ready set is a heap ordered by ``key``.

    Parameters
    ----------
    nodes
        Every node to order (isolated ones included).
    edges
        ``(u, v)``: ``u`` must come before ``v``; the graph must be acyclic.
    key
        Smaller key = placed first among nodes whose predecessors are all placed.

    Raises
    ------
    networkx.NetworkXUnfeasible
        If the edges contain a cycle.
    """
    import networkx as nx

    g = nx.DiGraph()
    g.add_nodes_from(nodes)
    g.add_edges_from(edges)
    return list(nx.lexicographical_topological_sort(g, key=key))


def placement_order(graph: SupportGraph, areas: dict[str, float]) -> list[str]:
    """Paper's TopoSort: Kahn on the object-only graph, ties by descending footprint, then id.

    Parameters
    ----------
    graph
        An acyclic support graph.
    areas
        Footprint area per object id (see :func:`footprint_areas`).
    """
    pairs = [e.pair for e in graph.edges if e.source not in graph.fixed_nodes]
    return kahn_order(graph.object_ids, pairs, footprint_key(areas))


def finalize(graph: SupportGraph, areas: dict[str, float] | None = None, scene=None,
             key: Callable[[str], tuple] | None = None) -> SupportGraph:
    """Break cycles and fill the placement order.

    Parameters
    ----------
    graph
        Any support graph; its existing ``dropped_edges`` are kept and new ones appended.
    areas
        Footprint areas by object id; computed from ``scene`` when omitted.
    scene
        The scene the graph belongs to (needed only when ``areas`` and ``key`` are omitted).
    key
        A different priority among ready nodes (e.g. mean height for the Z-topo
        baseline); overrides the footprint rule.

    Returns
    -------
    A new graph with acyclic ``edges``, ``dropped_edges`` and ``order``.
    """
    kept, dropped = break_cycles(graph.edges)
    if key is None:
        if areas is None:
            if scene is None:
                raise ValueError("finalize needs footprint areas, a scene or a key")
            areas = footprint_areas(scene)
        key = footprint_key(areas)
    pairs = [e.pair for e in kept if e.source not in graph.fixed_nodes]
    order = kahn_order(graph.object_ids, pairs, key)
    return graph.with_edges(kept, order=order, dropped_edges=list(graph.dropped_edges) + dropped)
