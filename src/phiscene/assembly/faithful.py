"""Faithful grounding: the stable pose closest to the input, kept on the supporters the graph names.

The paper's loop (translation-only SDF, free settling, freeze) lets the simulator
take an object wherever it goes: a slightly tilted block slides off its parent,
a fruit rolls off the table. The faithful variant adds these around the
same SDF and settling stages (:func:`phiscene.assembly.assemble.ground_scene`):

1. **Flush correction** before the SDF stage. The stable resting poses of the
   object's convex hull (:func:`resting_normals`: the facets its centre of mass projects into, the stable poses
   of :func:`trimesh.poses.compute_stable_poses`) each rest on one hull facet; the facet whose world normal
   under the input rotation is closest to ``-n`` (``n``: the supporters' surface normal under the object's
   footprint, :func:`support_normal`) is made to face exactly ``-n`` by the
   smallest rotation, about the object's centre of mass, if that rotation is at
   most ``max_flush_angle``. Small orientation errors are corrected, large
   ones (a plank leaning on purpose) are left alone. Objects with a
   ``leans_on`` parent are never flushed.
   An object attached to a wall or the ceiling stays static where it is fixed, but is first made flush with
   its plane, upright on a wall and touching it (:func:`flush_attached`): a wall shelf tilted by a rotation
   error of the input would hold nothing.
2. **Carried**. An object supported from below first moves with its
   supporter (``carry``, :func:`carried`): it is translated as the point of
   the supporter under its centre of mass moved, so it stays over the same
   spot of its supporter; it is not turned with it (a supporter that toppled
   would tip it over too; the flush correction sets its orientation).
   With ``ray`` (off by default) and the photo's camera, it is then moved along the camera ray through it to
   close part of its gap to what holds it from below (it floats, or sinks in; :func:`ray_corrected`): a
   monocular reconstruction errs mostly in depth, and the camera looks down, so an object put too far floats,
   one put too near sinks in.
3. **Guarded settling**. Each start is lowered straight down until it
   touches whatever lies beneath (never through it), then settled with the
   paper's settling. A result is accepted when it met the settling criterion,
   stays when gravity tilts by ``tilt_test`` degrees (no balancing on an edge),
   the placed objects it touches hold it when they are released too (``load_frames``),
   its centre of mass moved horizontally at most the bound (``max_slide`` or
   ``max_slide_frac`` of the bounding-box diagonal, the smaller) and fell at
   most as much below its lowered start (an object that leaves its shelf for
   the floor barely moves horizontally), it turned at
   most ``max_turn`` and it still touches a supporter the graph names. The
   starts, in order: the corrected pose (remedy ``none``, or the paper's
   ``extra_frames`` / ``damping``); where its convex pieces overlap what it
   neither stands nor leans on (its mesh clear of it), the corrected pose moved
   sideways out of that overlap (``clear``), which every later start is then
   taken from; an object that leans, lowered and moved horizontally until it touches what it leans on
   (``lean``: a depth error left it short of its wall); the object's other resting poses within
   ``max_stable_angle``, nearest first, at most ``max_candidates`` of them
   (``stable``); a run with high damping and rolling friction whose resting
   pose is then settled again at normal settings (``damped``); when none of
   these stayed in place, or those that did only balance on an edge, the pose moved onto the nearest upward-facing
   surface of the objects placed before it within ``onto_reach`` (``onto``,
   :func:`onto_start`: a depth error put it beside the shelf it stands on); when every
   start so far went farther than ``max_shift`` or lost its supporters (a jug
   whose base straddles a plate's rim tips over and rolls off the table), or
   none came to rest level (each turned past ``max_turn`` or was still moving: a
   book over its supporter's edge tips onto the floor, its centre of mass barely
   moving), the
   corrected pose shifted horizontally in ``shift_directions`` directions by
   steps of the slide bound up to ``max_shift`` (``shifted``, nearest first;
   its slide is measured from the shifted start; the first that stays in place
   on its supporters ends the search); before the shifted starts, when none came to rest level, the corrected
   pose (with its flush turn undone when that turn exceeded ``max_turn``) once more with the centre of mass
   declared low over its base and flush on the facet it then rests on
   (``ballast``, :func:`ballast_com`: the object is at rest in the photo, so its mass is not that of a uniform
   solid); then, when not even that start rests level and no start came to rest where it was put however
   turned, the same start on its base completed flat (``base``, :func:`flat_base`: its bottom, a hidden side
   the reconstruction guessed round, cannot stand whatever its mass). When none is accepted, a result that is no
   gross failure (turned past ``max_stable_angle`` or moved
   past ``onto_reach``: a table flipped over, a chair thrown across the room) is preferred, even one still moving
   when the settling window closed; among those, the settled result that stayed in place (on its supporters if
   one did: the graph may name the wrong one; :func:`fallback_rank`), else one that holds when tilted (the first
   ``FALLBACK_TILTS``
   of :mod:`phiscene.assembly.assemble` in that order are tilt-tested), closest to the corrected input
   (:func:`closeness`), is taken (``closest``), with the reasons in the certificate. The final pose is always
   the outcome of free settling at normal settings: the object is never frozen where the
   simulator would not leave it. The one exception is an object mostly unseen in the photo (``hidden_share``):
   instead of that fallback it is kept where it was put, static and attached to the ground (``hidden``), when
   something is beneath it, what it touches stays when released and the fallback ends no nearer to the input.
4. **Joint settling**. The sequentially grounded scene is released as a
   whole until every object is at rest (``joint_settle_frames``): a
   supporter is never tested under the load put on it later in the order.
   An object that this release toppled or dropped (``reground``) is grounded
   again from its input on its supporters as they now rest, and the scene is
   settled jointly once more.
   Objects at rest do not move; the log says how far the others went.
5. **A certificate** per object in the assembly log (:func:`certificate`), with the result of releasing
   the whole grounded scene at once (``joint_stable``; sequential settling only tests an object against a
   frozen context).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phiscene.params import Params
from phiscene.transforms import decompose, make_pose, rotation_angle, transform_points

#: Remedy ``ray`` (:func:`ray_corrected`): after the shift the surface under the object must be where it was,
#: within this (m): a shift that takes it off its supporter's edge or onto another object is not made.
RAY_SURFACE_TOL = 0.01

#: Relations whose parent carries the object from below (its surface normal matters for flushing).
BELOW = ("supports", "contains")

#: Upward surface samples per placed object for the remedy ``onto`` (:func:`upward_samples`).
ONTO_SAMPLES = 3000

#: Surface samples of an object's mesh added to its shape's corners when :func:`resting_on` looks for what it rests
#: on (``FaithfulParams.floor_lift``): a box on a round plate overhangs it at every corner, and its hull's corners
#: alone find nothing under them.
RESTING_SAMPLES = 1024

#: Remedy ``base`` (:func:`flat_base`): thicknesses of the band of an object's height, above its lowest point,
#: that is completed flat, thinnest first (shares of the height). The thinnest keeps the mesh closest to its
#: supporter; the thickest is 10 %: a base completed flat through more of the object is no longer its bottom.
BASE_SHARES = (0.01, 0.02, 0.04, 0.07, 0.1)

#: Remedy ``base``: the completed base is sampled on a grid of this many cells across to check that the object's
#: pieces are right above it (:func:`band_covered`).
BASE_CELLS = 12

#: Remedy ``onto``: the footprint is rasterised with at most this many cells across (:func:`fitting_point`).
FIT_CELLS = 48

#: An attached object is moved onto the wall or ceiling it is fixed to when its back is at most this far (m) from
#: it, in front or behind (:func:`flush_attached`); farther, the plane estimate is taken as wrong there.
ATTACH_REACH = 0.1


@dataclass(frozen=True)
class FaithfulParams(Params):
    """Settings of the faithful grounding (off = the paper's loop exactly).

    Attributes
    ----------
    enabled
        Run flush correction, guarded settling and the retry remedies.
    flush
        Rotate each object onto its nearest stable resting facet, flush with its supporters; an attached object
        flush with, upright on and touching the wall or ceiling it is fixed to (:func:`flush_attached`).
    max_flush_angle
        Largest flush rotation applied (deg); larger tilts are taken as intended.
    max_slide
        Largest centre-of-mass displacement accepted from settling (m).
    max_slide_frac
        Same bound as a fraction of the object's bounding-box diagonal (the smaller bound applies).
    max_turn
        Largest rotation accepted from settling (deg).
    carry
        Move each object with its (first placed) supporter from below (:func:`carried`).
    planar_floor
        An object that stands on the floor alone (the ground is its only supporter from below, it leans on
        nothing) and whose lowest point is at most this far (m) above the ground is pushed out of the objects
        placed before it and out of the walls horizontally only (``planar`` of
        :func:`~phiscene.assembly.penetration.resolve_penetration`; 0 = off): its height is the floor's, and a
        vertical push out of a neighbour (a chair tucked under a table top that was lowered onto the floor)
        lifts it off the floor, to topple or fall back into the overlap. Higher up, the graph is the suspect
        (a box a depth error sank into the box it is stacked on, read as standing on the floor) and the push
        is free.
    floor_lift
        Such an object pushed horizontally farther than ``max_slide``, or not clear at all, is lifted straight up
        out of the overlap instead (:func:`~phiscene.assembly.penetration.vertical_clearance`; its input, on the
        floor, inside a piece of furniture: a book a depth error sank into a shelf's bottom board, read as
        standing on the floor, slid out of the shelf across the floor) when that lift is at most this share of
        the horizontal push and at most ``max_shift`` (an office chair tucked under a conference table, wedged in
        its top, is not put on the table, 53 cm up) and leaves it resting on objects placed before it
        (:func:`resting_on`), and those objects are its supporters from then on instead of the ground
        (``sdf_lifted`` in the assembly log). 0 = off.
    joint_settle_frames
        After the loop the whole scene is simulated together until every object is at rest, at most this many
        frames (0 = off): a supporter is then tested under the load placed on it later.
    joint_frames
        After that the whole scene is released for this many frames (0 = no check); each certificate gets
        ``joint_drift`` and ``joint_stable``.
    joint_tol, joint_tol_deg
        ``joint_stable``: the object moved at most this far (m) and turned at most this much (deg).
    max_stable_angle
        Remedy ``stable``: a rejected object is restarted from its resting poses within this angle (deg) of
        its pose, nearest first.
    max_candidates
        At most this many resting poses are tried.
    tilt_test
        A settled result is accepted only if it stays (within ``joint_tol`` / ``joint_tol_deg``) when gravity
        tilts by this many degrees in each horizontal direction
        (:func:`~phiscene.assembly.settle.holds_when_tilted`): an object balanced on an edge stops moving too,
        and topples when the whole scene is released. 0 = off. Not for objects that lean on something: friction
        at two contacts holds them, and a tilt tests that margin rather than their balance.
    tilt_frames
        Frames simulated per tilt direction, at most: a direction ends once the object is past the tolerance, or
        within it and at rest by the settling criterion.
    load_frames
        A settled result that passed the tilt test is accepted only if the placed objects it touches, released
        under it for this many frames, hold it (:func:`~phiscene.assembly.settle.gives_way`: nothing moves more
        than ``joint_tol`` / ``joint_tol_deg``); 0 = off. Sequential settling tests an object against a frozen
        context, and the release of the whole scene is where a supporter that cannot carry its load collapses.
    load_depth
        How many levels of carriers the load test releases: 1 = the placed objects the object touches; each
        further level adds the bodies touching a released carrier with their centre of mass below its (its
        supporters: a plank whose book holds the new box but tips under book and box together).
    contact_tol
        A supporter counts as kept when the object is within this distance of it at rest (m).
    retry_damping
        Linear and angular damping of the ``damped`` retry (Bullet units, in [0, 1)).
    retry_rolling_friction
        Rolling and spinning friction of the ``damped`` retry.
    clear
        Remedy ``clear``: when the corrected pose is rejected, move the object horizontally out of the objects it
        neither stands nor leans on where its collision shape overlaps them deeper than ``contact_tol``, if a move
        of at most ``max_shift`` does (:func:`~phiscene.assembly.settle.clear_overlaps`), settle it from there, and
        take every later start from there. The penetration stage works on the meshes, and convex pieces reach
        beyond them: a potted plant's foliage overlapping a curtain in the simulator, though its mesh is clear of
        it, is knocked over by the simulator's separation before gravity acts. A start that overlaps and is
        accepted all the same is kept (a chair whose pieces reach into the table it stands at is nudged, not
        moved out). The move is recorded (``proxy_clear``).
    lean
        Remedy ``lean``: when the corrected pose of an object that leans (a ``leans_on`` parent) is rejected, move it,
        lowered onto what lies beneath, horizontally until it touches each object or wall it leans on
        (:func:`~phiscene.assembly.settle.close_gaps`, at most ``onto_reach``), and settle it from there: a depth
        error left a book or a plank centimetres short of the wall it leans on, and released there it turns until
        it falls onto it, far from the orientation the input gives it. The move is recorded (``lean_shift``).
    max_shift
        Remedy ``shifted``: an object whose every start went farther than this (m) or lost its supporters, or none
        of whose starts came to rest level (turned past ``max_turn`` or still moving), is restarted from the
        corrected pose shifted horizontally by multiples of the slide bound up to this distance, nearest first
        (0 = off).
    shift_directions
        Directions per shift distance (evenly spaced, the first along +x).
    onto_reach
        Remedy ``onto``: an object that fell or slid off from every start so far is moved onto the nearest
        upward-facing surface of the objects placed before it within this distance (m) of its bottom
        (:func:`onto_start`; 0 = off). A start that had to be lowered farther than this before it touched
        anything fell: it is not in place.
    reground
        After joint settling, an object it toppled (turned past ``max_stable_angle``) or dropped (moved farther
        than ``reground_move``) is grounded again from its input against the rest of the scene as it then rests, and
        the scene settled jointly once more (:func:`~phiscene.assembly.assemble.ground_scene`): its supporters,
        loaded together, may have shifted under it.
    reground_move
        Displacement (m) in joint settling past which an object is grounded again.
    ballast
        Remedy ``ballast``: an object that no start so far brought to rest level (each turned past ``max_turn``,
        was still moving, or only balanced on an edge) is settled once more from the corrected pose (with its
        flush turn undone when that turn exceeded ``max_turn``: chosen for the uniform solid, it contradicts the
        photo, which shows the object at rest as it is) with its centre of mass declared low in its base: over
        the centroid of its base, inside its convex hull, at ``ballast_height`` of its height above its lowest
        point (:func:`ballast_com`), before any shifted start.
        An object at rest in the photo is at rest: a vase whose flowers, as a uniform solid, outweigh its water
        and glass, a potted plant whose foliage outweighs its soil. Kept when accepted like any start; the
        declared centre goes into the grounded scene (:attr:`phiscene.scene.SceneObject.com`), where every
        simulator, metric and export uses it. Its base is its own (a book's whole bottom face), not the part
        of it its supporter holds: a book over its supporter's edge still tips, and is shifted.
    ballast_height
        Height of the declared centre of mass above the object's lowest point, as a share of its height.
    base
        Remedy ``base`` (needs ``ballast``): an object that not even the ``ballast`` start brought to rest level,
        and that no start brought to rest where it was put, however turned (its bottom, a hidden side the
        reconstruction guessed, is round: a jug, a fruit; a can tilted by a rotation error rests upright on its
        flat bottom from its resting pose, and is left to the other remedies), is settled once more
        from the ballast's start, with that centre of mass, on its base completed flat where it stands
        (:func:`flat_base`: one more convex piece of its collision shape, filling the thinnest band of its
        height above its lowest point, of ``BASE_SHARES``, that holds it when tilted), before any shifted
        start. Kept when accepted like any start; the piece goes into the grounded scene
        (:attr:`phiscene.scene.SceneObject.base`), where every simulator, metric and export adds it to the
        object's proxies. The visible mesh is unchanged. Not for an object whose input already has a base.
    ray
        With the photo's camera (:func:`~phiscene.assembly.assemble.ground_scene` ``eye``), close part of an
        object's vertical gap to what holds it (floating, or sunk in) by moving it along the camera ray through its
        centre of mass rather than straight down (:func:`ray_corrected`): a monocular reconstruction errs mostly
        in depth, and an object put too far from the camera also floats (the camera looks down). Off by default:
        on ``clutter`` it lowers the translation error against ground truth and raises the rotation error a
        little, on ``contact`` (errors in every direction alike) it raises the translation error, on the real
        scenes it changes little (README, "Along the camera ray").
    ray_share
        Share of the gap closed along the ray (the rest straight down, as without ``ray``). The gap is not all
        depth error: the levelling, the floor height, scale and hidden-side errors move an object's bottom too,
        and with depth errors and those of comparable size the expected depth error given a gap is about half
        the one that would explain it alone.
    ray_max_shift
        No shift when closing the whole gap along the ray would take one longer than this (m): more than a depth
        error explains (the 90th percentile of real ones is 15.6 cm); the graph or the shape is wrong there.
    ray_min_pitch
        Rays flatter than this (deg below the horizon) move objects sideways more than down: no shift.
    hidden_share
        Remedy ``hidden``: an object that no start held (it would take the ``closest`` fallback) and of which the
        photo's camera sees less than this share (:func:`phiscene.render.visible_shares` on the input scene: its
        pixels in the scene over its pixels alone) is kept where it was put, lowered onto what lies beneath it,
        static, like an object fixed in place (``attached`` to the ground in the grounded scene: left out of
        drift averages, counted with the attached objects); not when nothing is beneath it, when the placed
        objects it touches move when released with it static (:func:`~phiscene.assembly.settle.gives_way`: its
        convex pieces would shove them), or when the fallback's result is nearer to the input
        (:func:`closeness` from the input, a fall below it counted: the corrected pose may have been carried
        far with its supporter, or be lowered far). Its reconstruction is mostly a guess of what the photo does
        not show (a chair tucked under a table, seen by its backrest), and what holds it is in that unseen part:
        its guessed shape topples from every start, and the fallback throws it tens of centimetres. 0 = off;
        without the photo's camera, off.
    """

    _label = "faithful parameters"

    enabled: bool = False
    flush: bool = True
    max_flush_angle: float = 20.0
    max_slide: float = 0.03
    max_slide_frac: float = 0.25
    max_turn: float = 10.0
    carry: bool = True
    planar_floor: float = 0.1
    floor_lift: float = 0.5
    joint_settle_frames: int = 240
    joint_frames: int = 120
    joint_tol: float = 0.005
    joint_tol_deg: float = 1.0
    max_stable_angle: float = 45.0
    max_candidates: int = 3
    tilt_test: float = 4.0
    tilt_frames: int = 60
    load_frames: int = 60
    load_depth: int = 4
    contact_tol: float = 0.004
    retry_damping: float = 0.9
    retry_rolling_friction: float = 0.1
    clear: bool = True
    lean: bool = True
    max_shift: float = 0.09
    shift_directions: int = 6
    onto_reach: float = 0.3
    reground: bool = True
    reground_move: float = 0.09
    ballast: bool = True
    ballast_height: float = 0.25
    base: bool = True
    ray: bool = False
    ray_share: float = 0.5
    ray_max_shift: float = 0.15
    ray_min_pitch: float = 10.0
    hidden_share: float = 0.5

    def check(self) -> None:
        """Reject negative bounds and ``retry_damping`` outside [0, 1) (``ValueError``)."""
        for key in ("max_flush_angle", "max_stable_angle", "max_candidates", "tilt_test", "tilt_frames",
                    "joint_settle_frames", "joint_frames", "joint_tol", "joint_tol_deg", "max_slide",
                    "max_slide_frac", "max_turn", "contact_tol", "retry_rolling_friction", "max_shift",
                    "shift_directions", "onto_reach", "planar_floor", "floor_lift", "load_frames", "reground_move"):
            if getattr(self, key) < 0:
                raise ValueError(f"faithful parameter {key!r} must be >= 0, got {getattr(self, key)}")
        if self.load_depth < 1:
            raise ValueError(f"faithful parameter 'load_depth' must be >= 1, got {self.load_depth}")
        if not 0.0 <= self.retry_damping < 1.0:
            raise ValueError(f"faithful retry_damping must be in [0, 1), got {self.retry_damping}")
        if not 0.0 <= self.ray_share <= 1.0 or self.ray_max_shift < 0 or not 0.0 <= self.ray_min_pitch < 90.0:
            raise ValueError(f"faithful ray settings: ray_share must be in [0, 1] (got {self.ray_share}), "
                             f"ray_max_shift >= 0 (got {self.ray_max_shift}), ray_min_pitch in [0, 90) "
                             f"(got {self.ray_min_pitch})")
        if not 0.0 < self.ballast_height < 1.0:
            raise ValueError(f"faithful ballast_height must be in (0, 1), got {self.ballast_height}")
        if not 0.0 <= self.hidden_share <= 1.0:
            raise ValueError(f"faithful hidden_share must be in [0, 1], got {self.hidden_share}")


def support_normal(mesh_world, parents_world: dict[str, object]) -> np.ndarray:
    """Unit surface normal (3,) of the supporters under an object's footprint.

    Parameters
    ----------
    mesh_world
        The object's mesh in world coordinates (trimesh).
    parents_world
        Supporters carrying it from below: ``"ground"`` maps to ``None`` (normal +z), others to their
        world-frame mesh.

    Returns
    -------
    The area-weighted mean of the upward-facing supporter face normals closest to the object's lowest
    points (within 10% of its height of its lowest point; at a supporter's edge or vertex the most upward of the
    faces that meet there, :func:`closest_faces`), or +z when none face up.
    """
    up = np.array([0.0, 0.0, 1.0])
    objects = {k: m for k, m in parents_world.items() if m is not None}
    if not objects:
        return up
    v = np.asarray(mesh_world.convex_hull.vertices)
    zmin, zmax = v[:, 2].min(), v[:, 2].max()
    low = v[v[:, 2] <= zmin + 0.1 * max(zmax - zmin, 1e-6)]
    acc = np.zeros(3)
    if "ground" in parents_world:
        acc += up * len(low)
    for m in objects.values():
        dist, tri = closest_faces(m, low)
        n = m.face_normals[tri]
        near = dist <= max(0.02, 2 * float(np.min(dist)))
        w = (n[:, 2] > 0.5) & near
        acc += (n[w] * m.area_faces[tri][w, None] / max(float(m.area_faces[tri][w].mean()), 1e-12)
                if w.any() else np.zeros((0, 3))).sum(axis=0)
    norm = np.linalg.norm(acc)
    return acc / norm if norm > 1e-9 else up


#: Barycentric coordinate below which a closest point lies on its triangle's edge or vertex (:func:`closest_faces`).
ON_EDGE = 1e-9


def closest_faces(mesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to a mesh and the face nearest each point, the most upward one where several are.

    A point whose closest point on the mesh lies on an edge or a vertex is as near to every face meeting
    there (the top and the side of a table at its rim); of those the face with the largest normal z is taken,
    the surface a body resting there would bear on.

    Parameters
    ----------
    mesh
        Triangle mesh (trimesh) in world coordinates.
    points : (n, 3) float

    Returns
    -------
    distance : (n,) float
    face : (n,) int
    """
    import igl
    import trimesh

    p = np.ascontiguousarray(points, dtype=float)
    d2, face, closest = igl.point_mesh_squared_distance(p, np.ascontiguousarray(mesh.vertices, dtype=float),
                                                        np.ascontiguousarray(mesh.faces, dtype=np.int64))
    face = np.asarray(face, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):  # degenerate faces give NaN: no tie taken
        bary = trimesh.triangles.points_to_barycentric(mesh.triangles[face], closest)
    rim = np.flatnonzero(np.where(np.isfinite(bary), bary, 1.0).min(axis=1) <= ON_EDGE)
    if len(rim):
        normals_z = mesh.face_normals[:, 2]
        faces = np.asarray(mesh.faces, dtype=np.int64)
        order = np.argsort(faces.ravel(), kind="stable")  # the faces around each vertex, by vertex
        first = np.searchsorted(faces.ravel()[order], np.arange(len(mesh.vertices) + 1))
        for i in rim:
            corners = faces[face[i]][bary[i] > ON_EDGE]  # the edge's two vertices, or the one vertex
            if len(corners) == 0:
                continue
            tied = order[first[corners[0]]:first[corners[0] + 1]] // 3
            for c in corners[1:]:
                tied = np.intersect1d(tied, order[first[c]:first[c + 1]] // 3)
            if len(tied):
                face[i] = tied[np.argmax(normals_z[tied])]
    return np.sqrt(np.maximum(np.asarray(d2, dtype=float), 0.0)), face


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit vector ``a`` to unit vector ``b``."""
    from scipy.spatial.transform import Rotation

    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        return Rotation.from_rotvec(perp / np.linalg.norm(perp) * math.pi).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


#: Faces of a hull with less area than this share of its squared diagonal are slivers that no body rests on
#: (:func:`resting_normals`).
RESTING_MIN_AREA = 1e-12


def resting_normals(hull_points: np.ndarray, com: np.ndarray | None = None) -> np.ndarray:
    """Outward normals (k, 3), local frame, of the facets the object's convex hull can rest on.

    Parameters
    ----------
    hull_points : (n, 3) float
        Points whose convex hull is the object's collision shape (local, unscaled).
    com : (3,) float, optional
        Its centre of mass (local, unscaled); default: the hull's as a uniform solid.
    """
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(hull_points, dtype=float))
    centre = hull.center_mass if com is None else np.asarray(com, dtype=float)
    # A hull rests on a face exactly when the centre of mass projects into it (the sinks of the toppling graph of
    # trimesh.poses.compute_stable_poses, which is what it returns with threshold 0). Found directly: that function
    # walks a networkx graph over every face (43 s for a 12,000-face hull of a reconstructed bowl), and a
    # degenerate face (a sliver of a clipped or decimated hull) gets a NaN landing probability that, toppled into
    # a resting face, drops that face from its answer (the bowl's base).
    n = np.asarray(hull.face_normals, dtype=float)
    tri = np.asarray(hull.triangles, dtype=float)
    proj = centre - np.einsum("ij,ij->i", n, centre - tri[:, 0])[:, None] * n
    with np.errstate(divide="ignore", invalid="ignore"):
        bary = trimesh.triangles.points_to_barycentric(tri, proj)
    diag = float(np.linalg.norm(hull.extents))
    ok = (np.asarray(hull.area_faces) > RESTING_MIN_AREA * diag**2) & np.all(np.isfinite(bary), axis=1)
    rests = np.flatnonzero(ok & np.all(bary >= 0.0, axis=1))
    # one normal per resting facet (coplanar faces the centre projects onto, at a shared edge: the same to 1e-3,
    # as trimesh merges them)
    facets: dict[tuple, np.ndarray] = {}
    for f in rests:
        facets.setdefault(tuple(np.around(n[f], 3)), n[f])
    return np.array(list(facets.values()), dtype=float).reshape(-1, 3)


def resting_candidates(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, up: np.ndarray,
                       max_angle_deg: float) -> list[tuple[np.ndarray, float]]:
    """The pose rotated onto each resting facet within ``max_angle_deg`` of facing ``-up``, nearest first.

    Each candidate is the smallest rotation, about the centre of mass, that makes one resting facet face
    exactly ``-up``.

    Parameters
    ----------
    pose : (4, 4) float
        Input pose (uniform scale allowed).
    normals_local : (k, 3) float
        Resting facet normals (:func:`resting_normals`).
    com_local : (3,) float
        Centre of mass, local frame (the rotation's fixed point).
    up : (3,) float
        Unit supporter normal.
    max_angle_deg
        Facets farther than this from ``-up`` are left out.

    Returns
    -------
    list of (pose (4, 4), angle in deg), sorted by angle; a facet already flush (angle < 1e-9) gives ``pose``
    itself with angle 0.
    """
    if len(normals_local) == 0:
        return []
    R, t, s = decompose(pose)
    world = normals_local @ R.T
    world = world / np.linalg.norm(world, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(world @ -up, -1.0, 1.0)))
    c = com_world(pose, com_local)
    out = []
    for k in np.argsort(angles, kind="stable"):
        angle = float(angles[k])
        if angle > max_angle_deg:
            break
        if angle < 1e-9:
            out.append((pose, 0.0))
            continue
        Q = _rotation_between(world[k], -up)
        out.append((make_pose(Q @ R, c - Q @ (c - t), s), angle))
    return out


def flush_pose(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, up: np.ndarray,
               max_angle_deg: float) -> tuple[np.ndarray, float]:
    """The pose rotated so its nearest resting facet faces ``-up``, about its centre of mass.

    Parameters are those of :func:`resting_candidates`.

    Returns
    -------
    pose : (4, 4) float
        The flushed pose (``pose`` itself when no facet is within ``max_angle_deg``).
    angle
        The rotation applied (deg; 0 when none).
    """
    candidates = resting_candidates(pose, normals_local, com_local, up, max_angle_deg)
    return candidates[0] if candidates else (pose, 0.0)


def flush_attached(pose: np.ndarray, normals_local: np.ndarray, com_local: np.ndarray, hull_local: np.ndarray,
                   normal: np.ndarray, offset: float, wall: bool, max_angle_deg: float,
                   reach: float = ATTACH_REACH) -> tuple[np.ndarray, float, float]:
    """An object fixed to a wall or the ceiling made flush with it, upright, and touching it.

    A poster, a shelf or a clock is fixed with one face against its plane; a rotation error of the input tilts
    that face (and a shelf's top with it, so that nothing can stand on it) and a depth error pushes it into the
    plane or off it. Three steps, each about the centre of mass and each only when small:

    1. the resting facet of its hull nearest to facing the plane is made to face it exactly (smallest
       rotation; skipped beyond ``max_angle_deg``);
    2. on a wall only: a rotation about the wall normal makes the facet nearest to facing down, among those
       roughly perpendicular to the wall, face straight down within the wall's plane (upright; skipped beyond
       ``max_angle_deg``); a ceiling leaves the turn about the vertical free;
    3. a translation along the normal puts its hull's farthest point behind or nearest point in front exactly on
       the plane: always from behind it (nothing fixed to a wall is inside it: a depth error put a wall shelf
       21 cm into its wall, and what stood on it fell to the floor), from in front when at most ``reach`` away.

    Parameters
    ----------
    pose : (4, 4) float
        Input pose (uniform scale allowed).
    normals_local : (k, 3) float
        Resting facet normals of the hull (:func:`resting_normals`), local frame.
    com_local : (3,) float
        Centre of mass, local frame.
    hull_local : (n, 3) float
        Points of the collision shape, local frame.
    normal : (3,) float
        The plane's unit normal, pointing into the room.
    offset
        The plane's offset (points ``p`` on it: ``normal . p + offset = 0``).
    wall
        The plane is a wall (step 2 applies).
    max_angle_deg
        Largest rotation of steps 1 and 2 (deg).
    reach
        Largest translation of step 3 from in front of the plane (m).

    Returns
    -------
    pose : (4, 4) float
        The corrected pose.
    angle
        Rotation applied, steps 1 and 2 together (deg).
    shift
        Signed translation along ``normal`` (m; positive: away from the plane).
    """
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    out = np.array(pose, dtype=float, copy=True)
    candidates = resting_candidates(out, normals_local, com_local, n, max_angle_deg)
    if candidates:
        out = candidates[0][0]
    R, t, s = decompose(out)
    if wall and len(normals_local):
        down = np.array([0.0, 0.0, -1.0]) - (np.array([0.0, 0.0, -1.0]) @ n) * n
        world = normals_local @ R.T
        world = world / np.linalg.norm(world, axis=1, keepdims=True)
        side = world[np.abs(world @ n) < 0.5]
        if np.linalg.norm(down) > 1e-9 and len(side):
            down = down / np.linalg.norm(down)
            proj = side - np.outer(side @ n, n)
            proj = proj / np.maximum(np.linalg.norm(proj, axis=1, keepdims=True), 1e-12)
            k = int(np.argmax(proj @ down))
            angle = math.atan2(float(np.cross(proj[k], down) @ n), float(np.clip(proj[k] @ down, -1.0, 1.0)))
            if abs(math.degrees(angle)) <= max_angle_deg:
                from scipy.spatial.transform import Rotation

                Q = Rotation.from_rotvec(n * angle).as_matrix()
                c = com_world(out, com_local)
                out = make_pose(Q @ R, c - Q @ (c - t), s)
    turned = math.degrees(rotation_angle(decompose(pose)[0], decompose(out)[0]))
    gap = float((transform_points(out, np.asarray(hull_local, dtype=float)) @ n + offset).min())
    shift = -gap if gap < 0.0 or gap <= reach else 0.0
    out[:3, 3] += shift * n
    return out, turned, shift


def shifted_starts(pose: np.ndarray, step: float, max_shift: float,
                   directions: int) -> list[tuple[float, list[np.ndarray]]]:
    """``pose`` translated horizontally by ``step``, ``2 step``, ... up to ``max_shift`` in ``directions`` directions.

    Parameters
    ----------
    pose : (4, 4) float
        The corrected pose.
    step
        Distance between rings (m; the slide bound, so that neighbouring starts cover the plane).
    max_shift
        Largest shift (m).
    directions
        Evenly spaced directions per ring, the first along +x.

    Returns
    -------
    list of (shift in m, its ``directions`` poses (4, 4)), nearest ring first; empty when ``step``,
    ``max_shift`` or ``directions`` is 0.
    """
    if step <= 0 or max_shift <= 0 or directions <= 0:
        return []
    angles = 2 * math.pi * np.arange(directions) / directions
    out = []
    for ring in range(1, int(math.floor(max_shift / step + 1e-9)) + 1):
        r = ring * step
        starts = []
        for a in angles:
            start = np.array(pose, dtype=float, copy=True)
            start[:2, 3] += r * np.array([math.cos(a), math.sin(a)])
            starts.append(start)
        out.append((r, starts))
    return out


def carried(pose: np.ndarray, com_local: np.ndarray, supporter_before: np.ndarray,
            supporter_after: np.ndarray) -> np.ndarray:
    """``pose`` (4, 4) translated as its supporter's point at the object's centre of mass moved.

    Parameters
    ----------
    pose : (4, 4) float
        The object's input pose.
    com_local : (3,) float
        Its centre of mass, local frame.
    supporter_before, supporter_after : (4, 4) float
        The supporter's input and grounded poses.
    """
    c = com_world(pose, com_local)
    moved = transform_points(supporter_after @ np.linalg.inv(supporter_before), c[None])[0]
    out = np.array(pose, dtype=float, copy=True)
    out[:3, 3] += moved - c
    return out


def com_world(pose: np.ndarray, com_local: np.ndarray) -> np.ndarray:
    """World position (3,) of a local point (the centre of mass) under ``pose``."""
    return transform_points(pose, np.asarray(com_local, dtype=float)[None])[0]


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
    from scipy.spatial import Delaunay
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
    inside = Delaunay(points)
    for f in np.linspace(0.0, 1.0, steps + 1)[:-1]:
        p = low + f * (centre - low)
        if inside.find_simplex(p[None])[0] >= 0:
            return transform_points(np.linalg.inv(pose), p[None])[0]
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


def vertical_gap(points: np.ndarray, supporters: dict, ground_height: float, band: float = 0.3,
                 max_points: int = 256, reach: float = 0.05) -> float | None:
    """Signed vertical gap (m) between points of an object (n, 3), world, and the supporters beneath them.

    ``supporters`` maps a name to its world mesh, or to ``None`` for the ground (height ``ground_height``). Each
    mesh supporter's surface under the object's lowest points (those within ``band`` of its height above the
    lowest, at most ``max_points``) is found by casting rays straight down from ``reach`` above each point (so
    a point sunk in less than that still finds the surface it sank into, and a shelf's upper board is not
    taken for the one under it); the gap is the smallest height of a point above the surface under it, over
    the supporters (negative: it sinks in). ``None`` when no supporter lies under it.
    """
    return _under(points, supporters, ground_height, band, max_points, reach)[0]


def _under(points: np.ndarray, supporters: dict, ground_height: float, band: float = 0.3, max_points: int = 256,
           reach: float = 0.05, centre: np.ndarray | None = None) -> tuple[float | None, bool]:
    """:func:`vertical_gap`, and whether a supporter's surface lies under ``centre`` (3,) (the ground is under
    everything; ``True`` when no centre is given)."""
    pts = np.asarray(points, dtype=float)
    lo, hi = float(pts[:, 2].min()), float(pts[:, 2].max())
    low = pts[pts[:, 2] <= lo + band * max(hi - lo, 1e-9)]
    if len(low) > max_points:
        low = low[np.linspace(0, len(low) - 1, max_points).astype(int)]
    origins = low + np.array([0.0, 0.0, reach])
    dirs = np.tile([0.0, 0.0, -1.0], (len(low), 1))
    gaps, held = [], centre is None
    for mesh in supporters.values():
        if mesh is None:
            gaps.append(lo - ground_height)
            held = True
            continue
        hits, rays, _ = mesh.ray.intersects_location(origins, dirs, multiple_hits=False)
        if len(hits):
            gaps.append(float(np.min(low[rays, 2] - hits[:, 2])))
        if not held:
            held = bool(mesh.ray.intersects_any(np.asarray(centre, dtype=float)[None], np.array([[0.0, 0.0, -1.0]]))[0])
    return (min(gaps) if gaps else None), held


def resting_on(points: np.ndarray, com: np.ndarray, candidates: dict, ground_height: float, tol: float,
               reach: float = 0.05) -> list[str]:
    """The candidates an object rests on: those whose surface lies at most ``tol`` (m) under its lowest points.

    ``points`` (n, 3) and ``com`` (3,) are the object's (world); ``candidates`` maps an id to its world mesh.
    A candidate counts when :func:`vertical_gap` to it alone is at most ``tol`` (sunk in a little counts); the
    answer is empty unless one of those lies under the centre of mass as well (the object would tip off them).
    """
    found, held = [], False
    for name, mesh in candidates.items():
        gap, under = _under(points, {name: mesh}, ground_height, reach=reach, centre=com)
        if gap is not None and gap <= tol:
            found.append(name)
            held = held or under
    return found if held else []


def along_ray(pose: np.ndarray, com_local: np.ndarray, eye: np.ndarray, gap: float, share: float,
              min_pitch_deg: float, max_shift: float) -> tuple[np.ndarray, float]:
    """``pose`` moved along the camera ray through its centre of mass so that it drops by ``share * gap`` (m).

    Parameters
    ----------
    pose : (4, 4) float
    com_local : (3,) float
        Centre of mass, local frame (unscaled).
    eye : (3,) float
        The camera's centre, world frame.
    gap
        Its vertical gap to what holds it (m; negative: sunk in).
    share
        Share of the gap closed.
    min_pitch_deg
        Rays flatter than this (deg below the horizon) leave it unchanged.
    max_shift
        Nor is it moved when closing the whole gap would take a shift longer than this (m).

    Returns
    -------
    pose : (4, 4) float
        The moved pose (``pose`` itself when unchanged).
    shift : float
        Signed distance moved along the ray (m, > 0: away from the camera; 0 when unchanged).
    """
    d = com_world(pose, com_local) - np.asarray(eye, dtype=float)
    d = d / np.linalg.norm(d)
    if -d[2] < math.sin(math.radians(min_pitch_deg)):
        return pose, 0.0
    t = float(gap / -d[2])
    if abs(t) > max_shift:
        return pose, 0.0
    t *= share
    out = np.asarray(pose, dtype=float).copy()
    out[:3, 3] += t * d
    return out, t


def ray_corrected(pose: np.ndarray, points_local: np.ndarray, com_local: np.ndarray, supporters: dict,
                  ground_height: float, eye: np.ndarray, fp: FaithfulParams,
                  surface_tol: float = RAY_SURFACE_TOL) -> tuple[np.ndarray, float]:
    """Remedy ``ray``: ``ray_share`` of the object's vertical gap to its supporters closed along the camera ray.

    The gap (:func:`vertical_gap`) is measured again where the shift takes the object: unless the surface under
    it goes on there within ``surface_tol`` (m) of where it was, and still under its centre of mass if it was
    (not over its supporter's edge, not onto another object), the shift is not made.

    Parameters
    ----------
    pose : (4, 4) float
    points_local : (n, 3) float
        Points of its collision shape, local frame (unscaled).
    com_local : (3,) float
    supporters
        Name -> world mesh, or ``None`` for the ground, of what holds it from below.
    ground_height
        Height of the ground (m).
    eye : (3,) float
        The camera's centre, world frame.

    Returns
    -------
    pose : (4, 4) float
    shift : float
        Signed distance moved along the ray (m, > 0: away from the camera; 0 when not moved).
    """
    gap, held = _under(transform_points(pose, points_local), supporters, ground_height,
                       centre=com_world(pose, com_local))
    if gap is None:
        return pose, 0.0
    moved, t = along_ray(pose, com_local, eye, gap, fp.ray_share, fp.ray_min_pitch, fp.ray_max_shift)
    if t == 0.0:
        return pose, 0.0
    after, held_after = _under(transform_points(moved, points_local), supporters, ground_height,
                               centre=com_world(moved, com_local))
    if after is None or abs(after - (gap + moved[2, 3] - pose[2, 3])) > surface_tol or (held and not held_after):
        return pose, 0.0
    return moved, t


def slide_bound(diag: float, fp: FaithfulParams) -> float:
    """The slide (and drop) bound (m) of an object whose bounding-box diagonal is ``diag`` (m)."""
    return min(fp.max_slide, fp.max_slide_frac * diag)


def drop(start: np.ndarray, after: np.ndarray, com_local: np.ndarray) -> float:
    """How far (m) the centre of mass fell from ``start`` (the lowered start, poses (4, 4)); 0 when it rose."""
    return max(0.0, float(com_world(start, com_local)[2] - com_world(after, com_local)[2]))


def within_bounds(before: np.ndarray, after: np.ndarray, com_local: np.ndarray, diag: float,
                  fp: FaithfulParams, start: np.ndarray | None = None) -> tuple[bool, float, float]:
    """Whether settling from ``before`` to ``after`` (poses (4, 4)) stayed within the slide/turn bounds.

    ``start`` is where settling began, lowered onto what lies beneath (default ``before``): from there the
    centre of mass may fall at most the slide bound too. An object that leaves its shelf and lands on the
    floor below barely moves horizontally; the fall is what gives it away.

    Returns
    -------
    ok, moved (m, the larger of the horizontal centre-of-mass displacement from ``before`` and the fall from
    ``start``), turned (deg)
    """
    step = com_world(after, com_local) - com_world(before, com_local)
    slid = float(np.linalg.norm(step[:2]))  # sliding/rolling; the drop onto the supporter (lowering) is free
    moved = max(slid, drop(before if start is None else start, after, com_local))
    turned = math.degrees(rotation_angle(decompose(before)[0], decompose(after)[0]))
    return moved <= slide_bound(diag, fp) and turned <= fp.max_turn, moved, turned


def closeness(reference: np.ndarray, result: np.ndarray, com_local: np.ndarray, diag: float,
              start: np.ndarray | None = None) -> float:
    """How far settling took an object from ``reference`` (m): horizontal centre-of-mass shift plus the arc its
    rotation sweeps at half the bounding-box diagonal (``diag`` / 2 times the angle in rad), plus how far it fell
    from ``start`` (the lowered start, when given; the drop onto a supporter is free, as in
    :func:`within_bounds`).
    """
    step = com_world(result, com_local) - com_world(reference, com_local)
    turned = rotation_angle(decompose(reference)[0], decompose(result)[0])
    fell = drop(start, result, com_local) if start is not None else 0.0
    return float(np.linalg.norm(step[:2]) + 0.5 * diag * turned + fell)


def upward_samples(mesh_world, n: int, seed: int, min_normal_z: float = 0.8) -> np.ndarray:
    """Points (k, 3) sampled (area-weighted, seeded) on the upward-facing faces of a world-frame mesh.

    Faces whose unit normal has a z component below ``min_normal_z`` (walls, undersides, steep slopes) are
    left out; ``k`` is 0 when none faces up.
    """
    import trimesh

    faces = np.flatnonzero(np.asarray(mesh_world.face_normals)[:, 2] >= min_normal_z)
    if len(faces) == 0 or n <= 0:
        return np.zeros((0, 3))
    sub = mesh_world.submesh([faces], append=True)
    pts, _ = trimesh.sample.sample_surface(sub, n, seed=seed)
    return np.asarray(pts, dtype=float)


def fitting_point(level_xy: np.ndarray, footprint_xy: np.ndarray, start_xy: np.ndarray) -> np.ndarray | None:
    """The point nearest to ``start_xy`` at which an object's footprint lies wholly over a sampled surface.

    The surface (its samples of one level) is rasterised at its sampling spacing (holes between samples closed,
    then one cell taken off its rim: a cell holding an edge sample reaches past the edge), eroded by the
    footprint (:func:`scipy.ndimage.binary_erosion`: the Minkowski difference, so an elongated object fits along
    a narrow shelf, not across it), and the nearest cell centre that remains is returned: the smallest
    horizontal motion that puts the object wholly over the surface.

    Parameters
    ----------
    level_xy : (k, 2) float
        Surface samples (xy) of one level.
    footprint_xy : (m, 2) float
        The object's collision-shape points (xy) relative to the point being placed (its centre of mass).
    start_xy : (2,) float
        Where that point is now.

    Returns
    -------
    (2,) float, or ``None`` when the footprint fits nowhere (a surface smaller than the object) or the surface
    has fewer than 4 samples.
    """
    from scipy import ndimage
    from scipy.spatial import Delaunay, QhullError, cKDTree

    level_xy = np.asarray(level_xy, dtype=float).reshape(-1, 2)
    rel = np.asarray(footprint_xy, dtype=float).reshape(-1, 2)
    if len(level_xy) < 4 or len(rel) < 3:
        return None
    spacing = float(np.median(cKDTree(level_xy).query(level_xy, k=2)[0][:, 1]))
    # the sampling spacing, but at most FIT_CELLS cells across the footprint and 8 FIT_CELLS across the surface:
    # the erosion costs (surface cells) x (footprint cells)
    reach_xy = float(np.max(np.ptp(level_xy, axis=0)))
    size = float(np.max(np.ptp(rel, axis=0)))
    cell = max(spacing, 1e-3, size / FIT_CELLS, reach_xy / (8 * FIT_CELLS))
    start = np.asarray(start_xy, dtype=float)
    # the grid is anchored so that ``start_xy`` is a cell centre: a straight move along an axis stays on its line
    lo = start - cell * (0.5 + np.ceil((start - level_xy.min(axis=0) + 2 * cell) / cell))
    shape = np.ceil((np.maximum(level_xy.max(axis=0), start) + 2 * cell - lo) / cell).astype(int) + 1
    idx = np.floor((level_xy - lo) / cell).astype(int)
    surface = np.zeros(shape, dtype=bool)
    surface[idx[:, 0], idx[:, 1]] = True
    surface = ndimage.binary_closing(surface, structure=np.ones((3, 3), dtype=bool))
    # a cell holding a sample may reach a cell's width past the surface's edge: one cell in from the edge
    surface = ndimage.binary_erosion(surface, structure=ndimage.generate_binary_structure(2, 1))
    # the footprint as cell offsets: every cell with its centre or a corner inside the footprint's convex hull
    half = int(np.ceil(np.abs(rel).max() / cell)) + 1
    grid = np.arange(-half, half + 1)
    oi, oj = np.meshgrid(grid, grid, indexing="ij")
    inside = np.zeros(oi.shape, dtype=bool)
    try:
        hull = Delaunay(rel)
    except QhullError:  # degenerate footprint (all points on a line): its bounding box
        hull = None
    for di, dj in ((0.0, 0.0), (-0.5, -0.5), (-0.5, 0.5), (0.5, -0.5), (0.5, 0.5)):
        pts = np.column_stack([(oi.ravel() + di) * cell, (oj.ravel() + dj) * cell])
        if hull is not None:
            hit = hull.find_simplex(pts) >= 0
        else:
            hit = np.all((pts >= rel.min(axis=0)) & (pts <= rel.max(axis=0)), axis=1)
        inside |= hit.reshape(oi.shape)
    fits = ndimage.binary_erosion(surface, structure=inside, border_value=0)
    cells = np.argwhere(fits)
    if len(cells) == 0:
        return None
    centres = lo + (cells + 0.5) * cell
    return centres[int(np.argmin(np.linalg.norm(centres - start, axis=1)))]


def onto_start(pose: np.ndarray, com_local: np.ndarray, points_world: np.ndarray, surfaces: np.ndarray,
               reach: float, clearance: float, planes=()) -> tuple[np.ndarray, float] | None:
    """``pose`` moved onto the nearest supporting surface: wholly over it by the smallest motion, just above it.

    An object carried from below whose input is off its supporter (a vase beside the wall shelf it stands on,
    a can hanging over the board's edge: the depth error of a single image) falls when released. Its
    supporter's top is found as the upward-facing surface point nearest to the bottom of the object (within
    ``reach`` m); the object is moved horizontally by the smallest motion that puts its whole footprint over the
    samples of that level (:func:`fitting_point`), or, when it fits nowhere there (a surface narrower than the
    object), over that point pulled inward from the edge by mean-shift steps; and vertically so that its lowest
    point is ``clearance`` m above the surface.

    Parameters
    ----------
    pose : (4, 4) float
        The corrected pose.
    com_local : (3,) float
        Centre of mass, local frame.
    points_world : (n, 3) float
        The object's collision-shape points under ``pose``.
    surfaces : (k, 3) float
        Upward surface samples of the candidate supporters (:func:`upward_samples`).
    reach
        Largest distance (m) between the object's bottom and the surface.
    clearance
        Gap left under the object (m).
    planes
        Walls (:class:`~phiscene.scene.Plane`): surface points behind one are left out (an estimated wall may cut
        through the shelf fixed to it), and in the fallback those closer to one than the object's footprint
        radius.

    Returns
    -------
    (pose (4, 4), horizontal shift in m), or ``None`` when no surface is within reach.
    """
    pts = np.asarray(points_world, dtype=float)
    footprint = max(0.5 * float(np.max(np.ptp(pts[:, :2], axis=0))), 1e-3 / 1.5)  # footprint radius
    surfaces = np.asarray(surfaces, dtype=float).reshape(-1, 3)
    for plane in planes:
        surfaces = surfaces[plane.signed_distance(surfaces) >= 0.0]
    if len(surfaces) == 0:
        return None
    c = com_world(pose, com_local)
    low = float(pts[:, 2].min())
    bottom = np.array([c[0], c[1], low])
    d = np.linalg.norm(surfaces - bottom, axis=1)
    k = int(np.argmin(d))
    if d[k] > reach:
        return None
    level = surfaces[np.abs(surfaces[:, 2] - surfaces[k, 2]) <= 0.01]
    target = fitting_point(level[:, :2], pts[:, :2] - c[:2], c[:2])
    if target is None or np.linalg.norm(target - c[:2]) > reach:
        # fits nowhere within reach: the nearest point pulled inward, mean-shift steps with a kernel of 1.5
        # footprint radii (the shift converges slowly near the kernel radius), clear of the walls
        for plane in planes:
            level = level[plane.signed_distance(level) >= footprint]
        if len(level) == 0:
            return None
        target = level[int(np.argmin(np.linalg.norm(level - bottom, axis=1))), :2].copy()
        for _ in range(10):  # mean shift: away from the edge, towards where the surface lies around the point
            near = level[np.linalg.norm(level[:, :2] - target, axis=1) <= 1.5 * footprint]
            if len(near) == 0:
                break
            target = near[:, :2].mean(axis=0)
    out = np.array(pose, dtype=float, copy=True)
    out[:2, 3] += target - c[:2]
    out[2, 3] += surfaces[k, 2] + clearance - low
    return out, float(np.linalg.norm(target - c[:2]))


def lost_supporters(below: list[str], leaning: list[str], touching: list[str]) -> list[str]:
    """Supporters the object lost at rest: all of ``below`` when it touches none of them, plus untouched ``leaning``.

    An object carried from below needs one of its carriers (the graph may name a table that ``contains`` a
    jug standing on a plate); each object it leans on must still be touched.
    """
    lost = [] if not below or any(p in touching for p in below) else list(below)
    return lost + [p for p in leaning if p not in touching]


def fallback_rank(attempt: dict) -> tuple:
    """Sort key of a settling attempt when none was accepted (smallest first).

    No gross failure (a table flipped upside down, a chair thrown across the room) if any start avoided one,
    even one still moving when the settling window closed; then a settled result; then one that stayed in place
    (``in_place``, judged from its own start); then one on its supporters (``stayed``), one that holds when tilted
    (``robust``), one its carriers hold (``loaded``); then the closest to the corrected input (``cost``, m).

    ``attempt`` holds those keys and ``result`` (a settling result with ``settled``).
    """
    return (attempt["gross"], not attempt["result"].settled, not attempt["in_place"], not attempt["stayed"],
            not attempt["robust"], not attempt["loaded"], attempt["cost"])


def gross_failure(moved: float, turned_deg: float, fp: FaithfulParams) -> bool:
    """Whether a motion is a gross failure: turned past ``max_stable_angle`` (beyond any resting pose tried) or
    moved past ``onto_reach`` (farther than the ``onto`` remedy moves): a crate flipped upside down, a chair thrown
    across the room."""
    return turned_deg > fp.max_stable_angle or moved > fp.onto_reach


def gross_failures(certificates: dict[str, dict], fp: FaithfulParams) -> dict[str, str]:
    """The objects whose final pose is a gross failure from their input (:func:`gross_failure` of the certificate's
    ``displacement`` and ``rotation_change``), each with what happened to it."""
    return {oid: f"turned {c['rotation_change']:.0f} deg and moved {c['displacement']:.2f} m from its input "
                 f"(remedy {c['remedy']})"
            for oid, c in certificates.items() if gross_failure(c["displacement"], c["rotation_change"], fp)}


def certificate(settled: bool | None, remedy: str, below: list[str], leaning: list[str], touching: list[str],
                displacement: float, rotation_change_deg: float, flush_angle: float,
                reason: str = "") -> dict:
    """Per-object certificate for the assembly log.

    Parameters
    ----------
    settled
        Whether the final pose met the settling criterion.
    remedy
        What produced the final pose: ``none``, ``extra_frames``, ``damping`` (the paper's remedies),
        ``stable``, ``damped``, ``shifted`` (faithful retries), ``closest`` (no start was accepted: the closest settled
        result), ``attached``.
    below, leaning
        The graph's supporters of the object from below (``supports``, ``contains``) and those it leans on.
    touching
        Objects (``ground`` included) within ``contact_tol`` of it at rest.
    displacement, rotation_change_deg
        Centre-of-mass displacement (m) and rotation change (deg) from the input pose.
    flush_angle
        Flush rotation applied (deg).
    reason
        Why a remedy beyond the paper's was needed.
    """
    lost = lost_supporters(below, leaning, touching)
    return {"settled": settled, "remedy": remedy, "supporters": list(below) + list(leaning),
            "touching": sorted(touching),
            "supporters_kept": not lost, "lost": lost, "displacement": round(float(displacement), 9),
            "rotation_change": round(float(rotation_change_deg), 6), "flush_angle": round(float(flush_angle), 6),
            "reason": reason}
