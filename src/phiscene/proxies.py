"""Collision proxies: convex decomposition of each mesh, cached by content.

A proxy set is a list of convex hulls, each ``(v, 3)`` vertices in the
object's unscaled local frame. Back ends: ``coacd`` (default, CoACD with
decimation), ``vhacd`` (pybullet's V-HACD) and ``convex`` (one hull; fast,
for tests and convex objects). Results are cached under
``<cache_dir>/proxies/<mesh hash>-<params hash>.npz`` with atomic writes, so
parallel jobs can share the cache. Each entry also stores a hash of its own
hull arrays; an entry that is unreadable, was built for another key, or
whose content no longer matches its hash (a corrupted file) is rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import trimesh

from phiscene.atomic import atomic_path
from phiscene.errors import InputError
from phiscene.failures import raise_if_failed
from phiscene.meshes import load_mesh, mesh_hash
from phiscene.params import Params

log = logging.getLogger(__name__)

#: Bump when the decomposition code changes in a way that changes results.
PROXY_VERSION = 10
#: A hull vertex farther than this share of the mesh's bounding-box diagonal outside the mesh's convex hull makes
#: :func:`fit_to_mesh` clip the hull (below it: floating-point noise of an exact decomposition, left alone).
CLIP_TOLERANCE = 1e-4
#: Routes a decomposition can take (recorded in ``Proxy.meta["route"]``).
ROUTES = ("convex", "single_hull", "solid", "decomposed")
#: Routes through the backend's decomposition: the ones :func:`proxy_for_mesh`'s refinement may redo.
DECOMPOSED_ROUTES = ("solid", "decomposed")
#: phiscene's closed surfaces are simplified for CoACD to this share of their grid cell (:func:`_decompose_closed`).
CLOSED_SIMPLIFY = 0.25
#: The decomposed route's wrap lies this many grid cells outside the mesh: more than half a cell, so no sheet of
#: the mesh is lost however thin (:func:`phiscene.solid.wrapped_surface`).
WRAP_OFFSET = 0.6
#: ... and is then drawn in to this many cells from the mesh (:func:`phiscene.solid.drawn_in`): the wrap's offset
#: alone thickened a reconstructed chair's legs by 1.5 cm, and the suite's grounding moved chairs tucked under a
#: table farther (docs/measurements.md, "CoACD on closed surfaces").
WRAP_GAP = 0.1
#: Settings of :func:`proxy_for_mesh`'s refinement, not of one decomposition (left out of its cache key).
REFINE_KEYS = ("refine_excess", "refine_max_hulls")


@dataclass(frozen=True)
class ProxyParams(Params):
    """Convex decomposition parameters.

    Attributes
    ----------
    backend
        ``coacd``, ``vhacd`` or ``convex``.
    threshold
        CoACD concavity threshold (smaller = more, tighter hulls).
    max_hulls
        Cap on the number of hulls (-1 = no cap).
    max_hull_vertices
        Vertex cap per hull (V-HACD maxNumVerticesPerCH; CoACD's own decimation unless ``coacd_hull_vertices``;
        then every hull, the single hull of a nearly convex mesh included, through :func:`fit_to_mesh`'s
        farthest-point cap). A collision test of two convex pieces costs time in proportion to their vertices:
        the paper settles with at most 96 vertices per piece (supplement), and ``custom_viga`` grounded warm on
        one core in 7.0 s with 96 against 13.3 s with 256 (README, "Faithful grounding").
    coacd_hull_vertices
        CoACD's own decimation cap per hull (``max_ch_vertex``) when it is to be higher than
        ``max_hull_vertices`` (0: the same): the pieces are chosen (and the solid route's coverage tested) with
        this many vertices, then each is cut to ``max_hull_vertices`` of its own (:func:`cut_hull`). With CoACD
        decimating to 96 itself, ``custom_viga``'s proxies had 45 pieces and took 74 s instead of 31 in 22 s.
    preprocess_resolution
        Cells along the longest axis of the grid on which a mesh that is not closed is wrapped for CoACD (a
        closed surface :data:`WRAP_OFFSET` cells outside it, :func:`phiscene.solid.wrapped_surface`, simplified,
        then drawn in to :data:`WRAP_GAP` cells from the mesh), as CoACD's own manifold preprocessing does on its
        voxels (which it still does on a closed mesh that its manifold test refuses). The wrap is decomposed
        without that preprocessing: CoACD took 0.7-2.8 s on a reconstructed plate's wrap against 7.0 s on its
        decimated surface (docs/measurements.md, "CoACD on closed surfaces").
    resolution
        CoACD sampling resolution / V-HACD voxel resolution.
    mcts_iterations, mcts_nodes, mcts_max_depth
        CoACD tree-search settings.
    seed
        Random seed of the decomposition.
    max_faces
        Meshes with more faces are decimated (quadric, ``fast_simplification``) to this budget before
        decomposition; the fidelity check still measures the proxies against the original mesh. Real
        foundation-model meshes have ~30,000 faces, and CoACD's cost grows with them (0 = never decimate).
    convex_tolerance
        A mesh whose convex hull stays within this fraction of its bounding-box diagonal of its surface (95th
        percentile over hull surface samples) is nearly convex and gets its convex hull as its only proxy,
        without CoACD (fruit, plates, boxes, jugs). 0 = always decompose.
    solid_resolution
        A hollow, double-walled reconstruction (:func:`phiscene.solid.outer_shell` drops faces) is decomposed
        as the closed surface of its solid (:func:`phiscene.solid.solid_surface`, this many cells along the
        longest axis), which CoACD takes without its manifold preprocessing: the preprocessing turns a thin
        wall into a shell of its own and decomposes that (11-13 s for a reconstructed pear or jug, eight hulls
        reaching 4.6-7.5 cm beyond it, against 2-8 hulls reaching at most 4 mm beyond it in 2.4-2.8 s). 0 = off.
    solid_tolerance
        The solid route is kept only if no mesh surface sample lies farther than this fraction of the diagonal
        outside its hulls (a part thinner than a grid cell lost); otherwise the mesh takes the backend's route.
    decimation_tolerance
        A decimation (``max_faces``) that leaves a sample of the mesh's surface farther than this fraction of the
        diagonal from the decimated surface lost part of the object, and is redone with four times the face
        budget until nothing is lost or the mesh is kept whole (:func:`decimated_faithfully`): decimated to 2000
        faces, a reconstructed 1.5 m dining table lost most of its top, and its proxies left 69 cm of the table
        uncovered (it stood tilted 44 degrees on what was left). 0 = never redone.
    refine_excess
        A CoACD decomposition that used all of its ``max_hulls`` and still reaches farther beyond the mesh than
        this fraction of its diagonal (``Proxy.excess``) is decomposed again with ``refine_max_hulls``, and the
        set that reaches less far is kept (:func:`proxy_for_mesh`). The same bound as ``convex_tolerance``: a
        proxy may stand off the surface as far as a single hull may. Eight hulls fill the space between a
        reconstructed chair's legs and under its arms, 4-13 % of its diagonal beyond it; simulated, its pieces
        overlap the table it is tucked under by 10 cm where the meshes meet 9 mm deep. 0 = off.
    refine_max_hulls
        The hull cap of that second decomposition (no refinement unless it is larger than ``max_hulls``).
    """

    _label = "proxy parameters"

    backend: str = "coacd"
    threshold: float = 0.08
    max_hulls: int = 16
    max_hull_vertices: int = 512
    coacd_hull_vertices: int = 0
    preprocess_resolution: int = 40
    resolution: int = 1000
    mcts_iterations: int = 60
    mcts_nodes: int = 12
    mcts_max_depth: int = 2
    seed: int = 0
    max_faces: int = 2000
    convex_tolerance: float = 0.03
    solid_resolution: int = 40
    solid_tolerance: float = 0.02
    decimation_tolerance: float = 0.02
    refine_excess: float = 0.03
    refine_max_hulls: int = 16

    def check(self) -> None:
        """Reject an unknown ``backend``, negative budgets or a tolerance out of range (``ValueError``)."""
        if self.backend not in ("coacd", "vhacd", "convex"):
            raise ValueError(f"proxy backend must be coacd, vhacd or convex, got {self.backend!r}")
        if self.max_faces < 0 or self.max_faces in range(1, 100):
            raise ValueError(f"proxy max_faces must be 0 (no decimation) or >= 100, got {self.max_faces}")
        if not 0.0 <= self.convex_tolerance < 1.0:
            raise ValueError(f"proxy convex_tolerance must be in [0, 1), got {self.convex_tolerance}")
        if self.solid_resolution < 0 or self.solid_resolution in range(1, 8) or not 0.0 < self.solid_tolerance < 1.0:
            raise ValueError(f"proxy solid_resolution must be 0 (off) or >= 8 and solid_tolerance in (0, 1), got "
                             f"{self.solid_resolution}, {self.solid_tolerance}")
        if not 0.0 <= self.decimation_tolerance < 1.0:
            raise ValueError(f"proxy decimation_tolerance must be in [0, 1), got {self.decimation_tolerance}")
        if not 0.0 <= self.refine_excess < 1.0:
            raise ValueError(f"proxy refine_excess must be in [0, 1), got {self.refine_excess}")
        if self.coacd_hull_vertices < 0:
            raise ValueError(f"proxy coacd_hull_vertices must be >= 0 (0: max_hull_vertices), got "
                             f"{self.coacd_hull_vertices}")
        if self.refine_max_hulls < 0:
            raise ValueError(f"proxy refine_max_hulls must be >= 0 (0: never refine), got {self.refine_max_hulls}")

    def digest(self) -> str:
        """Cache key of one decomposition: every setting but the refinement's (:data:`REFINE_KEYS`), which
        chooses between two decompositions, each cached under its own key."""
        kept = {k: v for k, v in asdict(self).items() if k not in REFINE_KEYS}
        text = json.dumps({**kept, "version": PROXY_VERSION}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def decomposition_vertices(self) -> int:
        """The vertex cap the decomposition and its route work with (``coacd_hull_vertices``, else
        ``max_hull_vertices``), before each piece is cut to ``max_hull_vertices``."""
        return self.coacd_hull_vertices or self.max_hull_vertices

    def refines(self) -> bool:
        """Whether a decomposition that hit its hull cap may be redone with more hulls."""
        return self.backend == "coacd" and self.refine_excess > 0 and self.max_hulls > 0 and \
            self.refine_max_hulls > self.max_hulls


@dataclass
class Proxy:
    """Convex proxies of one mesh with their fidelity.

    Attributes
    ----------
    hulls
        Each ``(v, 3)`` float vertices of one convex piece (unscaled local frame).
    volume_ratio
        Total hull volume / mesh volume (>= 1 for a covering decomposition; NaN for open meshes).
    max_outside
        Largest distance (m, unscaled) of a mesh surface sample outside every hull.
    excess
        How far the proxies reach beyond the mesh (m, unscaled): the 95th percentile, over seeded samples of the
        boundary of the hulls' union, of the distance outside the mesh's solid (0 inside it). Defined for open
        meshes, where ``volume_ratio`` is not (a coarse decomposition that fattens a chair leg or fills a bowl
        scores high; NaN when unknown).
    seconds
        Decomposition wall time.
    """

    hulls: list[np.ndarray]
    volume_ratio: float
    max_outside: float
    seconds: float = 0.0
    meta: dict = field(default_factory=dict)
    excess: float = float("nan")


def decimated(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """``mesh`` itself, or a quadric-decimated copy with about ``max_faces`` faces (0 = no limit).

    Open boundaries are preserved, so a mesh with many holes keeps more faces than the budget.
    """
    if max_faces <= 0 or len(mesh.faces) <= max_faces:
        return mesh
    import fast_simplification

    v, f = fast_simplification.simplify(np.asarray(mesh.vertices, dtype=np.float32),
                                        np.asarray(mesh.faces, dtype=np.int32),
                                        target_reduction=1.0 - max_faces / len(mesh.faces))
    out = trimesh.Trimesh(np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64), process=True)
    return out if len(out.faces) >= 4 else mesh


def decimated_unit_free(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """:func:`decimated`, the same whatever the units of the mesh's frame: decimated centred on its bounding box and
    scaled to a unit diagonal, then put back.

    ``fast_simplification`` compares quadric errors (squared lengths) with fixed thresholds, so the same mesh in
    other units decimates differently: a SAM 3D Objects mesh comes in a [-0.5, 0.5]^3 frame with its size in its
    pose, the same object imported from a baked scene comes in metres. The nearly-convex decision of
    :func:`decompose_route`, taken on the decimated copy, then flipped: a reconstructed pear's :func:`hull_excess`
    was 0.0325 in metres and 0.0259 to 0.0369 at other scales, about the 0.03 tolerance (0.0333 at every scale
    now).
    """
    if max_faces <= 0 or len(mesh.faces) <= max_faces:
        return mesh
    v = np.asarray(mesh.vertices, dtype=float)
    centre = (v.min(axis=0) + v.max(axis=0)) / 2
    size = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    if not size > 0:
        return mesh
    unit = decimated(trimesh.Trimesh((v - centre) / size, np.asarray(mesh.faces), process=False), max_faces)
    return trimesh.Trimesh(np.asarray(unit.vertices) * size + centre, np.asarray(unit.faces), process=False)


def decimation_loss(mesh: trimesh.Trimesh, reduced: trimesh.Trimesh, samples: int = 2048, seed: int = 0) -> float:
    """Largest distance (m, unscaled) from a seeded sample of ``mesh``'s surface to ``reduced``'s surface.

    Every face of ``reduced`` counts. Measured to the outer shell of ``reduced`` instead (as before PROXIES 8), the
    voxel classification dropped faces of decimated reconstructions as inner walls: on the 61 `real` meshes the
    loss read up to 5.5 % of the diagonal more, a chair's decimation was redone for it, and the 76 measurements took
    8.5 s instead of 0.8 s.
    """
    from phiscene.meshes import sample_surface
    from phiscene.sdf import surface_distance

    if reduced is mesh:
        return 0.0
    return float(surface_distance(reduced, sample_surface(mesh, samples, seed)).max())


def decimated_faithfully(mesh: trimesh.Trimesh, max_faces: int, tolerance: float,
                         seed: int = 0) -> trimesh.Trimesh:
    """:func:`decimated_unit_free` to ``max_faces``, redone with four times the budget while it loses more than
    ``tolerance`` (m) of the surface (:func:`decimation_loss`); ``mesh`` itself once the budget reaches its faces.

    Quadric decimation keeps what is flat and merges what is thin: a table top seen edge-on, a chair's legs. The
    proxies are decomposed from the decimated copy, so what it loses, they lose. ``tolerance`` <= 0: decimated
    once.
    """
    work = decimated_unit_free(mesh, max_faces)
    budget = max_faces
    while tolerance > 0 and work is not mesh and decimation_loss(mesh, work, seed=seed) > tolerance:
        budget *= 4
        work = decimated_unit_free(mesh, budget)
        log.info("decimation to %d faces lost part of the mesh; decimating to %d", budget // 4, budget)
    return work


def hull_excess(mesh: trimesh.Trimesh, samples: int = 1024, seed: int = 0) -> float:
    """How far a mesh's convex hull reaches beyond the mesh: the 95th percentile of the distance from seeded
    samples of the hull's surface to the mesh surface, divided by the mesh's bounding-box diagonal.

    0 for a convex mesh; a table on legs, a bowl or an L-shape scores high.
    """
    hull = mesh.convex_hull
    pts, _ = trimesh.sample.sample_surface(hull, samples, seed=seed)
    with np.errstate(divide="ignore", invalid="ignore"):  # quiet on degenerate faces (same result)
        _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
    diag = float(np.linalg.norm(mesh.extents))
    return float(np.percentile(dist, 95)) / diag if diag > 0 else 0.0


def decompose(mesh: trimesh.Trimesh, params: ProxyParams) -> list[np.ndarray]:
    """Convex decomposition of a local-frame mesh (:func:`decompose_route` without the route)."""
    return decompose_route(mesh, params)[0]


def decompose_route(mesh: trimesh.Trimesh, params: ProxyParams, solid: bool = True) -> tuple[list[np.ndarray], str]:
    """Convex decomposition of a local-frame mesh, and the route it took (:data:`ROUTES`).

    The mesh is first reduced to its outer shell (:func:`phiscene.solid.outer_shell`: the cavity of a hollow
    reconstruction is part of the object) and decimated (``max_faces``, :func:`decimated_unit_free`); a nearly
    convex one
    (``convex_tolerance``) gets its convex hull; a hollow one is decomposed as the closed surface of its solid
    when that covers it (``solid_resolution``; not tried when ``solid`` is false); anything else goes to the
    backend, CoACD taking a shell that is not closed as its wrap (``preprocess_resolution``).

    Returns
    -------
    hulls : list of (v, 3) float
    route : str
    """
    hulls, route, _ = _decompose_routed(mesh, params, solid)
    return hulls, route


def _decompose_routed(mesh: trimesh.Trimesh, params: ProxyParams,
                      solid: bool) -> tuple[list[np.ndarray], str, bool]:
    """:func:`decompose_route`, and whether the solid route was tried and lost part of the mesh."""
    if params.backend == "convex":
        return [np.asarray(mesh.convex_hull.vertices, dtype=float)], "convex", False
    hulls, route, lost = _routed(mesh, params, params.decomposition_vertices(), solid)
    # each piece cut to its final budget once its route is chosen: a coverage test on the cut pieces would reject
    # the solid route for what the cut leaves uncovered
    return [cut_hull(h, params.max_hull_vertices) for h in hulls], route, lost


def _routed(mesh: trimesh.Trimesh, params: ProxyParams, vertices: int,
            solid: bool = True) -> tuple[list[np.ndarray], str, bool]:
    """:func:`decompose_route`'s routes, each piece through :func:`fit_to_mesh` with at most ``vertices``, and
    whether the solid route was tried and lost part of the mesh."""
    from phiscene.solid import outer_shell, wrapped_surface

    shell = outer_shell(mesh)
    diagonal = _diagonal(mesh)
    work = decimated_faithfully(shell, params.max_faces, params.decimation_tolerance * diagonal, params.seed)
    if params.convex_tolerance > 0 and hull_excess(work, seed=params.seed) <= params.convex_tolerance:
        return fit_to_mesh([mesh.convex_hull.vertices], mesh, vertices), "single_hull", False
    lost = False
    if solid and params.solid_resolution and params.backend == "coacd" and shell is not mesh:
        tol = params.solid_tolerance * diagonal
        hulls = fit_to_mesh(_decompose_solid(shell, mesh, tol, params), mesh, vertices)
        if hulls and max_outside(mesh, hulls, seed=params.seed) <= tol:
            return hulls, "solid", False
        log.info("solid route lost part of the mesh; decomposing the surface instead")
        lost = True
    if params.backend == "coacd" and not work.is_watertight:
        # CoACD would first make a manifold of the (decimated) surface with its own preprocessing; phiscene's wrap
        # of the same resolution, simplified, takes its place
        wrap = wrapped_surface(shell, params.preprocess_resolution, WRAP_OFFSET)
        if len(wrap.faces) >= 4 and wrap.is_watertight:
            cell = float(shell.extents.max()) / params.preprocess_resolution
            hulls = _decompose_closed(wrap, params, cell, hug=(shell, WRAP_GAP * cell))
            return fit_to_mesh(hulls, mesh, vertices), "decomposed", lost
    return fit_to_mesh(_decompose(work, params), mesh, vertices), "decomposed", lost


def fit_to_mesh(hulls: list[np.ndarray], mesh: trimesh.Trimesh, max_vertices: int) -> list[np.ndarray]:
    """Hulls cut back to the mesh's convex hull, each with at most ``max_vertices`` vertices.

    A decomposition reaches beyond the mesh it stands for: CoACD remeshes a mesh that is not a closed manifold
    (every reconstruction) on a voxel grid first, and decimates its hulls; the solid route decomposes a voxel
    surface; a quadric-decimated hull bulges past the faces it replaces. Measured on the regeneration's proxies,
    the hulls of the real scenes' objects with several pieces reached a median 5.1 mm (up to 20 mm) beyond the
    mesh's own convex hull, which nothing of the mesh reaches: objects rested that far above their supports (a
    box placed exactly on a table ended 7 mm above it, the table 7 mm above the floor). Each hull is intersected
    with the convex hull of the mesh (:func:`clip_to_hull`); the mesh lies inside that, so no part of it is
    uncovered by the cut. A hull with more than ``max_vertices`` vertices (a cut adds some; the hull of a
    30,000-face scan has thousands) keeps the convex hull of a farthest-point subset of them
    (:func:`farthest_points`), which lies inside it, never beyond (0 = no cap).

    Parameters
    ----------
    hulls
        Convex pieces, each ``(v, 3)`` local vertices.
    mesh
        The mesh they stand for, in the same frame.
    max_vertices
        Vertex cap per piece.

    Returns
    -------
    list of (v, 3) float
        A piece that lies entirely beyond the mesh's hull is dropped; all of them (never seen) leaves the input.
    """
    bound = mesh.convex_hull
    tol = CLIP_TOLERANCE * _diagonal(mesh)
    out = []
    for h in hulls:
        v = clip_to_hull(np.asarray(h, dtype=float), bound, tol)
        if v is None:
            continue
        out.append(cut_hull(v, max_vertices))
    return out or [np.asarray(h, dtype=float) for h in hulls]


def cut_hull(vertices: np.ndarray, max_vertices: int) -> np.ndarray:
    """A convex piece (v, 3) with at most ``max_vertices`` of its own vertices: the convex hull of their
    farthest-point subset (:func:`farthest_points`), which lies inside it; unchanged when within the budget or
    ``max_vertices`` is 0."""
    v = np.asarray(vertices, dtype=float)
    if 0 < max_vertices < len(v):
        v = np.asarray(trimesh.convex.convex_hull(farthest_points(v, max_vertices)).vertices, dtype=float)
    return v


def clip_to_hull(vertices: np.ndarray, bound: trimesh.Trimesh, tol: float = 0.0) -> np.ndarray | None:
    """Vertices of the intersection of the convex hull of ``vertices`` with the convex polytope ``bound``.

    Parameters
    ----------
    vertices : (v, 3) float
        A convex piece.
    bound
        A convex mesh (outward normals).
    tol
        The piece itself is returned, unchanged, when no vertex lies farther than ``tol`` outside ``bound``.

    Returns
    -------
    (w, 3) float, or None
        ``None`` when the intersection has no interior.
    """
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection, QhullError

    if _plane_distance(vertices, bound).max() <= tol:
        return vertices
    try:
        piece = trimesh.convex.convex_hull(vertices)
    except QhullError:
        return None
    # rows (n, -d): n . x - d <= 0 inside
    hs = np.unique(np.round(np.vstack([np.column_stack([n, -d]) for n, d in map(_face_planes, (piece, bound))]), 12),
                   axis=0)
    # the Chebyshev centre: the point deepest inside every halfspace (its depth must be positive)
    norm = np.linalg.norm(hs[:, :3], axis=1)
    lp = linprog(np.r_[0.0, 0.0, 0.0, -1.0], A_ub=np.column_stack([hs[:, :3], norm]), b_ub=-hs[:, 3],
                 bounds=[(None, None)] * 3 + [(0.0, None)], method="highs")
    if lp.status != 0 or lp.x[3] <= 1e-9 * max(_diagonal(bound), 1e-12):
        return None
    try:
        cut = HalfspaceIntersection(hs, lp.x[:3]).intersections
    except QhullError:
        return None
    return np.asarray(trimesh.convex.convex_hull(cut).vertices, dtype=float)


def farthest_points(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` of ``points`` (n, 3) chosen by farthest-point sampling, first the one farthest from their mean.

    Deterministic; returns (min(count, n), 3).
    """
    p = np.asarray(points, dtype=float)
    if count >= len(p):
        return p
    chosen = [int(np.argmax(np.linalg.norm(p - p.mean(axis=0), axis=1)))]
    dist = np.linalg.norm(p - p[chosen[0]], axis=1)
    for _ in range(count - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(p - p[k], axis=1))
    return p[np.sort(chosen)]


def _diagonal(mesh: trimesh.Trimesh) -> float:
    return float(np.linalg.norm(mesh.extents))


def _decompose_solid(shell: trimesh.Trimesh, mesh: trimesh.Trimesh, tol: float,
                     params: ProxyParams) -> list[np.ndarray]:
    """CoACD on the closed surface of a hollow mesh's solid (no manifold preprocessing needed).

    Empty when that surface is not closed, or when it cannot cover ``mesh`` within ``tol`` (m): every piece CoACD
    cuts from the surface lies in the surface's convex hull, so a mesh point farther than ``tol`` outside that hull
    (a plant's leaves, a fan's blades, a curtain's folds lost by the grid) stays uncovered whatever the
    decomposition, and the decomposition (seconds) is not run.
    """
    from phiscene.solid import solid_surface

    surface = solid_surface(shell, params.solid_resolution)
    if len(surface.faces) < 4 or not surface.is_watertight:
        return []
    if max_outside(mesh, [np.asarray(surface.vertices, dtype=float)], seed=params.seed) > tol:
        return []
    return _decompose_closed(surface, params, float(shell.extents.max()) / params.solid_resolution)


def _decompose_closed(surface: trimesh.Trimesh, params: ProxyParams, cell: float,
                      hug: tuple[trimesh.Trimesh, float] | None = None) -> list[np.ndarray]:
    """CoACD on a closed surface phiscene made on a grid of ``cell`` (m): simplified to :data:`CLOSED_SIMPLIFY`
    of a cell (:func:`phiscene.solid.simplified_closed`), given ``hug`` ``(mesh, gap)`` drawn in to ``gap`` from
    that mesh (:func:`phiscene.solid.drawn_in`), and decomposed without CoACD's manifold preprocessing.

    CoACD's ``auto`` preprocessing remeshed such a surface where its own manifold test failed on it: 28.7 s
    instead of 0.8 s for a reconstructed pear's solid (docs/measurements.md, "CoACD on closed surfaces").
    """
    from phiscene.solid import drawn_in, is_closed_manifold, simplified_closed

    small = simplified_closed(surface, CLOSED_SIMPLIFY * cell)
    if hug is not None:
        small = drawn_in(small, *hug)
    return _decompose(small, params, closed=is_closed_manifold(small))


def capped_hull(mesh: trimesh.Trimesh, max_vertices: int) -> np.ndarray:
    """Vertices (v, 3) of the convex hull of ``mesh``, at most about ``max_vertices`` of them.

    The hull of a 30,000-face scan of a fruit has thousands of vertices; collision tests and the enumeration
    of resting poses scale with them. A larger hull is quadric-decimated (``fast_simplification``) to the
    budget and the hull of what remains is taken, so the proxy stays convex and close to the full hull (the
    fidelity check measures it against the mesh). 0 = no cap.
    """
    hull = mesh.convex_hull
    if max_vertices <= 0 or len(hull.vertices) <= max_vertices:
        return np.asarray(hull.vertices, dtype=float)
    small = decimated(hull, max(2 * max_vertices - 4, 100))
    return np.asarray(trimesh.convex.convex_hull(small.vertices).vertices, dtype=float)


def _decompose(mesh: trimesh.Trimesh, params: ProxyParams, closed: bool = False) -> list[np.ndarray]:
    """The backend's decomposition of ``mesh``; ``closed``: a closed manifold, which CoACD takes without its
    manifold preprocessing."""
    if params.backend == "coacd":
        import coacd

        coacd.set_log_level("error")
        cm = coacd.Mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64))
        parts = coacd.run_coacd(
            cm, threshold=params.threshold, max_convex_hull=params.max_hulls,
            preprocess_mode="off" if closed else "auto",
            preprocess_resolution=params.preprocess_resolution, resolution=params.resolution,
            mcts_nodes=params.mcts_nodes, mcts_iterations=params.mcts_iterations,
            mcts_max_depth=params.mcts_max_depth, decimate=True,
            max_ch_vertex=params.decomposition_vertices(),
            seed=params.seed)
        hulls = [np.asarray(v, dtype=float) for v, _ in parts if len(v) >= 4]
    else:
        hulls = _vhacd(mesh, params)
    hulls = [h for h in hulls if _hull_ok(h)]
    if not hulls:  # decomposition failed: one convex hull is always a valid proxy
        log.warning("convex decomposition returned nothing usable; using the convex hull")
        hulls = [np.asarray(mesh.convex_hull.vertices, dtype=float)]
    return hulls


def _hull_ok(v: np.ndarray) -> bool:
    try:
        return trimesh.convex.convex_hull(v).volume > 1e-12
    except Exception:
        return False


def _vhacd(mesh: trimesh.Trimesh, params: ProxyParams) -> list[np.ndarray]:
    import tempfile

    import pybullet as p

    with tempfile.TemporaryDirectory() as tmp:
        src, dst, logf = Path(tmp, "in.obj"), Path(tmp, "out.obj"), Path(tmp, "log.txt")
        mesh.export(src)
        p.vhacd(str(src), str(dst), str(logf), resolution=max(params.resolution * 100, 10000),
                maxNumVerticesPerCH=params.max_hull_vertices, concavity=params.threshold * 0.05)
        scene = trimesh.load(dst, force="scene", process=False, split_object=True, group_material=False)
        geoms = list(scene.geometry.values()) if isinstance(scene, trimesh.Scene) else [scene]
        return [np.asarray(g.vertices, dtype=float) for g in geoms]


def _face_planes(hull: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals (f, 3) and offsets (f,) of a convex mesh's face planes: ``n . x = d`` on face f."""
    normals = np.asarray(hull.face_normals, dtype=float)
    return normals, np.einsum("ij,ij->i", normals, hull.triangles[:, 0])


def _plane_distance(points: np.ndarray, hull: trimesh.Trimesh) -> np.ndarray:
    """Signed distance (n,) of points to a convex hull from its face planes: exact inside, a lower bound outside."""
    normals, offsets = _face_planes(hull)
    points = np.asarray(points, dtype=float)
    step = max(1, 2**22 // max(len(normals), 1))  # rows per block: at most 4M distances (32 MB) at a time
    return np.concatenate([(points[i:i + step] @ normals.T - offsets).max(axis=1)
                           for i in range(0, len(points), step)]) if len(points) else np.zeros(0)


def max_outside(mesh: trimesh.Trimesh, hulls: list[np.ndarray], samples: int = 2048, seed: int = 0) -> float:
    """Largest distance (m, unscaled) of a seeded mesh surface sample outside every hull (0 when all are covered)."""
    from phiscene.meshes import sample_surface

    pts = sample_surface(mesh, samples, seed)
    outside = np.full(len(pts), np.inf)
    for h in hulls:
        outside = np.minimum(outside, np.maximum(_plane_distance(pts, trimesh.convex.convex_hull(h)), 0.0))
    return float(outside.max())


def fidelity(mesh: trimesh.Trimesh, hulls: list[np.ndarray], samples: int = 2048,
             seed: int = 0) -> tuple[float, float, float]:
    """Volume ratio, max outside distance and excess of a proxy set (see :class:`Proxy`).

    The excess is measured on the boundary of the union of the hulls (samples of a hull's surface that lie
    inside another hull are cut faces between pieces, not proxy surface) against the mesh's solid (a sample
    inside it reaches nowhere beyond it).
    """
    from phiscene.sdf import signed_distance_for

    hull_meshes = [trimesh.convex.convex_hull(h) for h in hulls]
    vol = sum(float(h.volume) for h in hull_meshes)
    ratio = vol / float(mesh.volume) if mesh.is_volume and mesh.volume > 0 else float("nan")
    shell = trimesh.util.concatenate(hull_meshes)
    pts, face = trimesh.sample.sample_surface(shell, samples, seed=seed)
    owner = np.repeat(np.arange(len(hull_meshes)), [len(h.faces) for h in hull_meshes])[face]
    boundary = np.ones(len(pts), dtype=bool)
    for k, h in enumerate(hull_meshes):
        if len(hull_meshes) > 1:
            boundary &= (owner == k) | (_plane_distance(pts, h) >= -1e-9)
    reach = np.maximum(signed_distance_for(mesh)(np.asarray(pts)[boundary]), 0.0)
    excess = float(np.percentile(reach, 95)) if len(reach) else 0.0
    return ratio, max_outside(mesh, hulls, samples, seed), excess


def proxy_for_mesh(mesh_file: str | Path, params: ProxyParams, cache_dir: str | Path) -> Proxy:
    """Proxies of the mesh in ``mesh_file``, from the cache or computed and cached.

    A cache entry is trusted only if its stored mesh hash and parameter hash
    match and its hulls still hash to the stored ``content_hash``; a corrupt
    or mismatched entry is recomputed (and rewritten).

    A decomposition routed through CoACD that used all ``max_hulls`` and reaches farther beyond the mesh than
    ``refine_excess`` of its diagonal is decomposed again with ``refine_max_hulls`` (cached too); the set with
    the smaller excess is returned, its ``meta["refined"]`` recording the first one's hull count and excess.
    When the first decomposition tried the solid route and it lost part of the mesh, the second does not try it
    (its meta's ``solid`` is ``skipped``): more pieces cut closer to the solid's surface and cover no more of the
    mesh. On the 36 objects of the `real` and REST3D-baseline suites whose first solid route was lost and that
    were refined, the second was lost too every time, after a CoACD run on the solid's surface (14 s of the
    128 s of `custom_room1`'s basket).
    """
    mesh = load_mesh(mesh_file)
    mh = mesh_hash(mesh)
    first = _decomposition(mesh, mh, params, cache_dir)
    if not (params.refines() and first.meta.get("route") in DECOMPOSED_ROUTES
            and len(first.hulls) >= params.max_hulls and first.excess > params.refine_excess * _diagonal(mesh)):
        return first
    # a solid route that lost part of the mesh is not tried again with more pieces (``solid`` in the meta)
    finer = _decomposition(mesh, mh, replace(params, max_hulls=params.refine_max_hulls), cache_dir,
                           solid=first.meta.get("solid") != "lost")
    log.info("%s: %d hulls reach %.4f m beyond it; with up to %d: %d hulls, %.4f m", Path(mesh_file).name,
             len(first.hulls), first.excess, params.refine_max_hulls, len(finer.hulls), finer.excess)
    best = finer if finer.excess < first.excess else first
    refined = {"hulls": len(first.hulls), "excess": first.excess, "kept": best is finer}
    return replace(best, seconds=first.seconds + finer.seconds, meta={**best.meta, "refined": refined})


def _decomposition(mesh: trimesh.Trimesh, mh: str, params: ProxyParams, cache_dir: str | Path,
                   solid: bool = True) -> Proxy:
    """One decomposition of ``mesh`` (content hash ``mh``) with its fidelity, from the cache or computed and
    cached. ``solid`` false: the solid route is not tried (:func:`decompose_route`); the meta's ``solid`` says
    ``lost`` when it was tried and lost part of the mesh, ``skipped`` when it was not tried for that reason."""
    import time

    ph = params.digest()
    path = Path(cache_dir) / "proxies" / f"{mh}-{ph}.npz"
    cached = _read_entry(path, mh, ph)
    if cached is not None:
        return cached
    t0 = time.perf_counter()
    hulls, route, lost = _decompose_routed(mesh, params, solid)
    ratio, outside, excess = fidelity(mesh, hulls)
    meta = {"mesh_hash": mh, "params_hash": ph, "content_hash": hulls_hash(hulls), "route": route,
            "faces": int(len(mesh.faces))}
    if lost or not solid:
        meta["solid"] = "lost" if lost else "skipped"
    proxy = Proxy(hulls=hulls, volume_ratio=ratio, max_outside=outside, excess=excess,
                  seconds=time.perf_counter() - t0, meta=meta)
    write_proxies(path, {"_": proxy})
    return proxy


def _read_entry(path: Path, mh: str, ph: str) -> Proxy | None:
    if not path.exists():
        return None
    try:
        got = read_proxies(path)["_"]
    except Exception as exc:
        log.warning("proxy cache entry %s unreadable (%s); rebuilding", path, exc)
        return None
    if got.meta.get("mesh_hash") != mh or got.meta.get("params_hash") != ph:
        log.warning("proxy cache entry %s does not match its key; rebuilding", path)
        return None
    if got.meta.get("content_hash") != hulls_hash(got.hulls):
        log.warning("proxy cache entry %s does not match its content hash (corrupted); rebuilding", path)
        return None
    return got


def hulls_hash(hulls: list[np.ndarray]) -> str:
    """Hash of a proxy set's arrays (shapes and float64 values), 16 hex digits.

    Parameters
    ----------
    hulls
        Each ``(v, 3)`` float vertices of one convex piece.
    """
    h = hashlib.sha256()
    for v in hulls:
        a = np.ascontiguousarray(v, dtype=np.float64)
        h.update(np.asarray(a.shape, dtype=np.int64).tobytes())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def write_proxies(path: str | Path, proxies: dict[str, Proxy]) -> None:
    """Write named proxy sets to one ``.npz`` atomically."""
    arrays: dict[str, np.ndarray] = {}
    index = {}
    for name, px in proxies.items():
        index[name] = {"n": len(px.hulls), "volume_ratio": px.volume_ratio, "max_outside": px.max_outside,
                       "excess": px.excess, "seconds": px.seconds, "meta": px.meta}
        for k, h in enumerate(px.hulls):
            arrays[f"{name}/{k}"] = np.asarray(h, dtype=np.float64)
    arrays["__index__"] = np.frombuffer(json.dumps(index, allow_nan=True).encode(), dtype=np.uint8)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


def read_proxies(path: str | Path) -> dict[str, Proxy]:
    """Read the named proxy sets written by :func:`write_proxies`.

    Raises
    ------
    InputError
        Missing, truncated or otherwise unreadable file.
    phiscene.failures.FailedInput
        The file is a failure record (the proxies job failed on this scene).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "proxies file not found")
    raise_if_failed(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            index = json.loads(bytes(z["__index__"]).decode())
            out = {}
            for name, info in index.items():
                hulls = [z[f"{name}/{k}"] for k in range(info["n"])]
                out[name] = Proxy(hulls=hulls, volume_ratio=info["volume_ratio"], max_outside=info["max_outside"],
                                  seconds=info.get("seconds", 0.0), meta=info.get("meta", {}),
                                  excess=info.get("excess", float("nan")))
    except Exception as exc:  # numpy and zipfile raise many types for a damaged archive
        raise InputError(path, None, f"not a readable proxies file ({type(exc).__name__}: {str(exc)[:120]})") from None
    return out


def check_proxies(scene, proxies: dict[str, Proxy], ids: list[str] | None = None) -> None:
    """Check that every object of a scene has a non-empty convex proxy.

    Parameters
    ----------
    scene
        A :class:`~phiscene.scene.Scene` (its ``source`` names the file in the error).
    proxies
        Proxies by object id.
    ids
        Only these object ids (default: every object of ``scene``).

    Raises
    ------
    InputError
        Field ``proxies``, naming the objects without a proxy (or with no hulls).
    """
    ids = [o.id for o in scene.objects] if ids is None else list(ids)
    missing = [i for i in ids if i not in proxies or not proxies[i].hulls]
    if missing:
        raise InputError(scene.source, "proxies", f"no collision proxies for objects {missing}")


def with_base(proxy: Proxy, base: np.ndarray | None) -> Proxy:
    """``proxy`` with one more convex piece, an object's completed base (:attr:`phiscene.scene.SceneObject.base`,
    (k, 3) local); ``proxy`` itself when ``base`` is ``None`` or already its last piece."""
    if base is None or (proxy.hulls and np.array_equal(proxy.hulls[-1], base)):
        return proxy
    return replace(proxy, hulls=[*proxy.hulls, np.asarray(base, dtype=float)])


def with_bases(scene, proxies: dict[str, Proxy]) -> dict[str, Proxy]:
    """``proxies`` (id -> :class:`Proxy`) with each object's completed base of ``scene`` added to its pieces
    (:func:`with_base`): the collision shapes every simulator and export builds. Objects without a proxy are
    left out of the check here (:func:`check_proxies` names them)."""
    out = dict(proxies)
    for o in scene.objects:
        if o.base is not None and o.id in out:
            out[o.id] = with_base(out[o.id], o.base)
    return out


def scene_proxies(scene, params: ProxyParams, cache_dir: str | Path) -> dict[str, Proxy]:
    """Proxies of every object of a :class:`~phiscene.scene.Scene`, keyed by object id."""
    return {o.id: proxy_for_mesh(o.mesh_path, params, cache_dir) for o in scene.objects}
