"""``height`` backend: the paper's Z-topo baseline (ordering by mean vertex height).

Order: objects sorted by the mean height of their world-frame mesh vertices,
ascending (ties by id), as the paper's "Z Topo." ablation does.

Edges (a single parent per object, pointing from lower to higher):

* ``ground -> A`` if A's lowest world point is within ``ground_tolerance`` of the ground;
* otherwise ``B -> A`` for the object B *directly below* A: B's world AABB
  overlaps A's in xy, B's top (highest point) is below A's AABB centre, and
  B's mean vertex height is below A's (so the edges agree with the order);
  among such B the one with the highest top wins (ties by id);
* ``ground -> A`` when no object qualifies.

The edges are consistent with the mean-height order by construction, and
Kahn's algorithm with the mean height as priority returns exactly that order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph
from phiscene.topology.order import finalize
from phiscene.topology.params import BackendParams


@dataclass(frozen=True)
class HeightParams(BackendParams):
    """Parameters of the ``height`` backend.

    Attributes
    ----------
    ground_tolerance
        An object whose lowest point is at most this high above the ground (m) rests on the ground.
    """

    ground_tolerance: float = 0.02


def infer(scene, params: HeightParams = HeightParams()) -> SupportGraph:
    """Z-topo support graph and order of ``scene`` (see the module docstring)."""
    meshes = {o.id: o.world_mesh() for o in scene.objects}
    mean_z = {k: float(np.asarray(m.vertices)[:, 2].mean()) for k, m in meshes.items()}
    bounds = {k: np.asarray(m.bounds, dtype=float) for k, m in meshes.items()}
    edges = []
    for a in scene.ids:
        lo, hi = bounds[a]
        if lo[2] - scene.ground_height <= params.ground_tolerance:
            edges.append(SupportEdge(GROUND, a, "supports", 1.0, "lowest point at the ground"))
            continue
        centre_z = 0.5 * (lo[2] + hi[2])
        best = None
        for b in scene.ids:
            if b == a:
                continue
            blo, bhi = bounds[b]
            overlap = np.all(np.minimum(hi[:2], bhi[:2]) > np.maximum(lo[:2], blo[:2]))
            if overlap and bhi[2] < centre_z and mean_z[b] < mean_z[a]:
                if best is None or (-bhi[2], b) < (-bounds[best][1][2], best):
                    best = b
        if best is None:
            edges.append(SupportEdge(GROUND, a, "supports", 0.5, "nothing below: assumed on the ground"))
        else:
            edges.append(SupportEdge(best, a, "supports", 1.0, "highest top directly below the centre"))
    graph = SupportGraph(objects=[GROUND] + scene.ids, edges=edges, backend="height",
                         meta={"params": params.to_dict(), "mean_height": mean_z})
    return finalize(graph, key=lambda n: (mean_z[n], n))
