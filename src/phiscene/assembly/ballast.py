"""Remedies ``ballast`` and ``base`` of faithful grounding: the mass and the bottom a reconstruction got wrong.

An object at rest in the photo that no start brings to rest level is given a centre of mass low over its base
(:func:`ballast_com`), then its base completed flat where it stands (:func:`flat_base`). See
:mod:`phiscene.assembly.faithful` for when each is tried.
"""

from __future__ import annotations

import math

import numpy as np

from phiscene.assembly.resting import com_world
from phiscene.transforms import transform_points

#: Remedy ``base`` (:func:`flat_base`): thicknesses of the band of an object's height, above its lowest point,
#: that is completed flat, thinnest first (shares of the height). The thinnest keeps the mesh closest to its
#: supporter; the thickest is 10 %: a base completed flat through more of the object is no longer its bottom.
BASE_SHARES = (0.01, 0.02, 0.04, 0.07, 0.1)


#: Remedy ``base``: the completed base is sampled on a grid of this many cells across to check that the object's
#: pieces are right above it (:func:`band_covered`).
BASE_CELLS = 12


def ballast_com(pose: np.ndarray, com_local: np.ndarray, hull_local: np.ndarray, share: float,
                base_band: float = 0.05, steps: int = 16) -> np.ndarray | None:
    """A lower centre of mass for an object at ``pose``, over its base, inside its convex hull.

    The mass of an object at rest in a photo sits low, in its base (a vase's water and glass, a pot's soil);
    a uniform solid puts it where the bulk of the shape is (the flowers). The declared centre lies at
    ``share`` of the object's height above its lowest point, over the centroid of its base (the convex hull of
    its vertices within ``base_band`` of its height above the lowest point, seen from above); when that point is
    outside the hull, the nearest point inside on the segment from it to the current centre.

    Parameters
    ----------
    pose : (4, 4) float
        The object's pose (uniform scale allowed).
    com_local : (3,) float
        Its centre of mass as it is (the uniform solid's, or one declared before), local frame (unscaled).
    hull_local : (k, 3) float
        Vertices of its convex hull (or of its convex pieces), local frame (unscaled).
    share
        Height of the declared centre above the lowest point, as a share of the object's height at ``pose``.
    base_band
        Thickness of the base, as a share of the height.
    steps
        Points tried along the segment towards the current centre.

    Returns
    -------
    The declared centre of mass (3,), local frame (unscaled); ``None`` when the current centre is not higher
    than the target or no point tried is inside the hull.
    """
    from shapely.geometry import MultiPoint

    points = transform_points(pose, np.asarray(hull_local, dtype=float))
    lo, hi = float(points[:, 2].min()), float(points[:, 2].max())
    target = lo + share * (hi - lo)
    centre = com_world(pose, com_local)
    if centre[2] <= target + 1e-6:
        return None
    base = points[points[:, 2] <= lo + base_band * (hi - lo), :2]
    foot = MultiPoint([tuple(p) for p in base]).convex_hull.centroid
    low = np.array([foot.x, foot.y, target])
    facets = hull_facets(points)
    if facets is None:
        return None
    for f in np.linspace(0.0, 1.0, steps + 1)[:-1]:
        p = low + f * (centre - low)
        if np.all(facets[:, :3] @ p + facets[:, 3] <= HULL_INSIDE_TOL):
            return transform_points(np.linalg.inv(pose), p[None])[0]
    return None


#: :func:`ballast_com`: a point this far (m) outside a facet plane of the convex hull still counts as inside it.
HULL_INSIDE_TOL = 1e-12


def hull_facets(points: np.ndarray) -> np.ndarray | None:
    """The facet half-spaces (f, 4) of the convex hull of ``points`` (k, 3), ``n . p + d <= 0`` inside (qhull), or
    ``None`` when qhull finds no hull even with joggled input (points in one plane get a joggled sliver).

    The vertices of a reconstruction's convex pieces hold near-duplicates (pieces that share a face); qhull's
    Delaunay triangulation of them can fail ("wide merge", a Gen3DSR reconstruction's curtain) where the hull
    holds: it is retried with joggled input (``QJ``) before giving up.
    """
    from scipy.spatial import ConvexHull, QhullError

    for options in (None, "QJ"):
        try:
            return ConvexHull(points, qhull_options=options).equations
        except (QhullError, ValueError):
            continue
    return None


def flat_base(pose: np.ndarray, hulls_local: list[np.ndarray], com_local: np.ndarray, up: np.ndarray,
              tilt_deg: float, shares: tuple[float, ...] = BASE_SHARES) -> tuple[np.ndarray, float] | None:
    """The object's base completed flat at ``pose``: one convex piece under it on which it stands level.

    A reconstruction guesses the hidden bottom of an object; a jug or a fruit guessed round underneath cannot
    stand where the photo shows it at rest, whatever its mass. The piece is the convex hull of the vertices of
    the object's convex pieces within a band of its height above its lowest point (along ``up``) and of their
    projections onto the plane through that point normal to ``up``: the bottom cut flat, filled in rather than
    cut off (the visible mesh keeps its shape and still touches its supporter). The thinnest band of ``shares``
    (shares of the height) is taken whose flat base

    - holds the centre of mass inside it with a margin: at least its height above the base times the tangent
      of twice ``tilt_deg``, so that it holds the object when gravity tilts by ``tilt_deg`` (the settling tilt
      test);
    - only fills the band: the object's pieces are within the band above every point of it
      (:func:`band_covered`). A table's or a chair's feet span no base: that piece would be a slab between its
      legs, under whatever stands beneath it.

    Parameters
    ----------
    pose : (4, 4) float
        The object's pose (uniform scale allowed), level where it should rest.
    hulls_local : list of (k, 3) float
        Vertices of its convex pieces, local frame (unscaled).
    com_local : (3,) float
        Its centre of mass, local frame (unscaled).
    up : (3,) float
        Unit normal of the surface it rests on (world).
    tilt_deg
        The tilt the base must withstand (deg).
    shares
        Band thicknesses tried, thinnest first, as shares of the object's height along ``up``.

    Returns
    -------
    ``(points, share)``: the piece's vertices (m, 3), local frame (unscaled), and the band share taken; ``None``
    when no band holds the centre of mass.
    """
    from scipy.spatial import ConvexHull, QhullError
    from shapely.geometry import MultiPoint, Point

    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    pieces = [transform_points(pose, np.asarray(h, dtype=float)) for h in hulls_local]
    points = np.vstack(pieces)
    facets = []  # each piece's half-spaces (f, 4), once for every band tried
    for piece in pieces:
        try:
            facets.append(ConvexHull(piece).equations)
        except (QhullError, ValueError):
            continue
    heights = points @ up
    lo, tall = float(heights.min()), float(np.ptp(heights))
    centre = com_world(pose, com_local)
    lever = float(centre @ up) - lo
    if tall <= 0.0 or lever <= 0.0:
        return None
    e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    need = lever * math.tan(math.radians(2.0 * tilt_deg))
    at = Point(float(centre @ e1), float(centre @ e2))
    for share in shares:
        band = points[heights <= lo + share * tall]
        if len(band) < 3:
            continue
        flat = band - np.outer(band @ up - lo, up)
        foot = MultiPoint([(float(p @ e1), float(p @ e2)) for p in flat]).convex_hull
        if foot.geom_type != "Polygon" or not foot.contains(at) or foot.exterior.distance(at) < need:
            continue
        if not band_covered(foot, e1, e2, up, lo, share * tall, facets):
            continue
        piece = np.unique(np.vstack([band, flat]).round(12), axis=0)
        if np.linalg.matrix_rank(piece - piece.mean(axis=0), tol=1e-9) < 3:
            continue
        return transform_points(np.linalg.inv(pose), piece), float(share)
    return None


def band_covered(foot, e1: np.ndarray, e2: np.ndarray, up: np.ndarray, lo: float, band: float,
                 facets: list[np.ndarray], cells: int = BASE_CELLS) -> bool:
    """Whether convex pieces lie within ``band`` (m) above every point of the polygon ``foot`` (shapely, in the
    coordinates ``(p . e1, p . e2)`` of the plane ``p . up = lo``). Each piece is given by its facets' half-spaces
    (``facets``: per piece (f, 4) rows ``n, d`` with ``n . x + d <= 0`` inside, world frame: Qhull's
    ``equations``).

    The polygon is sampled on a grid of ``cells`` across (its centroid when no grid point falls inside); a ray
    along ``up`` from each sample must enter a piece at most ``band`` above the plane. The entry of a ray into a
    convex piece is the largest of its entries into the half-spaces of the piece's facets.
    """
    from shapely import contains_xy

    x0, y0, x1, y1 = foot.bounds
    gx, gy = np.meshgrid(np.linspace(x0, x1, cells + 2)[1:-1], np.linspace(y0, y1, cells + 2)[1:-1])
    keep = contains_xy(foot, gx.ravel(), gy.ravel())
    uv = np.c_[gx.ravel()[keep], gy.ravel()[keep]]
    if not len(uv):
        uv = np.array([[foot.centroid.x, foot.centroid.y]])
    starts = uv[:, :1] * e1 + uv[:, 1:] * e2 + lo * up  # (n, 3) on the plane
    entry = np.full(len(starts), np.inf)
    for eq in facets:
        normal, offset = eq[:, :3], eq[:, 3]
        along = normal @ up  # (f,)
        side = starts @ normal.T + offset  # (n, f): > 0 outside the facet's half-space
        bound = -side / np.where(along == 0.0, 1.0, along)  # (n, f): t on each plane
        lower = np.where(along < 0, bound, -np.inf).max(axis=1)
        upper = np.where(along > 0, bound, np.inf).min(axis=1)
        parallel_out = (side > 0) & (along == 0.0)
        hit = (lower <= upper) & ~parallel_out.any(axis=1) & (upper >= 0.0)
        entry = np.where(hit, np.minimum(entry, np.maximum(lower, 0.0)), entry)
    return bool(np.all(entry <= band + 1e-9))
