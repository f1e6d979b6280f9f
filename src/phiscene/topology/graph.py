"""The support graph: objects plus the ground, directed support edges, a placement order.

An edge ``from -> to`` means that ``from`` physically carries (part of) the
weight of ``to`` (paper Eq. 2; the edge fields follow the paper's MLLM schema).
The ground is the node ``"ground"``; it only ever supports. The file format is
docs/DESIGN.md §3's topology JSON (schema ``phiscene.topology/1``)::

    {"format": "phiscene.topology/1", "backend": "geometric",
     "objects": ["ground", "obj_01", ...],
     "edges": [{"from": "ground", "to": "obj_01", "relation": "supports",
                "confidence": 0.9, "reason": "..."}],
     "order": ["obj_01", ...], "dropped_edges": [...], "meta": {...}}

The ground node is implicit: a file whose ``objects`` omit ``"ground"`` still
gets it. ``order`` lists every non-ground object exactly once.

Scenes with walls or a ceiling (:attr:`phiscene.scene.Scene.structure`) may name
those planes as supporter nodes: the optional key ``"structure": ["wall_0", ...]``
lists them. Like the ground they only ever support (``leans_on`` for an object
leaning on a wall, ``attached`` for one fixed to it), are never placed and are
not objects (``objects`` and ``order`` leave them out).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from phiscene import schemas
from phiscene.atomic import write_json
from phiscene.errors import InputError

FORMAT = "phiscene.topology/1"
#: Name of the ground node.
GROUND = "ground"


@dataclass(frozen=True)
class SupportEdge:
    """One directed support relation ``source -> target`` (``source`` carries ``target``).

    Attributes
    ----------
    source
        The supporting node (an object id or ``"ground"``); ``"from"`` in JSON.
    target
        The supported object id; ``"to"`` in JSON.
    relation
        ``supports`` (load from below), ``leans_on`` (near-vertical contact that
        keeps ``target`` from tipping) or ``contains``.
    confidence
        In [0, 1]; cycle breaking drops the least confident edge first.
    reason
        A short free-text explanation.
    """

    source: str
    target: str
    relation: str = "supports"
    confidence: float = 1.0
    reason: str = ""

    @property
    def pair(self) -> tuple[str, str]:
        """``(source, target)``."""
        return (self.source, self.target)

    def to_dict(self) -> dict:
        """JSON form with the schema's ``from``/``to`` keys."""
        d = {"from": self.source, "to": self.target, "relation": self.relation,
             "confidence": round(float(self.confidence), 6)}
        if self.reason:
            d["reason"] = self.reason
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SupportEdge":
        """Inverse of :meth:`to_dict` (schema-valid input assumed); a missing confidence is 1."""
        return cls(source=d["from"], target=d["to"], relation=d.get("relation", "supports"),
                   confidence=float(d.get("confidence", 1.0)), reason=d.get("reason", ""))


@dataclass
class SupportGraph:
    """Support topology of one scene (paper's ``G^{+g}`` plus its placement order).

    Attributes
    ----------
    objects
        Node names, ``"ground"`` first, then the object ids.
    edges
        The support edges that are kept (acyclic once :func:`phiscene.topology.order.finalize` ran).
    order
        Placement order of the non-ground objects (empty until computed).
    dropped_edges
        Edges removed to break cycles, in the order they were dropped.
    backend
        Name of the backend that produced the graph.
    meta
        Free-form extra data (parameters, per-object diagnostics).
    structure
        Ids of the wall and ceiling planes that are supporter nodes (like the ground; never targets).
    """

    objects: list[str]
    edges: list[SupportEdge]
    order: list[str] = field(default_factory=list)
    dropped_edges: list[SupportEdge] = field(default_factory=list)
    backend: str = ""
    meta: dict = field(default_factory=dict)
    structure: list[str] = field(default_factory=list)

    @property
    def fixed_nodes(self) -> set[str]:
        """The nodes that only support: the ground and the structure planes."""
        return {GROUND, *self.structure}

    def __post_init__(self) -> None:
        self.objects = [GROUND] + [o for o in self.objects if o != GROUND]

    @property
    def object_ids(self) -> list[str]:
        """The non-ground nodes, in file order."""
        return self.objects[1:]

    def pairs(self) -> set[tuple[str, str]]:
        """The kept edges as ``(from, to)`` pairs."""
        return {e.pair for e in self.edges}

    def parents(self, object_id: str) -> list[str]:
        """Supporters of ``object_id`` (ground included), in edge order."""
        return [e.source for e in self.edges if e.target == object_id]

    def children(self, node: str) -> list[str]:
        """Objects that ``node`` supports, in edge order."""
        return [e.target for e in self.edges if e.source == node]

    def to_networkx(self, include_ground: bool = True):
        """A :class:`networkx.DiGraph` of the kept edges; edge attributes are the edge fields.

        Parameters
        ----------
        include_ground
            Keep the ground and structure nodes and their edges (``False`` gives the paper's object-only graph ``G``).
        """
        import networkx as nx

        g = nx.DiGraph()
        g.add_nodes_from([*self.objects, *self.structure] if include_ground else self.object_ids)
        for e in self.edges:
            if include_ground or e.source not in self.fixed_nodes:
                g.add_edge(e.source, e.target, relation=e.relation, confidence=e.confidence, reason=e.reason)
        return g

    def with_edges(self, edges: Sequence[SupportEdge], **changes) -> "SupportGraph":
        """A copy with other edges (and optionally other fields)."""
        return replace(self, edges=list(edges), **changes)

    def to_dict(self) -> dict:
        """The topology JSON document (docs/DESIGN.md §3)."""
        out = {"format": FORMAT, "backend": self.backend, "objects": list(self.objects),
               "edges": [e.to_dict() for e in self.edges], "order": list(self.order),
               "dropped_edges": [e.to_dict() for e in self.dropped_edges]}
        if self.structure:
            out["structure"] = list(self.structure)
        if self.meta:
            out["meta"] = self.meta
        return out

    @classmethod
    def from_dict(cls, data: dict, path: str | Path | None = None,
                  scene_ids: Iterable[str] | None = None) -> "SupportGraph":
        """Validate a topology document and build the graph.

        Parameters
        ----------
        data
            The parsed JSON.
        path
            File named in error messages.
        scene_ids
            When given, the object set must equal these ids (ground aside).

        Raises
        ------
        InputError
            Schema violations, unknown format, and the graph checks of :func:`check_graph`.
        """
        if isinstance(data, dict) and "format" not in data:
            raise InputError(path, "format", f"missing; expected {FORMAT!r}")
        schemas.validate(data, "topology", path)
        graph = cls(objects=list(data["objects"]), edges=[SupportEdge.from_dict(e) for e in data["edges"]],
                    order=list(data.get("order", [])),
                    dropped_edges=[SupportEdge.from_dict(e) for e in data.get("dropped_edges", [])],
                    backend=data.get("backend", ""), meta=dict(data.get("meta", {})),
                    structure=list(data.get("structure", [])))
        check_graph(graph, path, scene_ids)
        return graph


def check_graph(graph: SupportGraph, path: str | Path | None = None,
                scene_ids: Iterable[str] | None = None) -> None:
    """Check node names, edges and order of ``graph``; raise :class:`InputError` naming file and field.

    Rejected: edges naming unknown nodes, self loops, duplicate ``(from, to)``
    pairs, edges into the ground or a structure plane, structure ids that are
    also objects, an ``order`` that is not a permutation of the objects, and
    (when ``scene_ids`` is given) objects missing from or extra to the scene.
    """
    known = set(graph.objects)
    if len(known) != len(graph.objects):
        raise InputError(path, "objects", "duplicate object names")
    planes = set(graph.structure)
    if len(planes) != len(graph.structure) or planes & known:
        raise InputError(path, "structure", f"duplicate or object-named plane ids {sorted(graph.structure)}")
    if scene_ids is not None:
        scene_set = set(scene_ids)
        if GROUND in scene_set:
            raise InputError(path, "objects", f"the scene uses the reserved id {GROUND!r}")
        missing = sorted(scene_set - known)
        extra = sorted(known - scene_set - {GROUND})
        if missing:
            raise InputError(path, "objects", f"missing scene objects {missing}")
        if extra:
            raise InputError(path, "objects", f"objects not in the scene {extra}")
    known |= planes
    for key, edges in (("edges", graph.edges), ("dropped_edges", graph.dropped_edges)):
        seen: set[tuple[str, str]] = set()
        for i, e in enumerate(edges):
            where = f"{key}[{i}]"
            if e.source not in known:
                raise InputError(path, f"{where}.from", f"unknown node {e.source!r}")
            if e.target not in known:
                raise InputError(path, f"{where}.to", f"unknown node {e.target!r}")
            if e.target == GROUND or e.target in planes:
                raise InputError(path, f"{where}.to", "the ground cannot be supported" if e.target == GROUND
                                 else f"the plane {e.target!r} cannot be supported")
            if e.source == e.target:
                raise InputError(path, where, f"self loop on {e.source!r}")
            if e.pair in seen:
                raise InputError(path, where, f"duplicate edge {e.source!r} -> {e.target!r}")
            seen.add(e.pair)
    if graph.order:
        if GROUND in graph.order:
            raise InputError(path, "order", "the ground is not placed and must not be in the order")
        if sorted(graph.order) != sorted(graph.object_ids):
            missing = sorted(set(graph.object_ids) - set(graph.order))
            extra = sorted(set(graph.order) - set(graph.object_ids))
            raise InputError(path, "order", f"not a permutation of the objects (missing {missing}, unknown {extra})")


def load(path: str | Path, scene_ids: Iterable[str] | None = None) -> SupportGraph:
    """Read and validate a topology JSON file.

    Parameters
    ----------
    path
        The file.
    scene_ids
        Optional object ids of the scene the topology belongs to; the file must list exactly these.

    Raises
    ------
    InputError
        Missing or malformed file, schema violation, or a failed :func:`check_graph`.
    """
    return SupportGraph.from_dict(schemas.read_json(path), path, scene_ids)


def save(graph: SupportGraph, path: str | Path) -> Path:
    """Validate ``graph`` and write it atomically as topology JSON.

    Raises
    ------
    InputError
        When the graph would not load back (the same checks as :func:`load`).
    """
    path = Path(path)
    data = graph.to_dict()
    schemas.validate(data, "topology", path)
    check_graph(graph, path)
    write_json(path, data)
    return path
