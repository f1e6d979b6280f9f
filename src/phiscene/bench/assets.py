"""The benchmark's asset library: procedural primitives and meshes shipped with ``pybullet_data``.

An :class:`Asset` is a named, described, categorised watertight mesh in a
canonical local frame: metres, z up, origin at the centre of its bounding box.
The library is a deterministic function of a seed and a size
(:func:`asset_library`); scenes draw their objects from it, so the same few
meshes recur across scenes and their collision proxies (cached by mesh
content) are computed once per asset.

Categories (what the scene templates ask for):

``box``, ``book``
    Flat-topped blocks that can carry other objects.
``plank``
    Long thin boards (bridges, leaning boards).
``plate``, ``can``
    Thin and upright cylinders.
``tray``, ``crate``
    Open-top containers (base + four walls, one watertight union); their
    ``meta`` holds ``inner`` (x, y interior size, m) and ``floor`` (local z of
    the inside floor).
``wall``
    A tall, thick, heavy panel to lean things against.
``blob``
    ``pybullet_data/random_urdfs`` shapes at the size their URDF gives.
``prop``, ``ball``
    ``pybullet_data`` models (duck, teddy, torus, mug, bunny; balls).
"""

from __future__ import annotations

import colorsys
import hashlib
import json
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import trimesh

from phiscene.bench.cleanmesh import MAX_FACES, canonical, resting_transform
from phiscene.errors import InputError

#: Bump when asset geometry changes (part of every cache key that depends on assets).
ASSET_VERSION = 2

#: Named colours for descriptions and the reference render, RGB 0-255.
COLORS: dict[str, tuple[int, int, int]] = {
    "red": (200, 40, 40), "orange": (230, 130, 30), "yellow": (230, 200, 40), "green": (60, 160, 70),
    "teal": (40, 150, 150), "blue": (50, 90, 200), "purple": (130, 70, 170), "pink": (220, 120, 170),
    "brown": (130, 85, 50), "white": (235, 235, 230), "grey": (140, 140, 140), "black": (40, 40, 40),
    "beige": (215, 195, 150),
}

#: Wood tones for planks, trays and crates.
WOOD = {"light wooden": (200, 160, 110), "wooden": (160, 115, 70), "dark wooden": (110, 75, 45)}

#: Asset categories in the order the library cycles through them (every category appears once n >= 16).
CATEGORY_CYCLE = ("box", "plank", "tray", "blob", "book", "wall", "can", "prop",
                  "plate", "crate", "box", "blob", "plank", "book", "prop", "ball")


@dataclass
class Asset:
    """One reusable object model.

    Attributes
    ----------
    name
        Unique within a library, e.g. ``plank_01`` or ``blob_03``.
    description
        Short text as a 3D foundation model would caption it ("wooden plank 40 cm").
    category
        See the module docstring.
    rgb
        Base colour (0-255) of the reference render.
    build
        Zero-argument function returning the local-frame mesh (called once, lazily); it may
        update ``description``, ``rgb`` and ``meta`` (a blob slot falls back to another blob).
    meta
        Extra geometry facts (containers: ``inner``, ``floor``; sources: ``source``).
    recipe
        JSON-able description of how the mesh is built; with :data:`ASSET_VERSION` it keys the disk cache.
    cache_dir
        Folder holding built meshes (``<cache_dir>/assets/<key>.glb`` + ``.json``), or ``None``.
    """

    name: str
    description: str
    category: str
    rgb: tuple[int, int, int]
    build: Callable[[], trimesh.Trimesh] = field(repr=False)
    meta: dict = field(default_factory=dict)
    recipe: dict = field(default_factory=dict)
    cache_dir: Path | None = None

    @property
    def key(self) -> str:
        """Content key of the build recipe (20 hex digits)."""
        text = json.dumps({"version": ASSET_VERSION, "max_faces": MAX_FACES, "recipe": self.recipe}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:20]

    @cached_property
    def mesh(self) -> trimesh.Trimesh:
        """The canonical, closed local-frame mesh (built or read from the cache on first use; do not modify)."""
        if self.cache_dir is not None:
            cached = self._read_cache()
            if cached is not None:
                return cached
        mesh = self.build()
        if self.cache_dir is not None:
            self._write_cache(mesh)
        return mesh

    @property
    def extents(self) -> np.ndarray:
        """Bounding box size (3,) in metres."""
        return np.asarray(self.mesh.extents, dtype=float)

    def _cache_paths(self) -> tuple[Path, Path]:
        stem = Path(self.cache_dir) / "assets" / self.key
        return stem.with_suffix(".glb"), stem.with_suffix(".json")

    def _read_cache(self) -> trimesh.Trimesh | None:
        glb, info = self._cache_paths()
        if not (glb.is_file() and info.is_file()):
            return None
        try:
            data = json.loads(info.read_text())
            mesh = trimesh.load(glb, force="mesh", process=False)
        except Exception:  # a damaged entry is rebuilt
            return None
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) != data.get("faces"):
            return None
        self.description, self.rgb, self.meta = data["description"], tuple(data["rgb"]), data["meta"]
        return trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), process=False)

    def _write_cache(self, mesh: trimesh.Trimesh) -> None:
        from phiscene.atomic import write_json
        from phiscene.meshes import save_mesh

        glb, info = self._cache_paths()
        save_mesh(mesh, glb)
        write_json(info, {"name": self.name, "description": self.description, "rgb": list(self.rgb),
                          "meta": self.meta, "faces": len(mesh.faces), "recipe": self.recipe})


# -- procedural primitives -------------------------------------------------------------------------------
def box_mesh(size) -> trimesh.Trimesh:
    """Axis-aligned box centred at the origin; ``size`` (3,) in metres."""
    return trimesh.creation.box(extents=np.asarray(size, dtype=float))


def cylinder_mesh(radius: float, height: float, sections: int = 32) -> trimesh.Trimesh:
    """Upright (z) cylinder centred at the origin."""
    return trimesh.creation.cylinder(radius=radius, height=height, sections=sections)


def open_box_mesh(outer, wall: float, base: float) -> trimesh.Trimesh:
    """Open-top container: a base slab and four walls, unioned into one watertight mesh.

    Parameters
    ----------
    outer : (3,) float
        Outer size x, y, z (m).
    wall
        Wall thickness (m).
    base
        Base thickness (m).
    """
    x, y, z = (float(v) for v in outer)
    parts = [box_mesh((x, y, base)).apply_translation((0, 0, base / 2))]
    for sx in (-1, 1):
        parts.append(box_mesh((wall, y, z)).apply_translation((sx * (x - wall) / 2, 0, z / 2)))
    for sy in (-1, 1):
        parts.append(box_mesh((x, wall, z)).apply_translation((0, sy * (y - wall) / 2, z / 2)))
    return trimesh.boolean.union(parts, engine="manifold")


def _cm(v: float) -> int:
    return int(round(100 * v))


def _pick_color(rng: np.random.Generator, table: dict) -> tuple[str, tuple[int, int, int]]:
    names = sorted(table)
    name = names[int(rng.integers(len(names)))]
    return name, table[name]


def _primitive(category: str, name: str, rng: np.random.Generator) -> Asset:
    """A procedural asset of ``category`` with dimensions drawn from ``rng``."""
    u = rng.uniform
    if category == "box":
        size = np.round([u(0.10, 0.26), u(0.10, 0.22), u(0.07, 0.20)], 3)
        cname, rgb = _pick_color(rng, {"brown": COLORS["brown"], "beige": COLORS["beige"], "white": COLORS["white"]})
        desc = f"{cname} cardboard box {_cm(size[0])}x{_cm(size[1])}x{_cm(size[2])} cm"
        return Asset(name, desc, category, rgb, lambda: canonical(box_mesh(size), name=name), {"size": size.tolist()},
                     {"box": size.tolist()})
    if category == "book":
        size = np.round([u(0.15, 0.26), u(0.11, 0.18), u(0.02, 0.05)], 3)
        cname, rgb = _pick_color(rng, COLORS)
        desc = f"{cname} book {_cm(size[0])} cm"
        return Asset(name, desc, category, rgb, lambda: canonical(box_mesh(size), name=name), {"size": size.tolist()},
                     {"box": size.tolist()})
    if category == "plank":
        size = np.round([u(0.32, 0.60), u(0.06, 0.12), u(0.015, 0.025)], 3)
        cname, rgb = _pick_color(rng, WOOD)
        desc = f"{cname} plank {_cm(size[0])} cm"
        return Asset(name, desc, category, rgb, lambda: canonical(box_mesh(size), name=name), {"size": size.tolist()},
                     {"box": size.tolist()})
    if category == "wall":
        size = np.round([u(0.45, 0.70), u(0.07, 0.10), u(0.32, 0.45)], 3)
        desc = f"grey wall panel {_cm(size[0])} cm"
        return Asset(name, desc, category, COLORS["grey"], lambda: canonical(box_mesh(size), name=name),
                     {"size": size.tolist()}, {"box": size.tolist()})
    if category == "plate":
        r, h = round(u(0.07, 0.13), 3), round(u(0.012, 0.02), 3)
        cname, rgb = _pick_color(rng, {"white": COLORS["white"], "blue": COLORS["blue"], "beige": COLORS["beige"]})
        desc = f"{cname} plate {_cm(2 * r)} cm"
        return Asset(name, desc, category, rgb, lambda: canonical(cylinder_mesh(r, h, 40), name=name),
                     {"radius": r, "height": h}, {"cylinder": [r, h, 40]})
    if category == "can":
        r, h = round(u(0.03, 0.045), 3), round(u(0.08, 0.15), 3)
        cname, rgb = _pick_color(rng, COLORS)
        desc = f"{cname} can {_cm(h)} cm"
        return Asset(name, desc, category, rgb, lambda: canonical(cylinder_mesh(r, h, 24), name=name),
                     {"radius": r, "height": h}, {"cylinder": [r, h, 24]})
    if category in ("tray", "crate"):
        if category == "tray":
            outer = np.round([u(0.26, 0.40), u(0.20, 0.30), u(0.035, 0.06)], 3)
            wall, base = 0.012, 0.012
        else:
            outer = np.round([u(0.26, 0.36), u(0.22, 0.30), u(0.10, 0.15)], 3)
            wall, base = 0.015, 0.015
        cname, rgb = _pick_color(rng, WOOD)
        desc = f"{cname} {category} {_cm(outer[0])} cm"
        meta = {"size": outer.tolist(), "inner": [float(outer[0] - 2 * wall), float(outer[1] - 2 * wall)],
                "floor": float(base - outer[2] / 2), "wall": wall}
        return Asset(name, desc, category, rgb, lambda: canonical(open_box_mesh(outer, wall, base), name=name), meta,
                     {"open_box": [*outer.tolist(), wall, base]})
    raise ValueError(f"unknown primitive category {category!r}")


# -- pybullet_data meshes ----------------------------------------------------------------------------------
def pybullet_data_dir() -> Path:
    """Folder of the ``pybullet_data`` package."""
    import pybullet_data

    return Path(pybullet_data.getDataPath())


@dataclass(frozen=True)
class PropSpec:
    """A ``pybullet_data`` model: file, metric size, up axis and caption.

    Attributes
    ----------
    file
        Path under ``pybullet_data``.
    size
        Longest bounding-box side after scaling (m).
    up
        Axis of the file that points up: ``x``, ``y`` or ``z`` (optionally ``-`` prefixed).
    description, category, color
        Caption, library category and colour name (key of :data:`COLORS`).
    max_faces
        Face budget (balls are kept coarse so that they come to rest on a facet).
    """

    file: str
    size: float
    up: str
    description: str
    category: str
    color: str
    max_faces: int = MAX_FACES


#: The pybullet_data props in library order.
PROPS: tuple[PropSpec, ...] = (
    PropSpec("duck.obj", 0.10, "z", "yellow rubber duck", "prop", "yellow"),
    PropSpec("teddy2_VHACD_CHs.obj", 0.18, "y", "brown teddy bear", "prop", "brown"),
    PropSpec("torus/torus_textured.obj", 0.16, "y", "orange rubber ring", "prop", "orange"),
    PropSpec("objects/mug.obj", 0.12, "z", "white mug", "prop", "white"),
    PropSpec("bunny.obj", 0.15, "z", "white ceramic bunny", "prop", "white"),
    PropSpec("soccerball.obj", 0.20, "z", "soccer ball", "ball", "white", 400),
    PropSpec("sphere_smooth.obj", 0.08, "z", "red ball", "ball", "red", 400),
    PropSpec("sphere_smooth.obj", 0.12, "z", "blue ball", "ball", "blue", 400),
)


def _up_rotation(up: str) -> np.ndarray:
    """4x4 rotation taking the file's ``up`` axis to +z."""
    sign = -1.0 if up.startswith("-") else 1.0
    axis = {"x": [1.0, 0, 0], "y": [0, 1.0, 0], "z": [0, 0, 1.0]}[up.lstrip("-")]
    return trimesh.geometry.align_vectors(sign * np.asarray(axis), [0, 0, 1.0])


def load_prop(spec: PropSpec) -> trimesh.Trimesh:
    """Load a ``pybullet_data`` model upright and canonicalised.

    Its ``up`` axis is turned to z, it is scaled to ``spec.size``, then turned onto the
    statically stable pose nearest to that upright one (:func:`resting_transform`), so it
    stands still on flat ground.
    """
    path = pybullet_data_dir() / spec.file
    m = trimesh.load(path, force="mesh", process=False)
    m = trimesh.Trimesh(np.asarray(m.vertices, dtype=float), np.asarray(m.faces), process=True)
    m.apply_transform(_up_rotation(spec.up))
    m.apply_scale(spec.size / float(m.extents.max()))
    first = canonical(m, spec.max_faces, name=str(path))
    m.apply_transform(resting_transform(first, nearest=True))
    return canonical(m, spec.max_faces, name=str(path))


def urdf_mesh_scale(urdf: Path) -> tuple[str, np.ndarray, np.ndarray | None]:
    """Mesh file name, scale (3,) and rgba (4,) or None of the first ``<mesh>`` in a URDF."""
    text = urdf.read_text()
    mesh = re.search(r'<mesh\s+filename="([^"]+)"(?:\s+scale="([^"]+)")?', text)
    if mesh is None:
        raise InputError(urdf, "mesh", "no <mesh filename=...> element")
    scale = np.array([float(v) for v in mesh.group(2).split()]) if mesh.group(2) else np.ones(3)
    rgba = re.search(r'<color\s+rgba="([^"]+)"', text)
    color = np.array([float(v) for v in rgba.group(1).split()]) if rgba else None
    return mesh.group(1), scale, color


def nearest_color_name(rgb01) -> str:
    """Name (key of :data:`COLORS`) of the named colour nearest in hue/lightness to ``rgb01`` (3,) in [0, 1]."""
    h, light, s = colorsys.rgb_to_hls(*np.clip(np.asarray(rgb01[:3], dtype=float), 0, 1))
    if s < 0.25 or light < 0.12 or light > 0.9:
        return "black" if light < 0.25 else ("white" if light > 0.75 else "grey")
    best, best_d = "grey", np.inf
    for name, c in COLORS.items():
        if name in ("white", "grey", "black", "beige"):
            continue
        hc, lc, _ = colorsys.rgb_to_hls(*(np.asarray(c) / 255.0))
        dh = min(abs(h - hc), 1 - abs(h - hc))
        d = dh + 0.3 * abs(light - lc)
        if d < best_d:
            best, best_d = name, d
    return best


def blob_mesh(index: int) -> trimesh.Trimesh:
    """``random_urdfs/<index>`` at its URDF scale, on its most stable face, canonicalised."""
    folder = pybullet_data_dir() / "random_urdfs" / f"{index:03d}"
    mesh_file, scale, _ = urdf_mesh_scale(folder / f"{index:03d}.urdf")
    m = trimesh.load(folder / mesh_file, force="mesh", process=False)
    m = trimesh.Trimesh(np.asarray(m.vertices, dtype=float) * scale, np.asarray(m.faces), process=True)
    m.apply_transform(resting_transform(m.convex_hull))
    return canonical(m, name=str(folder / mesh_file))


def _blob_identity(index: int) -> tuple[str, tuple[int, int, int], dict]:
    _, _, rgba = urdf_mesh_scale(pybullet_data_dir() / "random_urdfs" / f"{index:03d}" / f"{index:03d}.urdf")
    cname = nearest_color_name(rgba) if rgba is not None else "grey"
    rgb = tuple(int(round(255 * c)) for c in rgba[:3]) if rgba is not None else COLORS["grey"]
    return f"{cname} random blob", rgb, {"source": f"random_urdfs/{index:03d}"}


def _blob_slot(candidates: list[int], name: str) -> Asset:
    """A blob asset: the first of ``candidates`` whose mesh can be made clean (most can)."""
    description, rgb, meta = _blob_identity(candidates[0])
    asset = Asset(name, description, "blob", rgb, lambda: None, meta, {"blob_candidates": candidates})

    def build() -> trimesh.Trimesh:
        problems = []
        for index in candidates:
            try:
                mesh = blob_mesh(index)
            except InputError as exc:
                problems.append(exc.problem)
                continue
            asset.description, asset.rgb, asset.meta = _blob_identity(index)
            return mesh
        raise InputError(name, None, f"no usable blob among {candidates}: {problems}")

    asset.build = build
    return asset


def _prop(spec: PropSpec, name: str) -> Asset:
    return Asset(name, f"{spec.description} {_cm(spec.size)} cm", spec.category, COLORS[spec.color],
                 lambda: load_prop(spec), {"source": spec.file}, {"prop": asdict(spec)})


# -- the library --------------------------------------------------------------------------------------------
#: Blob slot ``k`` tries blobs ``perm[k], perm[k + BLOB_STRIDE], ...`` (distinct slots never share a blob).
BLOB_STRIDE = 200


@lru_cache(maxsize=8)
def asset_library(seed: int, n: int, cache_dir: Path | None = None) -> tuple[Asset, ...]:
    """The deterministic asset library of size ``n``.

    Asset ``i`` has category ``CATEGORY_CYCLE[i % 16]``; its dimensions, colour,
    blob or prop are drawn from ``default_rng([seed, i])`` and seeded
    permutations, so a library of size ``n`` is a prefix of one of size ``n + 1``.
    Meshes are built lazily on first use, and kept under ``cache_dir`` when given.

    Parameters
    ----------
    seed
        Library seed.
    n
        Number of assets (1 to 1600).
    cache_dir
        Folder for built meshes (shared between processes), or ``None``.

    Returns
    -------
    tuple of :class:`Asset`
    """
    if not 1 <= n <= len(CATEGORY_CYCLE) * BLOB_STRIDE // 2:
        raise ValueError(f"asset library size must be in [1, {len(CATEGORY_CYCLE) * BLOB_STRIDE // 2}], got {n}")
    order = np.random.default_rng([seed, 1_000_003])
    blobs = [int(b) for b in order.permutation(1000)]
    props = [PROPS[k] for k in order.permutation(len(PROPS))]
    balls = [p for p in props if p.category == "ball"]
    props = [p for p in props if p.category == "prop"]
    counts: dict[str, int] = {}
    out = []
    for i in range(n):
        cat = CATEGORY_CYCLE[i % len(CATEGORY_CYCLE)]
        k = counts.get(cat, 0)
        counts[cat] = k + 1
        if cat == "blob":
            out.append(_blob_slot(blobs[k::BLOB_STRIDE], f"blob_{k + 1:02d}"))
        elif cat in ("prop", "ball"):
            pool = props if cat == "prop" else balls
            spec = pool[k % len(pool)]
            stem = Path(spec.file).stem.split("_")[0]
            out.append(_prop(spec, f"{stem}_{_cm(spec.size)}cm"))
        else:
            out.append(_primitive(cat, f"{cat}_{k + 1:02d}", np.random.default_rng([seed, i])))
    seen: dict[str, int] = {}
    for a in out:  # props recur once n exceeds their number: keep names unique
        c = seen.get(a.name, 0)
        seen[a.name] = c + 1
        if c:
            a.name = f"{a.name}_{c + 1}"
        a.cache_dir = None if cache_dir is None else Path(cache_dir)
    return tuple(out)


def by_category(library, *categories: str) -> list[Asset]:
    """Assets of the library whose category is one of ``categories`` (library order)."""
    return [a for a in library if a.category in categories]
