"""Assets of the ``clutter`` suite: the contact library, furniture, wall-fixed items, bowls and baskets.

Every asset is a procedural, watertight rigid body made by :func:`phiscene.bench.cleanmesh.canonical`
(recentred on its bounding box). Wall-fixed items (``poster``, ``frame``, ``wall_shelf``) are thin boxes
whose wall side is local ``+y``. Bowls and baskets are open containers with ``meta`` ``inner`` (inner
size in x and y, m; a bowl's is its inner diameter twice) and ``floor`` (local z of the inner floor).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh

from phiscene.bench.assets import COLORS, WOOD, Asset, asset_library, box_mesh, open_box_mesh
from phiscene.bench.cleanmesh import canonical
from phiscene.bench.furniture import furniture_asset

#: Furniture of the clutter library (category, count).
FURNITURE = (("shelf", 3), ("dining_table", 2), ("chair", 3), ("vase", 2), ("lamp", 1))
#: Wall-fixed items of the clutter library (category, count).
WALL_ITEMS = (("poster", 3), ("frame", 3), ("wall_shelf", 3))
#: Open containers of the clutter library besides the contact library's trays and crates (category, count).
CONTAINER_ITEMS = (("bowl", 3), ("basket", 2))
#: Facets of a bowl's walls.
BOWL_SECTIONS = 32


def wall_item(category: str, name: str, rng: np.random.Generator) -> Asset:
    """A thin box fixed to a wall: ``poster`` (paper), ``frame`` (a framed picture) or ``wall_shelf`` (a board).

    Local frame: the wall side is ``+y``; a shelf board's top face is up.
    """
    u = rng.uniform
    if category == "poster":
        size = np.round([u(0.3, 0.6), u(0.004, 0.008), u(0.4, 0.8)], 3)
        cname, rgb = _choose_color(rng, ("red", "blue", "yellow", "teal", "white"))
        desc = f"{cname} poster on the wall {int(round(100 * size[2]))} cm"
    elif category == "frame":
        size = np.round([u(0.25, 0.5), u(0.02, 0.035), u(0.2, 0.45)], 3)
        cname, rgb = _choose_color(rng, ("black", "white", "brown"))
        desc = f"{cname} framed picture on the wall {int(round(100 * size[0]))} cm"
    elif category == "wall_shelf":
        size = np.round([u(0.45, 0.8), u(0.18, 0.25), u(0.02, 0.03)], 3)
        cname, rgb = sorted(WOOD.items())[int(rng.integers(len(WOOD)))]
        desc = f"{cname} wall-mounted shelf {int(round(100 * size[0]))} cm"
    else:
        raise ValueError(f"unknown wall item {category!r}")
    return Asset(name, desc, category, rgb, lambda: canonical(box_mesh(size), name=name), {"size": size.tolist()},
                 {"box": size.tolist()})


def _choose_color(rng: np.random.Generator, names: tuple[str, ...]) -> tuple[str, tuple[int, int, int]]:
    name = names[int(rng.integers(len(names)))]
    return name, COLORS[name]


def container_item(category: str, name: str, rng: np.random.Generator) -> Asset:
    """An open container: a round ``bowl`` (8-12 cm radius) or a rectangular wicker ``basket``."""
    u = rng.uniform
    if category == "bowl":
        r, h, wall, base = round(u(0.08, 0.12), 3), round(u(0.06, 0.09), 3), 0.008, 0.01
        cname, rgb = _choose_color(rng, ("white", "blue", "teal", "beige"))
        meta = {"size": [2 * r, 2 * r, h], "inner": [2 * (r - wall)] * 2, "floor": base - h / 2, "wall": wall,
                "round": True}

        def build():
            outer = trimesh.creation.cylinder(radius=r, height=h, sections=BOWL_SECTIONS)
            inner = trimesh.creation.cylinder(radius=r - wall, height=h, sections=BOWL_SECTIONS)
            inner.apply_translation((0.0, 0.0, base))
            return canonical(trimesh.boolean.difference([outer, inner], engine="manifold"), name=name)

        return Asset(name, f"{cname} bowl {int(round(200 * r))} cm", category, rgb, build, meta,
                     {"bowl": [r, h, wall, base, BOWL_SECTIONS]})
    if category == "basket":
        outer = np.round([u(0.28, 0.4), u(0.22, 0.3), u(0.07, 0.11)], 3)
        wall, base = 0.012, 0.012
        meta = {"size": outer.tolist(), "inner": [float(outer[0] - 2 * wall), float(outer[1] - 2 * wall)],
                "floor": float(base - outer[2] / 2), "wall": wall}
        return Asset(name, f"wicker basket {int(round(100 * outer[0]))} cm", category, (190, 150, 90),
                     lambda: canonical(open_box_mesh(outer, wall, base), name=name), meta,
                     {"open_box": [*outer.tolist(), wall, base]})
    raise ValueError(f"unknown container {category!r}")


@lru_cache(maxsize=8)
def clutter_library(seed: int, n: int, cache_dir: Path | None = None) -> tuple[Asset, ...]:
    """The deterministic asset library of the clutter suite.

    The contact library of the same seed and size (:func:`phiscene.bench.assets.asset_library`), then
    the furniture of :data:`FURNITURE` (designs of :mod:`phiscene.bench.furniture`), the wall items
    of :data:`WALL_ITEMS` (:func:`wall_item`) and the containers of :data:`CONTAINER_ITEMS`
    (:func:`container_item`), each drawn from ``default_rng([seed, 3_000_017, i])``.
    """
    out = list(asset_library(seed, n, cache_dir))
    i = 0
    for table, make in ((FURNITURE, furniture_asset), (WALL_ITEMS, wall_item), (CONTAINER_ITEMS, container_item)):
        for category, count in table:
            for k in range(count):
                asset = make(category, f"{category}_{k + 1:02d}", np.random.default_rng([seed, 3_000_017, i]))
                asset.cache_dir = None if cache_dir is None else Path(cache_dir)
                out.append(asset)
                i += 1
    return tuple(out)
