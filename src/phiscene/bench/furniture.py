"""Furniture-scale assets of the ``rooms`` suite: procedural beds, tables, chairs, shelves, ... at real sizes.

Every piece of furniture is a handful of overlapping boxes (and cylinders for
lamps) joined by an exact boolean union (manifold3d) into one watertight mesh,
then made a rigid-body asset by :func:`phiscene.bench.cleanmesh.canonical`.
Sizes are metric and drawn per asset from a seed within the usual range of
the kind (a double bed is 1.4-1.8 m wide and 2.0-2.1 m long, a dining table
0.72-0.78 m high, ...), so the library has some variation.

Local frame of every asset before canonicalisation: the floor is ``z = 0``,
the piece is centred in x and y, its front faces ``-y`` (a chair's or a sofa's
back, a bed's headboard, a bookcase's back panel are at ``+y``). The canonical
mesh is recentred on its bounding box; :attr:`Asset.meta` then holds, in that
canonical frame:

``size``
    Bounding-box size (3,) in metres.
``top``
    Only for pieces that can carry a small object (tables, desks,
    nightstands, sideboards, TV stands, low shelves):
    ``{"z": local height of the top surface, "center": [x, y], "half": [hx, hy]}``,
    the usable rectangle of the top surface.

Small objects for the tops are table lamps and vases (made here) and the
books, boxes, plates and random blobs of the contact library
(:func:`phiscene.bench.assets.asset_library`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh

from phiscene.bench.assets import COLORS, WOOD, Asset, asset_library
from phiscene.bench.cleanmesh import canonical

#: Furniture kinds (categories) in the order the rooms library cycles through them; small objects
#: (``lamp``, ``vase``) are interleaved so every kind appears once ``n >= len(FURNITURE_CYCLE)``.
FURNITURE_CYCLE = ("bed", "nightstand", "wardrobe", "dining_table", "chair", "sofa", "coffee_table", "tv_stand",
                   "bookcase", "desk", "sideboard", "lamp", "chair", "shelf", "nightstand", "vase")

#: Categories of the contact library used as small objects on furniture tops.
CONTACT_SMALL = ("book", "box", "plate", "blob")

#: Categories that go on top of furniture.
TOP_CATEGORIES = ("lamp", "vase", *CONTACT_SMALL)

#: Overlap (m) of touching parts, so that their union is one solid piece.
JOIN = 0.005

#: Painted finishes (name -> RGB 0-255) for furniture that is not wooden.
PAINT = {"white": COLORS["white"], "grey": COLORS["grey"], "black": COLORS["black"]}

#: Upholstery colours of sofas and beds' mattresses.
FABRIC = {name: COLORS[name] for name in ("grey", "beige", "blue", "green", "teal", "red")}


#: Facets of cylinder parts (lamps, vases).
CYLINDER_SECTIONS = 32


@dataclass(frozen=True)
class Part:
    """One solid part of a piece of furniture, in the piece's frame (floor z = 0).

    Attributes
    ----------
    shape
        ``box`` or ``cylinder`` (upright).
    size : (3,) float
        Box extents (m); for a cylinder ``(radius, radius, height)``.
    center : (3,) float
        Centre of the part (m).
    """

    shape: str
    size: tuple[float, float, float]
    center: tuple[float, float, float]

    @property
    def bounds(self) -> np.ndarray:
        """AABB (2, 3) of the part."""
        half = np.array(self.size, dtype=float) / 2
        if self.shape == "cylinder":
            half = np.array([self.size[0], self.size[1], self.size[2] / 2])
        c = np.asarray(self.center, dtype=float)
        return np.array([c - half, c + half])

    def mesh(self) -> trimesh.Trimesh:
        """The part's closed mesh."""
        if self.shape == "box":
            m = trimesh.creation.box(extents=self.size)
        elif self.shape == "cylinder":
            m = trimesh.creation.cylinder(radius=self.size[0], height=self.size[2], sections=CYLINDER_SECTIONS)
        else:
            raise ValueError(f"unknown part shape {self.shape!r}")
        return m.apply_translation(self.center)

    def to_list(self) -> list:
        return [self.shape, [float(v) for v in self.size], [float(v) for v in self.center]]


def box(size, center) -> Part:
    """A box part of extents ``size`` (3,) centred at ``center`` (3,), rounded to 0.1 mm."""
    return Part("box", tuple(round(float(v), 4) for v in size), tuple(round(float(v), 4) for v in center))


def slab(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> Part:
    """A box part spanning ``[x0, x1] x [y0, y1] x [z0, z1]``."""
    return box((x1 - x0, y1 - y0, z1 - z0), ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


def cylinder(radius: float, z0: float, z1: float) -> Part:
    """An upright cylinder part on the z axis spanning ``[z0, z1]``."""
    r = round(float(radius), 4)
    return Part("cylinder", (r, r, round(z1 - z0, 4)), (0.0, 0.0, round((z0 + z1) / 2, 4)))


def union_parts(parts: list[Part]) -> trimesh.Trimesh:
    """One watertight mesh: the exact boolean union (manifold3d) of the parts."""
    meshes = [p.mesh() for p in parts]
    if len(meshes) == 1:
        return meshes[0]
    return trimesh.boolean.union(meshes, engine="manifold")


def parts_bounds(parts: list[Part]) -> np.ndarray:
    """AABB (2, 3) of a list of parts."""
    b = np.array([p.bounds for p in parts])
    return np.array([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])


def legs(width: float, depth: float, height: float, side: float, inset: float) -> list[Part]:
    """Four square legs of cross-section ``side`` from the floor to ``height``, ``inset`` from the edges."""
    out = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx = sx * (width / 2 - inset - side / 2)
            cy = sy * (depth / 2 - inset - side / 2)
            out.append(box((side, side, height), (cx, cy, height / 2)))
    return out


@dataclass(frozen=True)
class Design:
    """A piece of furniture before it is built: its parts, caption, colour and carrying surface.

    Attributes
    ----------
    parts
        Solid parts (piece frame, floor z = 0).
    description
        Caption ("wooden double bed 2.0 m").
    rgb
        Base colour (0-255).
    top
        Index into ``parts`` of the part whose upper face can carry a small object, or ``None``.
    """

    parts: list[Part]
    description: str
    rgb: tuple[int, int, int]
    top: int | None = None


def _pick(rng: np.random.Generator, table: dict) -> tuple[str, tuple[int, int, int]]:
    names = sorted(table)
    name = names[int(rng.integers(len(names)))]
    return name, table[name]


def _material(rng: np.random.Generator) -> tuple[str, tuple[int, int, int]]:
    """A wood tone or a paint, half and half."""
    return _pick(rng, WOOD if rng.random() < 0.5 else PAINT)


def length_text(v: float) -> str:
    """``2.0 m`` from 1 m up, else ``45 cm``."""
    return f"{v:.1f} m" if v >= 1.0 else f"{int(round(100 * v))} cm"


# -- designs --------------------------------------------------------------------------------------------------
def bed(rng: np.random.Generator) -> Design:
    """Frame + mattress + headboard (at +y); single or double."""
    u = rng.uniform
    double = bool(rng.random() < 0.7)
    W = u(1.4, 1.8) if double else u(0.9, 1.0)
    L, frame_h, mattress_h = u(2.0, 2.1), u(0.25, 0.35), u(0.18, 0.25)
    head_t, head_h = u(0.05, 0.08), u(0.9, 1.15)
    y_head = L / 2 - head_t
    parts = [slab(-W / 2, W / 2, -L / 2, y_head + JOIN, 0.0, frame_h),
             slab(-W / 2 + 0.02, W / 2 - 0.02, -L / 2 + 0.02, y_head + JOIN, frame_h - JOIN, frame_h + mattress_h),
             slab(-W / 2, W / 2, y_head, L / 2, 0.0, head_h)]
    name, rgb = _pick(rng, WOOD)
    return Design(parts, f"{name} {'double' if double else 'single'} bed {length_text(L)}", rgb)


def table(rng: np.random.Generator, coffee: bool = False) -> Design:
    """Top + four legs: a dining table, or a low coffee table."""
    u = rng.uniform
    if coffee:
        W, D, H = u(0.9, 1.2), u(0.5, 0.65), u(0.40, 0.48)
    else:
        W, D, H = u(1.2, 1.8), u(0.75, 1.0), u(0.72, 0.78)
    t, leg, inset = u(0.03, 0.05), u(0.05, 0.07), u(0.03, 0.08)
    parts = [slab(-W / 2, W / 2, -D / 2, D / 2, H - t, H), *legs(W, D, H - t + JOIN, leg, inset)]
    name, rgb = _material(rng)
    label = "coffee table" if coffee else "dining table"
    return Design(parts, f"{name} {label} {length_text(W)}", rgb, top=0)


def desk(rng: np.random.Generator) -> Design:
    """Top on a drawer pedestal at one end and two legs at the other, or on four legs with a back panel."""
    u = rng.uniform
    W, D, H, t = u(1.2, 1.6), u(0.6, 0.75), u(0.73, 0.77), u(0.025, 0.04)
    leg = u(0.04, 0.06)
    parts = [slab(-W / 2, W / 2, -D / 2, D / 2, H - t, H)]
    if rng.random() < 0.5:
        ped = u(0.38, 0.45)
        parts.append(slab(W / 2 - ped, W / 2 - 0.01, -D / 2 + 0.02, D / 2 - 0.02, 0.0, H - t + JOIN))
        for sy in (-1, 1):
            cy = sy * (D / 2 - 0.03 - leg / 2)
            parts.append(box((leg, leg, H - t + JOIN), (-W / 2 + 0.03 + leg / 2, cy, (H - t + JOIN) / 2)))
    else:
        parts += legs(W, D, H - t + JOIN, leg, 0.03)
        parts.append(slab(-W / 2 + 0.03 + leg - JOIN, W / 2 - 0.03 - leg + JOIN, D / 2 - 0.03 - leg,
                          D / 2 - 0.03 - leg + 0.02, H - t - u(0.3, 0.4), H - t + JOIN))
    name, rgb = _material(rng)
    return Design(parts, f"{name} desk {length_text(W)}", rgb, top=0)


def chair(rng: np.random.Generator) -> Design:
    """Seat on four legs with a back (at +y)."""
    u = rng.uniform
    W, D, seat_h, t = u(0.42, 0.48), u(0.42, 0.48), u(0.44, 0.48), u(0.04, 0.05)
    leg, back_t, top = u(0.03, 0.04), u(0.03, 0.04), u(0.82, 0.95)
    parts = [slab(-W / 2, W / 2, -D / 2, D / 2, seat_h - t, seat_h), *legs(W, D, seat_h - t + JOIN, leg, 0.0),
             slab(-W / 2, W / 2, D / 2 - back_t, D / 2, seat_h - JOIN, top)]
    name, rgb = _material(rng)
    return Design(parts, f"{name} chair {length_text(top)}", rgb)


def sofa(rng: np.random.Generator) -> Design:
    """Seat base + back (at +y) + two arms."""
    u = rng.uniform
    W, D, seat_h = u(1.6, 2.3), u(0.8, 0.95), u(0.40, 0.45)
    back_t, back_h, arm_w, arm_h = u(0.18, 0.25), u(0.75, 0.9), u(0.12, 0.2), u(0.55, 0.65)
    parts = [slab(-W / 2 + arm_w - JOIN, W / 2 - arm_w + JOIN, -D / 2, D / 2 - back_t + JOIN, 0.0, seat_h),
             slab(-W / 2, W / 2, D / 2 - back_t, D / 2, 0.0, back_h)]
    for sx in (-1, 1):
        x0, x1 = sorted((sx * W / 2, sx * (W / 2 - arm_w)))
        parts.append(slab(x0, x1, -D / 2, D / 2 - back_t + JOIN, 0.0, arm_h))
    name, rgb = _pick(rng, FABRIC)
    return Design(parts, f"{name} fabric sofa {length_text(W)}", rgb)


def case(rng: np.random.Generator, tall: bool) -> Design:
    """Bookcase (tall) or low shelf: two sides and 3-6 boards, open front and back.

    Sides are 4-5 cm and boards 3.5-4.5 cm thick, 35-45 cm apart, 0.8-1.2 m wide: thinner boards,
    narrower cases or a back panel make CoACD (threshold 0.08) slow (up to 30 s) and let its hulls
    fill the compartments (hull volume up to 4x the mesh's); with these, 52 draws took <= 2.9 s and
    <= 1.26x the volume.
    """
    u = rng.uniform
    W = u(0.8, 1.2)
    D, H = (u(0.28, 0.36), u(1.5, 2.0)) if tall else (u(0.3, 0.4), u(0.7, 1.0))
    side, board = u(0.04, 0.05), u(0.035, 0.045)
    n_boards = max(3, int(round(H / u(0.35, 0.45))) + 1)
    parts = [slab(-W / 2, -W / 2 + side, -D / 2, D / 2, 0.0, H), slab(W / 2 - side, W / 2, -D / 2, D / 2, 0.0, H)]
    for z in np.linspace(0.0, H - board, n_boards):
        parts.append(slab(-W / 2 + side - JOIN, W / 2 - side + JOIN, -D / 2, D / 2, z, z + board))
    name, rgb = _material(rng)
    label = "bookcase" if tall else "shelf"
    # the top board spans between the sides; its top is the piece's top
    return Design(parts, f"{name} {label} {length_text(H if tall else W)}", rgb, top=None if tall else len(parts) - 1)


def cabinet(rng: np.random.Generator, kind: str) -> Design:
    """A closed box on a recessed plinth: ``wardrobe``, ``sideboard``, ``nightstand`` or ``tv_stand``."""
    u = rng.uniform
    dims = {"wardrobe": ((0.8, 1.5), (0.55, 0.62), (1.8, 2.1)), "sideboard": ((0.9, 1.5), (0.4, 0.5), (0.75, 0.9)),
            "nightstand": ((0.4, 0.55), (0.35, 0.45), (0.45, 0.6)), "tv_stand": ((1.2, 1.8), (0.35, 0.45), (0.4, 0.55))}
    (w0, w1), (d0, d1), (h0, h1) = dims[kind]
    W, D, H = u(w0, w1), u(d0, d1), u(h0, h1)
    plinth_h, inset = u(0.06, 0.1), u(0.03, 0.05)
    parts = [slab(-W / 2, W / 2, -D / 2, D / 2, plinth_h - JOIN, H),
             slab(-W / 2 + inset, W / 2 - inset, -D / 2 + inset, D / 2 - inset, 0.0, plinth_h)]
    name, rgb = _material(rng)
    label = {"tv_stand": "TV stand"}.get(kind, kind)
    size = H if kind == "wardrobe" else W
    return Design(parts, f"{name} {label} {length_text(size)}", rgb, top=None if kind == "wardrobe" else 0)


def lamp(rng: np.random.Generator) -> Design:
    """Table lamp: round base, thin stem, cylindrical shade."""
    u = rng.uniform
    base_r, base_h = u(0.07, 0.09), u(0.02, 0.03)
    stem_r, stem_h = u(0.01, 0.015), u(0.15, 0.25)
    shade_r, shade_h = u(0.09, 0.13), u(0.14, 0.2)
    top = base_h + stem_h + shade_h
    parts = [cylinder(base_r, 0.0, base_h), cylinder(stem_r, base_h - JOIN, base_h + stem_h + JOIN),
             cylinder(shade_r, base_h + stem_h, top)]
    name, rgb = _pick(rng, {k: COLORS[k] for k in ("white", "beige", "yellow", "black")})
    return Design(parts, f"{name} table lamp {length_text(top)}", rgb)


def vase(rng: np.random.Generator) -> Design:
    """A cylindrical vase."""
    r, h = rng.uniform(0.05, 0.08), rng.uniform(0.18, 0.3)
    name, rgb = _pick(rng, {k: COLORS[k] for k in ("white", "blue", "teal", "green", "orange")})
    return Design([cylinder(r, 0.0, h)], f"{name} vase {length_text(h)}", rgb)


#: Design function of each furniture category.
DESIGNS = {
    "bed": bed, "dining_table": table, "coffee_table": lambda rng: table(rng, coffee=True), "desk": desk,
    "chair": chair, "sofa": sofa, "bookcase": lambda rng: case(rng, tall=True),
    "shelf": lambda rng: case(rng, tall=False), "wardrobe": lambda rng: cabinet(rng, "wardrobe"),
    "sideboard": lambda rng: cabinet(rng, "sideboard"), "nightstand": lambda rng: cabinet(rng, "nightstand"),
    "tv_stand": lambda rng: cabinet(rng, "tv_stand"), "lamp": lamp, "vase": vase,
}


def design_meta(design: Design) -> dict:
    """``size`` and ``top`` (see the module docstring) in the canonical frame (bounding box centred at 0)."""
    lo, hi = parts_bounds(design.parts)
    centre = (lo + hi) / 2
    meta = {"size": [float(v) for v in hi - lo]}
    if design.top is not None:
        tlo, thi = design.parts[design.top].bounds
        middle = (tlo[:2] + thi[:2]) / 2 - centre[:2]
        meta["top"] = {"z": float(thi[2] - centre[2]), "center": [float(v) for v in middle],
                       "half": [float(v) for v in (thi[:2] - tlo[:2]) / 2]}
    return meta


def furniture_asset(category: str, name: str, rng: np.random.Generator) -> Asset:
    """An asset of a furniture (or lamp/vase) ``category`` with dimensions and finish drawn from ``rng``."""
    if category not in DESIGNS:
        raise ValueError(f"unknown furniture category {category!r}; known: {sorted(DESIGNS)}")
    design = DESIGNS[category](rng)
    recipe = {"furniture": category, "parts": [p.to_list() for p in design.parts]}
    return Asset(name, design.description, category, design.rgb,
                 lambda: canonical(union_parts(design.parts), name=name), design_meta(design), recipe)


@lru_cache(maxsize=8)
def rooms_library(seed: int, n: int, cache_dir: Path | None = None) -> tuple[Asset, ...]:
    """The deterministic asset library of the ``rooms`` suite.

    ``n`` furniture assets (asset ``i`` of category ``FURNITURE_CYCLE[i % 16]``, drawn from
    ``default_rng([seed, 2_000_003, i])``) followed by the small objects of the contact
    library of the same seed and size (:data:`CONTACT_SMALL` categories of
    :func:`~phiscene.bench.assets.asset_library`). Meshes are built lazily, and cached
    under ``cache_dir`` when given.

    Parameters
    ----------
    seed
        Library seed.
    n
        Number of furniture assets (>= 1; >= 16 holds every kind).
    cache_dir
        Folder for built meshes, or ``None``.

    Returns
    -------
    tuple of :class:`~phiscene.bench.assets.Asset`
    """
    if n < 1:
        raise ValueError(f"rooms library size must be >= 1, got {n}")
    counts: dict[str, int] = {}
    out = []
    for i in range(n):
        cat = FURNITURE_CYCLE[i % len(FURNITURE_CYCLE)]
        k = counts.get(cat, 0)
        counts[cat] = k + 1
        asset = furniture_asset(cat, f"{cat}_{k + 1:02d}", np.random.default_rng([seed, 2_000_003, i]))
        asset.cache_dir = None if cache_dir is None else Path(cache_dir)
        out.append(asset)
    small = [a for a in asset_library(seed, max(n, 16), cache_dir) if a.category in CONTACT_SMALL]
    return tuple(out + small)
