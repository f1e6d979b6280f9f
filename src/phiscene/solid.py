"""The solid a reconstructed mesh stands for: the outer shell of a hollow, double-walled surface.

3D foundation models extract their meshes from a sparse voxel structure that holds only the voxels near the
surface, so a solid object often comes out as a closed *thin shell*: an outer surface, and an inner one a few
millimetres inside it facing a sealed cavity (a pear is a balloon with a 5 mm wall). Measured on the 117 SAM 3D
Objects meshes of the REST3D page assets (`benchmarks/hollow_shells.py`): the generalised winding number is 0 in
the cavity, so every inside test, signed distance, penetration depth, decomposition and mass of such an object
sees the wall only, and an object pushed deep into a pear is not inside it.

:func:`outer_shell` drops the faces that face a sealed cavity. The mesh's surface is rasterised onto a voxel grid
(``resolution`` voxels along the longest axis, every face sampled on a barycentric lattice finer than half a
voxel, so the grid is the same for the same mesh), the surface voxels are closed morphologically (openings
narrower than ``seal`` of the longest axis are sealed: the walls of a reconstructed pear meet around a hole of
1-3 cm), the exterior is flood-filled from the grid's border, and a connected region of voxels neither reached
nor on the surface is *enclosed* when the surface alone encloses it, or when it reaches deeper than the closing
radius from the surface (a cavity behind a small opening, not a crevice the closing bridged). A face is inner
when the point ``probe`` voxels in front of it lies in an enclosed region whose winding number is below
``TOL.winding_inside`` (the cavity of a double wall, not the body of a solid, where the number is 1, nor the
overlap of two solids, where it is 2; read exactly at the region's deepest voxels). What remains is the outer
surface: its winding number is about 1 in the whole body (the lip where an inner wall met the outer one is a
small hole the winding number tolerates), and the distance to it is the depth below the object's real surface.

A mesh with no enclosed voxel (every solid or open model: boxes, bowls, chairs, containers whose cavity is open
to the outside) is returned unchanged, as is one whose outer faces would be fewer than ``min_outer`` of all
(an inward-oriented mesh, whose every face looks into its own body).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from phiscene.memo import Memo
from phiscene.params import Params
from phiscene.tolerances import TOL

#: Fewest voxels of an enclosed region (smaller pockets, in a wall or between two, change no inside test).
MIN_REGION = 8
#: Voxels per enclosed region at which its winding number is read (the deepest; the median decides).
PROBES_PER_REGION = 4


@dataclass(frozen=True)
class ShellParams(Params):
    """Parameters of :func:`outer_shell` (lengths in voxels).

    Attributes
    ----------
    resolution
        Voxels along the mesh's longest bounding-box axis.
    seal
        Widest opening sealed, as a share of the longest axis: the surface voxels are dilated ``r = ceil(seal
        resolution / 2)`` times before the exterior flood fill and the fill is eroded back, so openings up to
        ``2 r`` voxels wide do not let the exterior in (a jug's neck is sealed, a bowl or a crate stays open).
    probe
        Distances in front of a face (voxels) at which its side is looked up; the first that lands off the
        surface voxels decides.
    min_outer
        Smallest share of outer faces for the mesh to be trimmed at all.
    """

    _label = "shell parameters"

    resolution: int = 64
    seal: float = 0.1
    probe: tuple = (1.0, 1.5, 2.0, 3.0)
    min_outer: float = 0.1

    def digest(self) -> str:
        """Hash of the parameters (cache keys)."""
        import hashlib
        import json
        from dataclasses import asdict

        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:12]

    def check(self) -> None:
        """Reject a grid too coarse to hold a cavity or a negative radius (``ValueError``)."""
        if self.resolution < 8 or not 0.0 <= self.seal < 0.5 or not self.probe or min(self.probe) <= 0:
            raise ValueError(f"shell parameters need resolution >= 8, seal in [0, 0.5), positive probes: {self}")

    @property
    def close(self) -> int:
        """Closing radius in voxels."""
        return int(np.ceil(self.seal * self.resolution / 2.0))


@dataclass
class VoxelShell:
    """The voxel classification behind :func:`outer_shell`.

    Attributes
    ----------
    origin : (3,) float
        Corner of voxel ``(0, 0, 0)``.
    pitch : float
        Voxel edge length.
    surface, enclosed : (nx, ny, nz) bool
        Voxels the surface passes through; voxels neither on the surface nor reachable from outside.
    regions : (nx, ny, nz) int
        Label of the enclosed region each enclosed voxel belongs to (1, 2, ...; 0 elsewhere).
    deepest : (k, 3) float
        Centres of each region's voxels farthest from the surface (at most ``PROBES_PER_REGION`` per region).
    deepest_region : (k,) int
        The region label of each of them.
    """

    origin: np.ndarray
    pitch: float
    surface: np.ndarray
    enclosed: np.ndarray
    regions: np.ndarray
    deepest: np.ndarray
    deepest_region: np.ndarray

    def index(self, points: np.ndarray) -> np.ndarray:
        """Voxel indices (n, 3) int of points (n, 3), clipped to the grid."""
        idx = np.floor((np.asarray(points, dtype=float) - self.origin) / self.pitch).astype(np.int64)
        return np.clip(idx, 0, np.asarray(self.surface.shape) - 1)


def lattice_points(triangles: np.ndarray, spacing: float, max_steps: int = 256) -> np.ndarray:
    """Points on every triangle, on a barycentric lattice whose steps are at most ``spacing`` long.

    Deterministic (no random sampling), so a mesh always rasterises to the same voxels.

    Parameters
    ----------
    triangles : (m, 3, 3) float
    spacing
        Longest lattice step along an edge.
    max_steps
        Cap on the subdivisions of one edge.

    Returns
    -------
    points : (p, 3) float
        Includes every corner.
    """
    tri = np.asarray(triangles, dtype=float)
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    steps = np.clip(np.ceil(edges / spacing).astype(np.int64), 1, max_steps)
    out = [tri.reshape(-1, 3)]
    for n in np.unique(steps):
        if n == 1:
            continue
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        a, b = i[keep] / n, j[keep] / n  # (q,)
        sel = tri[steps == n]  # (k, 3, 3)
        pts = (sel[:, None, 0] + a[None, :, None] * (sel[:, None, 1] - sel[:, None, 0])
               + b[None, :, None] * (sel[:, None, 2] - sel[:, None, 0]))
        out.append(pts.reshape(-1, 3))
    return np.concatenate(out)


def voxel_shell(mesh: trimesh.Trimesh, params: ShellParams = ShellParams()) -> VoxelShell:
    """Rasterise ``mesh`` and classify its voxels into surface, exterior and enclosed (see the module text)."""
    from scipy import ndimage

    lo, hi = np.asarray(mesh.bounds, dtype=float)
    pitch = float((hi - lo).max()) / params.resolution
    pad = params.close + int(np.ceil(max(params.probe))) + 2
    origin = lo - pad * pitch
    shape = tuple(int(n) for n in np.ceil((hi - lo) / pitch).astype(np.int64) + 2 * pad + 1)
    idx = np.floor((lattice_points(mesh.triangles, 0.5 * pitch) - origin) / pitch).astype(np.int64)
    surface = np.zeros(shape, dtype=bool)
    surface[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    cross = ndimage.generate_binary_structure(3, 1)
    sealed = ndimage.binary_dilation(surface, cross, iterations=params.close) if params.close else surface
    filled = ndimage.binary_fill_holes(sealed)
    if params.close:
        filled = ndimage.binary_erosion(filled, cross, iterations=params.close, border_value=0) | surface
    enclosed = filled & ~surface
    regions = np.zeros(shape, dtype=np.int32)
    deepest, deepest_region = np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    if enclosed.any():
        # a region enclosed by the surface itself is a cavity; one the closing enclosed must reach deeper than
        # the closing radius (a cavity behind a small opening, not a crevice the closing bridged)
        closed_by_surface = ndimage.binary_fill_holes(surface) & ~surface
        labels, n = ndimage.label(enclosed)
        dist = ndimage.distance_transform_edt(~surface)
        index = np.arange(1, n + 1)
        depth = np.asarray(ndimage.maximum(dist, labels, index=index))
        own = np.asarray(ndimage.maximum(closed_by_surface, labels, index=index)) > 0
        size = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        keep = np.zeros(n + 1, dtype=bool)
        keep[index[(own | (depth > params.close + 0.5)) & (size >= MIN_REGION)]] = True
        renumber = np.cumsum(keep) * keep  # kept labels -> 1, 2, ...
        regions = renumber[labels].astype(np.int32)
        cells = np.flatnonzero(regions)
        if len(cells):  # the (at most PROBES_PER_REGION) deepest voxels of each kept region
            order = np.lexsort((-dist.ravel()[cells], regions.ravel()[cells]))
            cells = cells[order]
            region_of = regions.ravel()[cells]
            first = np.searchsorted(region_of, np.arange(1, region_of.max() + 1))
            top = np.arange(len(cells)) - first[region_of - 1] < PROBES_PER_REGION
            deepest = origin + (np.stack(np.unravel_index(cells[top], shape), axis=1) + 0.5) * pitch
            deepest_region = region_of[top].astype(np.int64)
        enclosed = regions > 0
    return VoxelShell(origin=origin, pitch=pitch, surface=surface, enclosed=enclosed, regions=regions,
                      deepest=deepest, deepest_region=deepest_region)


def hollow_regions(mesh: trimesh.Trimesh, vox: VoxelShell) -> np.ndarray:
    """Which enclosed regions of ``vox`` are cavities of a double wall, (regions + 1,) bool (index 0: none).

    A cavity has winding number ~0 (the body of a solid 1, the overlap of two solids 2), read exactly
    (:func:`phiscene.sdf.winding_number_exact`, a few points against every triangle) at the region's deepest
    voxels; the median decides.
    """
    from phiscene.sdf import winding_number_exact

    hollow = np.zeros(int(vox.regions.max()) + 1, dtype=bool)
    if len(vox.deepest) == 0:
        return hollow
    w = winding_number_exact(np.asarray(mesh.triangles, dtype=float), vox.deepest)
    for r in np.unique(vox.deepest_region):
        hollow[r] = np.median(w[vox.deepest_region == r]) < TOL.winding_inside
    return hollow


def inner_faces(mesh: trimesh.Trimesh, params: ShellParams = ShellParams()) -> np.ndarray:
    """Which faces face a sealed cavity of a double-walled mesh, (f,) bool (see the module text).

    All ``False`` when the mesh encloses no cavity, or when fewer than ``min_outer`` of its faces would
    remain.
    """
    n_faces = len(mesh.faces)
    vox = voxel_shell(mesh, params)
    inner = np.zeros(n_faces, dtype=bool)
    if not vox.enclosed.any():
        return inner
    hollow = hollow_regions(mesh, vox)
    if not hollow.any():
        return inner
    centres = np.asarray(mesh.triangles_center, dtype=float)
    normals = np.asarray(mesh.face_normals, dtype=float)
    undecided = np.ones(n_faces, dtype=bool)
    for step in params.probe:
        k = vox.index(centres + step * vox.pitch * normals)
        on_surface = vox.surface[k[:, 0], k[:, 1], k[:, 2]]
        inner |= undecided & ~on_surface & hollow[vox.regions[k[:, 0], k[:, 1], k[:, 2]]]
        undecided &= on_surface
    if (~inner).sum() < params.min_outer * n_faces:
        return np.zeros(n_faces, dtype=bool)
    return inner


#: Per-process cache of outer shells by mesh content hash (least recently used evicted); None: nothing dropped.
_CACHE: "Memo[trimesh.Trimesh | None]" = Memo(256)
#: Folder of the on-disk cache of inner-face masks (:func:`use_disk_cache`); ``None``: memory only.
_DISK: Path | None = None


def use_disk_cache(cache_dir: str | Path | None) -> None:
    """Keep the inner-face masks :func:`outer_shell` computes in ``<cache_dir>/shells`` too (``None``: memory only).

    Classifying a 30,000-face reconstruction takes about 0.1 s; every workflow job that tests insides or measures
    penetration on the same meshes (topology, grounding, metrics) would redo it. The stage functions of
    :mod:`phiscene.pipeline` that take a cache folder set it.
    """
    global _DISK
    _DISK = None if cache_dir is None else Path(cache_dir) / "shells"


def _read_mask(path: Path, n_faces: int) -> np.ndarray | None:
    """The cached inner-face mask (n_faces,) bool at ``path``, or ``None`` when absent, unreadable or not this
    mesh's (another face count)."""
    try:
        packed = np.load(path)
    except (OSError, ValueError):
        return None
    if packed.dtype != np.uint8 or packed.shape != ((n_faces + 7) // 8,):
        return None
    return np.unpackbits(packed, count=n_faces).astype(bool)


def _inner_mask(mesh: trimesh.Trimesh, params: "ShellParams", key: str) -> np.ndarray:
    """:func:`inner_faces` of ``mesh``, through the disk cache when one is set (:func:`use_disk_cache`)."""
    from phiscene.atomic import atomic_path

    n = len(mesh.faces)
    path = None if _DISK is None else _DISK / f"{key}.npy"
    got = None if path is None else _read_mask(path, n)
    if got is not None:
        return got
    inner = inner_faces(mesh, params) if n >= 4 else np.zeros(n, dtype=bool)
    if path is not None:
        with atomic_path(path) as tmp:
            np.save(tmp, np.packbits(inner))
    return inner


def outer_shell(mesh: trimesh.Trimesh, params: ShellParams = ShellParams()) -> trimesh.Trimesh:
    """``mesh`` without the faces that face a sealed cavity (``mesh`` itself when there are none).

    Cached per process by mesh content and parameters (the result is shared: copy it before changing it), and the
    inner-face mask on disk where :func:`use_disk_cache` set a folder.

    Parameters
    ----------
    mesh
        Any triangle mesh (vertices need not be merged: the classification is per face).

    Returns
    -------
    trimesh.Trimesh
        The outer surface, same vertices, a subset of the faces (``mesh`` itself when nothing is dropped).
    """
    from phiscene.meshes import mesh_hash

    key = f"{mesh_hash(mesh)}-{params.digest()}"

    def shell() -> trimesh.Trimesh | None:
        inner = _inner_mask(mesh, params, key)
        if not inner.any():
            return None
        got = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)[~inner], process=False)
        got.remove_unreferenced_vertices()
        return got

    # nothing dropped is remembered as None, not as the mesh first seen: callers test ``outer_shell(m) is m``, and
    # another object with the same content (the same file loaded again) must get itself back too
    got = _CACHE.get(key, shell)
    return mesh if got is None else got


def solid_surface(mesh: trimesh.Trimesh, resolution: int) -> trimesh.Trimesh:
    """A closed surface of the solid ``mesh`` stands for: marching cubes of its signed distance on a grid.

    The signed distance is :class:`phiscene.sdf.SignedDistance`'s (the outer shell's, so a hollow
    reconstruction comes out filled). The grid has ``resolution`` cells along the longest axis and two cells of
    padding, so the surface is closed; parts thinner than about a cell may be lost (callers check what they
    keep against the mesh).

    Returns
    -------
    trimesh.Trimesh
        Watertight unless the mesh is too thin for the grid (then possibly empty).
    """
    from phiscene.sdf import signed_distance_for

    axes, h = _grid_axes(mesh, resolution, 0)
    return grid_surface(axes, h, signed_distance_for(mesh))


def wrapped_surface(mesh: trimesh.Trimesh, resolution: int, offset: float) -> trimesh.Trimesh:
    """A closed surface around ``mesh``, ``offset`` grid cells outside it, that fills what the mesh encloses and
    leaves open what is open to the outside (a bowl's cavity, the space under a table).

    What CoACD's manifold preprocessing makes of a mesh that is not closed, on phiscene's grid: the nodes within
    ``offset`` cells of the surface (its unsigned distance) are the wall; the other nodes that the grid's border
    reaches through the other nodes (6-connected) are outside, the rest enclosed; the surface is marching
    cubes of the unsigned distance at the wall's edge, between the outside and the rest. The grid has
    ``resolution`` cells along the longest axis. Above half a cell, no sheet of the mesh is lost however thin (it
    becomes a slab of twice the offset); a part thinner than a cell across two axes (a wire) can be lost up to
    ``sqrt(3) / 2`` cells.

    Returns
    -------
    trimesh.Trimesh
        Closed (possibly empty when the wall holds no node).
    """
    from scipy import ndimage

    from phiscene.sdf import SignedDistance

    axes, h = _grid_axes(mesh, resolution, offset)
    shape = tuple(len(a) for a in axes[::-1])  # (nz, ny, nx): grid_surface's node order, x fastest
    unsigned = SignedDistance(mesh).unsigned

    def field(nodes: np.ndarray) -> np.ndarray:
        d = np.asarray(unsigned(nodes), dtype=float)
        free = (d >= offset * h).reshape(shape)
        labels, _ = ndimage.label(free)
        border = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                           labels[:, :, [0, -1]].ravel()]))
        outside = np.isin(labels, border[border > 0]).ravel()
        return np.where(outside, d, -d)

    return grid_surface(axes, h, field, level=offset * h)


def drawn_in(surface: trimesh.Trimesh, mesh: trimesh.Trimesh, gap: float) -> trimesh.Trimesh:
    """``surface`` (a wrap of ``mesh``) with each vertex moved to ``gap`` (m) from its closest point on ``mesh``,
    on the side it lies: the wrap's connectivity (closed, what is enclosed filled, what is open left open) on
    the mesh's own surface, where a wrap stands off it by its offset everywhere (a reconstructed chair's legs
    thickened by 1.5 cm on a 40-cell grid). A thin sheet stays a slab of twice ``gap``. Faces between moved
    vertices are not checked for crossing one another.

    Returns
    -------
    trimesh.Trimesh
        The same faces; vertices (v, 3) moved.
    """
    from phiscene.sdf import nearest_on_surface

    v = np.asarray(surface.vertices, dtype=float)
    origin = v.mean(axis=0)
    _, closest = nearest_on_surface(mesh, v, origin)
    away = v - origin - closest
    length = np.linalg.norm(away, axis=1, keepdims=True)
    moved = np.where(length > 0, closest + gap * away / np.where(length > 0, length, 1.0), v - origin)
    return trimesh.Trimesh(moved + origin, np.asarray(surface.faces), process=False)


def _grid_axes(mesh: trimesh.Trimesh, resolution: int, offset: float) -> tuple[list[np.ndarray], float]:
    """Node coordinates (nx,), (ny,), (nz,) of a grid of ``resolution`` cells along ``mesh``'s longest axis,
    padded by two cells beyond ``offset`` cells around its bounds, and the cell size (m)."""
    lo, hi = np.asarray(mesh.bounds, dtype=float)
    h = float((hi - lo).max()) / resolution
    counts = np.ceil((hi - lo) / h + 2 * offset).astype(np.int64) + 5
    start = 0.5 * (lo + hi) - 0.5 * h * (counts - 1)
    return [start[i] + h * np.arange(counts[i]) for i in range(3)], h


def simplified_closed(mesh: trimesh.Trimesh, tolerance: float) -> trimesh.Trimesh:
    """A closed surface simplified by manifold3d, no point of it moved farther than ``tolerance`` (m).

    Marching cubes writes thousands of faces where a few hundred hold the shape; CoACD's cost grows with them
    (a reconstructed pear's solid: 9,344 faces, 3.4 s; simplified to a quarter of a grid cell, 1,616 faces,
    0.2 s, the same two pieces). manifold3d keeps the result a closed manifold, which lets CoACD skip its own
    manifold preprocessing. ``mesh`` itself when manifold3d does not take it as a manifold.
    """
    import manifold3d

    solid = manifold3d.Manifold(manifold3d.Mesh(np.asarray(mesh.vertices, dtype=np.float32),
                                                np.asarray(mesh.faces, dtype=np.uint32)))
    if solid.status() != manifold3d.Error.NoError or solid.is_empty():
        return mesh
    out = solid.simplify(tolerance).to_mesh()
    small = trimesh.Trimesh(np.asarray(out.vert_properties, dtype=float)[:, :3],
                            np.asarray(out.tri_verts, dtype=np.int64), process=False)
    return small if len(small.faces) >= 4 and is_closed_manifold(small) else mesh


def is_closed_manifold(mesh: trimesh.Trimesh) -> bool:
    """Whether ``mesh`` is closed and consistently wound with every vertex at a position of its own.

    What CoACD may take without its manifold preprocessing. manifold3d keeps two sheets that touch at a point or
    an edge apart with two vertices at the same place; merged, their edges join four faces, and CoACD run on
    such a surface without preprocessing crashed the process (a reconstructed plant's solid).
    """
    merged = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=True)
    return len(merged.vertices) == len(mesh.vertices) and merged.is_watertight and merged.is_winding_consistent


def grid_surface(axes: list[np.ndarray], cell: float, distance, level: float = 0.0) -> trimesh.Trimesh:
    """Marching cubes (libigl) of ``distance - level`` on the regular grid of ``axes``.

    Parameters
    ----------
    axes
        Three increasing node coordinate arrays (nx,), (ny,), (nz,) of spacing ``cell``.
    distance
        ``distance(nodes (n, 3)) -> (n,)``, a signed distance (negative inside).
    level
        The isovalue; a node within ``1e-9 cell`` of it counts as outside (no zero-length edges).

    Returns
    -------
    trimesh.Trimesh
        Empty when no node is inside; otherwise oriented like ``distance`` (normals towards larger values).
    """
    import igl

    counts = [len(a) for a in axes]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")  # libigl: x varies fastest
    nodes = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    values = np.asarray(distance(nodes), dtype=float) - level
    values[np.abs(values) < 1e-9 * cell] = 1e-9 * cell
    if values.min() >= 0:
        return trimesh.Trimesh()
    v, f, _ = igl.marching_cubes(values, nodes, int(counts[0]), int(counts[1]), int(counts[2]), 0.0)
    return trimesh.Trimesh(np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64), process=False)


def cavity_share(mesh: trimesh.Trimesh, params: ShellParams = ShellParams()) -> float:
    """Share of the solid's voxels that lie in sealed cavities of a double wall (0 for a solid or open mesh).

    The solid is every voxel the surface passes through or encloses (:func:`voxel_shell`); a cavity is an
    enclosed region whose winding number is below ``TOL.winding_inside``. The same measure on real and
    synthetic reconstructions compares how hollow they are (surface voxels count as solid, so a thin object
    scores low at any wall thickness).
    """
    vox = voxel_shell(mesh, params)
    if not vox.enclosed.any():
        return 0.0
    cavity = int(hollow_regions(mesh, vox)[vox.regions].sum())
    return cavity / float(vox.surface.sum() + vox.enclosed.sum())
