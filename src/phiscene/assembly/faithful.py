"""Faithful grounding: the stable pose closest to the input, kept on the supporters the graph names.

The paper's loop (translation-only SDF, free settling, freeze) lets the simulator
take an object wherever it goes: a slightly tilted block slides off its parent,
a fruit rolls off the table. The faithful variant adds these around the
same SDF and settling stages (:func:`phiscene.assembly.assemble.ground_scene`):

1. **Flush correction** before the SDF stage. The stable resting poses of the
   object's convex hull (:func:`resting.resting_normals`: the facets its centre of mass projects into, the stable poses
   of :func:`trimesh.poses.compute_stable_poses`) each rest on one hull facet; the facet whose world normal
   under the input rotation is closest to ``-n`` (``n``: the supporters' surface normal under the object's
   footprint, :func:`resting.support_normal`) is made to face exactly ``-n`` by the
   smallest rotation, about the object's centre of mass, if that rotation is at
   most ``max_flush_angle``. Small orientation errors are corrected, large
   ones (a plank leaning on purpose) are left alone. Objects with a
   ``leans_on`` parent are never flushed.
   An object attached to a wall or the ceiling stays static where it is fixed, but is first made flush with
   its plane, upright on a wall and touching it (:func:`resting.flush_attached`): a wall shelf tilted by a rotation
   error of the input would hold nothing.
2. **Carried**. An object supported from below first moves with its
   supporter (``carry``, :func:`starts.carried`): it is translated as the point of
   the supporter under its centre of mass moved, so it stays over the same
   spot of its supporter; it is not turned with it (a supporter that toppled
   would tip it over too; the flush correction sets its orientation). With
   ``carry_sideways: off_support`` (``phi_scene``'s) it takes only the vertical part of that move while
   it still stands over the moved supporter where the photo put it.
   With ``ray`` (off by default) and the photo's camera, it is then moved along the camera ray through it to
   close part of its gap to what holds it from below (it floats, or sinks in; :func:`starts.ray_corrected`): a
   monocular reconstruction errs mostly in depth, and the camera looks down, so an object put too far floats,
   one put too near sinks in.
3. **Guarded settling** (:mod:`phiscene.assembly.guarded`). Each start is lowered straight down until it
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
   :func:`starts.onto_start`: a depth error put it beside the shelf it stands on); when every
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
   (``ballast``, :func:`ballast.ballast_com`: the object is at rest in the photo, so its mass is not that of a uniform
   solid); then, when not even that start rests level and no start came to rest where it was put however
   turned, the same start on its base completed flat (``base``, :func:`ballast.flat_base`: its bottom, a hidden side
   the reconstruction guessed round, cannot stand whatever its mass). When still none is accepted and a start came
   to rest in place and holds when tilted but falls, or tips what carries it, when its carriers are released under
   it (a body moves past the slide bound or turns past ``max_turn`` in that load test: a box on a book that
   overhangs its own supporter), that rest moved horizontally half and then all of the way from its centre of mass
   to its carriers' (``centre_load``, remedy ``centred``: the load over its carriers' centre adds no torque that
   tips them). When none is accepted, a result that is no
   gross failure (turned past ``max_stable_angle`` or moved
   past ``onto_reach``: a table flipped over, a chair thrown across the room) is preferred, even one still moving
   when the settling window closed; among those, the settled result that stayed in place (on its supporters if
   one did: the graph may name the wrong one; :func:`certify.fallback_rank`), else one that holds when tilted (the first
   ``FALLBACK_TILTS``
   of :mod:`phiscene.assembly.guarded` in that order are tilt-tested), closest to the corrected input
   (:func:`certify.closeness`), is taken (``closest``), with the reasons in the certificate. The final pose is always
   the outcome of free settling at normal settings: the object is never frozen where the
   simulator would not leave it. The one exception is an object mostly unseen in the photo (``hidden_share``):
   instead of that fallback it is kept where it was put, static and attached to the ground (``hidden``), when
   something is beneath it, what it touches stays when released and the fallback ends no nearer to the input.
   So is, on the same conditions, an object that the fallback would carry across the scene (``hold_far``: farther
   than its own size and ``onto_reach``), reported as not settled (``held``).
4. **Joint settling**. The sequentially grounded scene is released as a
   whole until every object is at rest (``joint_settle_frames``): a
   supporter is never tested under the load put on it later in the order.
   An object that this release toppled or dropped (``reground``) is grounded
   again from its input on its supporters as they now rest, and the scene is
   settled jointly once more.
   Objects at rest do not move; the log says how far the others went.
5. **A certificate** per object in the assembly log (:func:`certify.certificate`), with the result of releasing
   the whole grounded scene at once (``joint_stable``; sequential settling only tests an object against a
   frozen context).
"""

from __future__ import annotations

from dataclasses import dataclass

from phiscene.params import Params
from phiscene.tolerances import DRIFT_LIFT

#: Relations whose parent carries the object from below (its surface normal matters for flushing).
BELOW = ("supports", "contains")
#: ``FaithfulParams.carry_sideways``: how much of its supporter's horizontal move a supported object takes.
CARRY_SIDEWAYS = ("always", "off_support")


@dataclass(frozen=True)
class FaithfulParams(Params):
    """Settings of the faithful grounding (off = the paper's loop exactly).

    Attributes
    ----------
    enabled
        Run flush correction, guarded settling and the retry remedies.
    flush
        Rotate each object onto its nearest stable resting facet, flush with its supporters; an attached object
        flush with, upright on and touching the wall or ceiling it is fixed to (:func:`resting.flush_attached`).
    max_flush_angle
        Largest flush rotation applied (deg); larger tilts are taken as intended.
    max_slide
        Largest centre-of-mass displacement accepted from settling (m).
    max_slide_frac
        Same bound as a fraction of the object's bounding-box diagonal (the smaller bound applies).
    max_turn
        Largest rotation accepted from settling (deg).
    carry
        Move each object with its (first placed) supporter from below (:func:`starts.carried`).
    carry_sideways
        ``off_support`` (the default): only the vertical part of that move
        (:func:`starts.carried_vertically`) while the object's centre of mass, and the points ``carry_margin`` of
        its horizontal half-extent from it along x and y, still lie over the moved supporter
        (:func:`beneath.over_support`), the whole move otherwise; ``always``: the whole move (before d401e72).
        The supporter's horizontal move is its own correction (pushed out of a neighbour, a wall); what stands
        on it keeps where the photo put it while it can stand there (a lamp on a side table pushed 12 cm out of a
        sofa).
    carry_margin
        That share (>= 0; 0: the centre of mass alone).
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
        Such an object pushed horizontally farther than ``max_slide``, or not clear at all, is moved up and out
        of the overlap instead (:func:`~phiscene.assembly.penetration.upward_clearance`: straight up, or up and
        sideways, then lowered onto what lies there; its input, on the
        floor, inside a piece of furniture: a book a depth error sank into a shelf's bottom board, read as
        standing on the floor, slid out of the shelf across the floor) when that lift is at most this share of
        the horizontal push and at most ``max_shift`` (an office chair tucked under a conference table, wedged in
        its top, is not put on the table, 53 cm up) and leaves it resting on objects placed before it
        (:func:`beneath.resting_on`), and those objects are its supporters from then on instead of the ground
        (``sdf_lifted`` in the assembly log). 0 = off.
    joint_settle_frames
        After the loop the whole scene is simulated together until every object is at rest, at most this many
        frames (0 = off): a supporter is then tested under the load placed on it later.
    joint_frames
        After that the whole scene is released for this many frames (0 = no check); each certificate gets
        ``joint_drift`` and ``joint_stable``.
    joint_drop
        That release lifts every free object by this much (m) first, as the drift protocol does
        (``metrics.physical.upward_offset``, 2 mm), so that ``joint_stable`` comes from the drift metric's release: an
        object resting on another that the release in place leaves alone may be thrown 48 cm by that drop. Default: the
        protocol's lift (:data:`phiscene.tolerances.DRIFT_LIFT`); 0 = released in place (before 688279f).
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
    fixtures
        An attached object that overlaps one attached before it deeper than ``contact_tol`` (a curtain through
        the window behind it, two posters through each other) is moved the shortest way clear of it, never into
        the wall or ceiling holding it (:mod:`phiscene.assembly.fixtures`). Recorded as ``fixture_clear``.
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
        (:func:`starts.onto_start`; 0 = off). A start that had to be lowered farther than this before it touched
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
        point (:func:`ballast.ballast_com`), before any shifted start.
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
        (:func:`ballast.flat_base`: one more convex piece of its collision shape, filling the thinnest band of its
        height above its lowest point, of :data:`ballast.BASE_SHARES`, that holds it when tilted), before any shifted
        start. Kept when accepted like any start; the piece goes into the grounded scene
        (:attr:`phiscene.scene.SceneObject.base`), where every simulator, metric and export adds it to the
        object's proxies. The visible mesh is unchanged. Not for an object whose input already has a base.
    centre_load
        Remedy ``centred``: when no start is accepted and one came to rest in place and holds when tilted, but it
        or its carriers move past the slide bound or turn past ``max_turn`` when they are released under it
        (:func:`~phiscene.assembly.settle.gives_way`; a carrier that only rocks is left to joint settling), that
        rest is tried again moved horizontally ``CENTRE_FRACTIONS`` (:mod:`phiscene.assembly.guarded`) of the way
        from the object's centre of mass to its carriers' (the free placed objects it touches there whose centre
        of mass lies lower than its own, mass-weighted), at most ``max_shift``, nearest first. Without it such an
        object takes the fallback at rest on carriers that tip once the scene is released together: a tall stack
        then collapses in joint settling.
    ray
        With the photo's camera (:func:`~phiscene.assembly.assemble.ground_scene` ``eye``), close part of an
        object's vertical gap to what holds it (floating, or sunk in) by moving it along the camera ray through its
        centre of mass rather than straight down (:func:`starts.ray_corrected`): a monocular reconstruction errs mostly
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
        pixels in the scene over its pixels alone) is kept where it was put, lowered onto what lies beneath it
        (past the bodies beside and above it), static, like an object fixed in place (``attached`` to the ground in
        the grounded scene: left out of drift averages, counted with the attached objects); not when nothing then
        touches it from beneath (a contact normal within 60 deg of straight up), when lowering took it deeper into
        a body (one beside it that widens lower down), when the placed
        objects it touches move when released with it static (:func:`~phiscene.assembly.settle.gives_way`: its
        convex pieces would shove them), or when the fallback's result is nearer to the input
        (:func:`certify.closeness` from the input, a fall below it counted: the corrected pose may have been carried
        far with its supporter, or be lowered far). Its reconstruction is mostly a guess of what the photo does
        not show (a chair tucked under a table, seen by its backrest), and what holds it is in that unseen part:
        its guessed shape topples from every start, and the fallback throws it tens of centimetres. 0 = off;
        without the photo's camera, off.
    hold_far
        Remedy ``held``: an object no start held whose fallback (the result ranked first, above) went farther than
        this many times its bounding-box diagonal, and farther than ``onto_reach``, from where its start put it (its
        centre of mass, horizontally, or falling) is kept where it was put as remedy ``hidden`` keeps one, on the
        same conditions, seen or not and with or without the photo's camera: static, attached to the ground in the
        grounded scene (left out of drift averages, counted with the attached objects), and reported as not
        settled (its record's ``settled`` false, the summary's ``held``), the fallback's motion in its reason.
        Settling would carry it across the scene: a reconstruction's chair pushed out of the table it was put
        through, thrown metres, a ball rolling down a ramp; no nearby rest exists on the shape and supporters it
        was given, and where the simulator would leave it is neither the photo's scene nor a rest the photo
        supports. A plank that topples over on the spot moves less than its size and takes the fallback. 0 = off.
    """

    _label = "faithful parameters"

    enabled: bool = False
    flush: bool = True
    max_flush_angle: float = 20.0
    max_slide: float = 0.03
    max_slide_frac: float = 0.25
    max_turn: float = 10.0
    carry: bool = True
    carry_sideways: str = "off_support"
    carry_margin: float = 0.5
    planar_floor: float = 0.1
    floor_lift: float = 0.5
    joint_settle_frames: int = 240
    joint_frames: int = 120
    joint_drop: float = DRIFT_LIFT
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
    fixtures: bool = True
    lean: bool = True
    max_shift: float = 0.09
    shift_directions: int = 6
    onto_reach: float = 0.3
    reground: bool = True
    reground_move: float = 0.09
    ballast: bool = True
    ballast_height: float = 0.25
    base: bool = True
    centre_load: bool = True
    ray: bool = False
    ray_share: float = 0.5
    ray_max_shift: float = 0.15
    ray_min_pitch: float = 10.0
    hidden_share: float = 0.5
    hold_far: float = 1.0

    def check(self) -> None:
        """Reject negative bounds, an unknown ``carry_sideways`` and ``retry_damping`` outside [0, 1)
        (``ValueError``)."""
        for key in ("max_flush_angle", "max_stable_angle", "max_candidates", "tilt_test", "tilt_frames",
                    "joint_settle_frames", "joint_frames", "joint_drop", "joint_tol", "joint_tol_deg", "max_slide",
                    "max_slide_frac", "max_turn", "contact_tol", "retry_rolling_friction", "max_shift",
                    "shift_directions", "onto_reach", "planar_floor", "floor_lift", "load_frames", "reground_move",
                    "carry_margin", "hold_far"):
            if getattr(self, key) < 0:
                raise ValueError(f"faithful parameter {key!r} must be >= 0, got {getattr(self, key)}")
        if self.carry_sideways not in CARRY_SIDEWAYS:
            raise ValueError(f"faithful carry_sideways must be one of {', '.join(CARRY_SIDEWAYS)}, got "
                             f"{self.carry_sideways!r}")
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
