"""Floor-standing furniture: chairs, tables, beds and cabinets stand on the floor, not on each other.

A 3D foundation model's depth errors slide furniture into each other: the chairs around a table overlap their
neighbours and sit under the table top, and a table whose legs the reconstruction cut off floats above the floor
over the chairs' seats. Read from near contact alone, such a scene says the table rests on two chairs and the chairs
on each other, and a scene grounded on that graph collapses when it is released as a whole. Furniture is made to
stand on the floor, so the geometric backend takes the description as a prior (:func:`floor_standing`, setting
``topology.geometric.floor_reach``): an object whose description's head noun names floor furniture
(:data:`~phiscene.topology.words.FURNITURE_WORDS`; not one it says is mounted) and whose bottom is within
``floor_reach`` of the ground keeps
only supporters that lie low themselves (a rug, a mat, a platform: their top within ``floor_reach`` of the ground)
and its walls or objects it leans on, and gets the ground as a supporter. A chair stacked on a table, a stool on a
desk, a table lamp (head noun "lamp") or anything whose bottom is higher are left as the geometry says.
"""

from __future__ import annotations

from phiscene.topology.graph import GROUND, SupportEdge
from phiscene.topology.words import names_furniture

#: Relations an object keeps whatever the prior says (it leans on a wall or an object besides standing).
KEPT_RELATIONS = ("leans_on",)


def floor_standing(edges: list[SupportEdge], scene, bounds: dict, floor_reach: float) -> tuple[list[SupportEdge],
                                                                                                   list[str]]:
    """Apply the floor prior (module docstring) to a graph's edges.

    Parameters
    ----------
    edges
        Support edges of the scene.
    scene
        The scene (descriptions and ground height).
    bounds
        Object id -> world AABB (2, 3).
    floor_reach
        Furniture whose bottom is within this distance (m) of the ground stands on it; supporters whose top is
        within it of the ground (a rug) are kept. 0 disables the prior.

    Returns
    -------
    edges
        The edges with the prior applied.
    changed
        Ids of the objects whose supporters it changed, in scene order.
    """
    if floor_reach <= 0:
        return edges, []
    ground = float(scene.ground_height)
    furniture = [o.id for o in scene.objects
                 if names_furniture(o.description or o.id.replace("_", " "))
                 and bounds[o.id][0][2] - ground <= floor_reach]
    out = list(edges)
    changed = []
    for oid in furniture:
        incoming = [e for e in out if e.target == oid]
        high = [e for e in incoming if e.relation not in KEPT_RELATIONS and e.source != GROUND
                and e.source in bounds and bounds[e.source][1][2] - ground > floor_reach]
        on_ground = any(e.source == GROUND for e in incoming)
        if not high and on_ground:
            continue
        out = [e for e in out if e not in high]
        if not on_ground:
            gap = 100 * (bounds[oid][0][2] - ground)
            out.append(SupportEdge(GROUND, oid, "supports", 0.9,
                                   f"floor furniture (description), its bottom {gap:.1f} cm from the floor"))
        changed.append(oid)
    return out, changed
