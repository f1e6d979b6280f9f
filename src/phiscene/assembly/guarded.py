"""Guarded settling, step 3 of faithful grounding (:mod:`phiscene.assembly.faithful`): the starts tried for one object,
the tests a settled result must pass, and the fallback when none does.

:func:`settle_faithful` runs in the sequential loop of :func:`phiscene.assembly.assemble.ground_scene`, one object at a
time against the objects placed before it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from phiscene.assembly import ballast, certify, resting, starts
from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.record import rounded
from phiscene.assembly.settle import (
    SettleParams,
    clear_overlaps,
    close_gaps,
    gives_way,
    holds_when_tilted,
    load_carriers,
    settle_object,
    window_motion,
)
from phiscene.proxies import Proxy, with_base
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, transform_points, turned_about

#: When no start is accepted, at most this many fallback results are tilt-tested, in rank order, for one that holds.
FALLBACK_TILTS = 4

#: A contact whose normal (from the other body towards the object) is within 60 deg of straight up is a contact
#: beneath the object (remedy ``hidden``, :func:`lowered_start`).
BENEATH_MIN_Z = 0.5

#: Remedies that keep an object static where it was put (attached to the ground in the grounded scene): ``hidden``
#: (settled: its unseen part holds it) and ``held`` (not settled: the fallback carried it across the scene).
KEPT_REMEDIES = ("hidden", "held")

#: Remedy ``centred``: shares of the way from a body's centre of mass to its carriers' that its starts move it,
#: nearest first.
CENTRE_FRACTIONS = (0.5, 1.0)


def settle_faithful(world, oid: str, mesh, proxy: Proxy, pose: np.ndarray, sim: SimSettings, sp: SettleParams,
                    fp: FaithfulParams, info: dict, rec: dict, com: np.ndarray | None = None) -> np.ndarray:
    """Guarded settling (see :mod:`phiscene.assembly.faithful`); fills ``rec``; returns the frozen pose.

    Every start (the corrected pose, then that pose moved out of proxy overlaps (``clear``), then the nearest
    resting poses, then a damped run, then the pose moved onto the
    nearest supporting surface, then horizontal shifts when every start so far went farther than ``max_shift`` or
    lost its supporters, or none came to rest level, then a rest whose carriers gave way under it moved over their
    centre of mass (``centred``)) is lowered onto what lies beneath and settled with the paper's
    settling; the first result within the slide/drop/turn bounds that keeps the graph's supporters is taken, else,
    avoiding gross failures (turned past ``max_stable_angle`` or moved past ``onto_reach``) where a start did, the
    closest settled one that stayed in place (on its supporters if one did), else the closest. The final pose is
    always the outcome of free settling.

    The body has the declared centre of mass ``com`` (3,) local, if any. When no start came to rest level, one
    more start with its centre of mass declared lower (from the photo's orientation, the corrected pose with the
    flush turn undone, when that turn exceeded ``max_turn``; remedy ``ballast``,
    :func:`~phiscene.assembly.ballast.ballast_com`) comes before the shifted ones; accepted, ``rec`` gets
    ``ballast`` (``com``: the declared centre, local; ``lowered``: m), else the body is a uniform solid again.
    """
    from phiscene.inertia import rigid_props

    scale = decompose(pose)[2]
    props = rigid_props(mesh, proxy.hulls, sim.density, scale, com)
    world.add_body(oid, proxy.hulls, pose, props)
    context = [b for b in world.bodies if b != oid]

    def touching() -> list[str]:
        return sorted(world.distances(oid, context, fp.contact_tol))

    tried: list[dict] = []
    own = props.com / scale  # its centre of mass as it came (local, unscaled)
    # the centre of mass the body in the world has (declared, local; None: uniform), and its completed base
    body = {"com": com, "base": None}

    def mass(declared: np.ndarray | None, base: np.ndarray | None = None) -> None:
        # the body again, with another centre of mass (and completed base, remedy base)
        if declared is not body["com"] or base is not body["base"]:
            hulls = with_base(proxy, base).hulls
            world.remove_body(oid)
            world.add_body(oid, hulls, pose, rigid_props(mesh, hulls, sim.density, scale, declared))
            body.update(com=declared, base=base)

    def attempt(label: str, start: np.ndarray, damped: bool = False, origin: np.ndarray | None = None) -> dict:
        # origin: where the slide bound is measured from (a shifted start: the start itself)
        origin = pose if origin is None else origin
        lowered = lowered_start(world, oid, start, context, fp.contact_tol / 2)
        # lowered farther than onto_reach: nothing it could stand on was beneath it (beside its shelf); a fall
        fell = float(start[2, 3] - lowered[2, 3])
        fell = fell if 0 < fp.onto_reach < fell else 0.0
        start = lowered
        world.set_pose(oid, start)
        frames = 0
        if damped:
            world.set_dynamics(oid, linearDamping=fp.retry_damping, angularDamping=fp.retry_damping,
                               rollingFriction=fp.retry_rolling_friction, spinningFriction=fp.retry_rolling_friction)
            first = settle_object(world, oid, sp)
            world.restore_dynamics(oid)
            frames += first.frames
            world.set_pose(oid, first.pose)  # at rest; then normal settings decide whether it stays
        result = settle_object(world, oid, sp)
        frames += result.frames
        ok, moved, turned = certify.within_bounds(origin, result.pose, info["com"], info["diag"], fp, start=lowered)
        if fell:
            ok, moved = False, max(moved, fell)
        near = touching()
        lost = certify.lost_supporters(info["below"], info["leaning"], near)
        # in place: within the bounds, still leaning where it leans (the graph may name the wrong supporter
        # from below: an object that rests where it was put, on something else, is in place all the same)
        in_place = ok and not any(p in lost for p in info["leaning"])
        robust = True  # tested only where it decides: a settled result in place (the fallback: below)
        tested = result.settled and in_place and fp.tilt_test > 0 and not info["leaning"]  # leaning: friction
        if tested:
            robust, spent = holds_when_tilted(world, oid, fp.tilt_test, fp.tilt_frames, fp.joint_tol,
                                              fp.joint_tol_deg, sp)
            frames += spent
        gave: list[str] = []  # the placed objects it touches (and their supporters), released under it, hold it
        motions: dict[str, tuple[float, float]] = {}  # how far each body went in that test (m, deg)
        if result.settled and in_place and robust and fp.load_frames > 0:
            carriers = load_carriers(world, oid, near, info["fixed"], fp.contact_tol, fp.load_depth)
            if carriers:
                gave, spent = gives_way(world, oid, carriers, fp.load_frames, fp.joint_tol, fp.joint_tol_deg, sp,
                                        motions)
                frames += spent
        whys = ["" if ok else f"moved {moved:.3f} m / {turned:.1f} deg",
                f"lost supporters {lost}" if lost else "", "" if result.settled else "not settled",
                "" if robust else f"marginal: tips when tilted {fp.tilt_test:g} deg",
                f"gives way when released: {gave}" if gave else ""]
        stayed = ok and not lost
        # a gross failure: turned beyond any resting pose tried, or went farther than the onto remedy moves
        gross = certify.gross_failure(moved, turned, fp)
        out = {"label": label, "result": result, "frames": frames, "gross": gross, "turned": turned, "moved": moved,
               "ok": stayed and result.settled and robust and not gave, "lost": bool(lost), "robust": robust,
               "loaded": not gave,
               "stayed": stayed, "in_place": in_place, "travel": moved if not lost else math.inf,
               "cost": certify.closeness(pose, result.pose, info["com"], info["diag"], start=lowered) + fell,
               "why": "; ".join(w for w in whys if w), "touching": near, "com": body["com"], "base": body["base"],
               "tilt_tested": tested,
               "collapses": bool(gave) and any(m > certify.slide_bound(info["diag"], fp) or d > fp.max_turn
                                               for m, d in motions.values())}
        tried.append(out)
        return out

    def holds(t: dict) -> bool:
        # tilt-test a settled result where it came to rest, with the body it had (once): whether it holds
        if not t["tilt_tested"] and fp.tilt_test > 0:
            mass(t["com"], t["base"])
            world.set_pose(oid, t["result"].pose)
            t["tilt_tested"] = True
            t["robust"], spent = holds_when_tilted(world, oid, fp.tilt_test, fp.tilt_frames, fp.joint_tol,
                                                   fp.joint_tol_deg, sp)
            t["frames"] += spent
            if not t["robust"]:
                t["why"] = "; ".join(w for w in (t["why"], f"marginal: tips when tilted {fp.tilt_test:g} deg") if w)
        return t["robust"]

    best = attempt("none", pose)
    if not best["ok"] and fp.clear:
        # out of what it neither stands nor leans on, where its convex pieces overlap it (its mesh is clear of
        # it): the simulator shoves it out at once; the remaining starts are taken from there
        holders = {"ground", *info["below"], *info["leaning"]}
        world.set_pose(oid, pose)
        shift = clear_overlaps(world, oid, [b for b in context if b not in holders], fp.contact_tol, fp.max_shift)
        if shift is not None:
            pose = pose.copy()
            pose[:3, 3] += shift
            rec["proxy_clear"] = [rounded(v) for v in shift]
            best = attempt("clear", pose)
    if not best["ok"] and fp.lean and info["leaning"]:
        # short of what it leans on (depth error): lowered, then moved sideways until it touches it
        lowered = lowered_start(world, oid, pose, context, fp.contact_tol / 2)
        world.set_pose(oid, lowered)
        shift = close_gaps(world, oid, info["leaning"], fp.contact_tol, fp.contact_tol / 2, fp.onto_reach)
        if shift is not None:
            start = lowered.copy()
            start[:3, 3] += shift
            rec["lean_shift"] = [rounded(v) for v in shift]
            best = attempt(f"lean {np.linalg.norm(shift):.3f} m", start, origin=start)
    if not best["ok"]:
        stable_poses = resting.resting_candidates(pose, info["normals"], info["com"], info["up"], fp.max_stable_angle)
        for start, angle in [c for c in stable_poses if c[1] > 0.5][: fp.max_candidates]:
            if attempt(f"stable {angle:.1f} deg", start)["ok"]:
                break
        if not any(t["ok"] for t in tried):
            attempt("damped", pose, damped=True)
        if not any(t["ok"] or (t["in_place"] and t["result"].settled and t["robust"] and t["loaded"])
                   for t in tried) and fp.onto_reach > 0:
            # fell or slid off every time, only balances on an edge or its carriers give way under it: its input
            # is off its supporter or over its edge (depth error); move it onto the nearest supporting surface,
            # inside its edge (the graph may name the wrong supporter), from where the input put it: carried
            # by a supporter the graph got wrong, it may have gone far. Any surface nearer than where it went
            # anyway (a can over nothing falls a metre to the floor; the wall shelf its depth error took it off
            # is 31 cm away) is nearer to the input than that
            here = pose.copy()
            here[:3, 3] += resting.com_world(info["input"], info["com"]) - resting.com_world(pose, info["com"])
            points = transform_points(here, info["points"])
            went = [t["travel"] for t in tried if math.isfinite(t["travel"])]
            reach = max(fp.onto_reach, min(went)) if went else fp.onto_reach
            onto = starts.onto_start(here, info["com"], points, info["surfaces"](info["placed"]), reach,
                                     fp.contact_tol / 2, info["walls"])
            if onto is not None and onto[1] > 1e-3:
                attempt(f"onto {onto[1]:.3f} m", onto[0], origin=onto[0])
        if fp.ballast and not any(t["ok"] for t in tried) and all(
                t["turned"] > fp.max_turn or not t["result"].settled or not t["robust"] for t in tried):
            # none came to rest level: at rest in the photo, so not a uniform solid (flowers outweighing a vase).
            # A flush within the turn bound corrects the input's rotation error; a larger one was chosen for the
            # uniform solid and contradicts the photo, which shows the object at rest: that turn undone
            points = info["points"]  # its convex pieces' vertices (local)
            undone = info["flush_angle"] > fp.max_turn
            start = _unflushed(world, oid, pose, info, context, fp.contact_tol / 2) if undone else pose
            declared = ballast.ballast_com(start, own, points, fp.ballast_height)
            angle = 0.0  # the flush turn of these starts (from the photo's orientation when undone)
            if declared is not None and fp.flush and info["flushable"]:
                # flush on the facet it rests on with that centre of mass (a vase's base is no resting facet of
                # the uniform solid), then the centre over that base
                normals = resting.cached_resting_normals(points, info["cache_dir"], declared)
                start, angle = resting.flush_pose(start, normals, declared, info["up"], fp.max_flush_angle)
                if angle > 0:
                    declared = ballast.ballast_com(start, own, points, fp.ballast_height)
            if declared is not None:
                mass(declared)
                t = attempt("ballast", start, origin=start)
                if undone:
                    t["flush"] = angle
                if not t["ok"]:  # the flush is a correction, as for none
                    mass(com)  # the other starts as it came; the ballast result may still be the closest
            if fp.base and info["flushable"] and not info["given_base"] and not any(t["ok"] for t in tried) \
                    and not _rests(tried, certify.slide_bound(info["diag"], fp), holds):
                mass(com)  # the body as it came (a tilt test may have changed it)
                # nor with its mass low, and no start came to rest where it was put, however turned (a can
                # tilted by a rotation error stands upright on its bottom, a resting pose 28 deg away): its
                # bottom is a guess that cannot stand (a jug, a fruit guessed round underneath); complete it
                # flat where it stands, level, with its mass as low
                declared = com if declared is None else declared
                flat = ballast.flat_base(start, proxy.hulls, own if declared is None else declared, info["up"],
                                         fp.tilt_test)
                if flat is not None:
                    mass(declared, flat[0])
                    t = attempt(f"base {flat[1]:g}", start, origin=start)
                    if undone:
                        t["flush"] = angle
                    if not t["ok"]:
                        mass(com)
            elif not any(t["ok"] for t in tried):
                mass(com)  # the body as it came (a tilt test may have changed it)
        travelled = min(t["travel"] for t in tried)
        # every start went far, or none came to rest level (tipped over, or still moving: a book whose depth error
        # put it over its supporter's edge): one nearby
        tipped = all(t["turned"] > fp.max_turn or not t["result"].settled for t in tried)
        if (travelled > fp.max_shift or tipped) and not any(t["ok"] for t in tried):
            step = certify.slide_bound(info["diag"], fp)
            for r, ring in starts.shifted_starts(pose, step, fp.max_shift, fp.shift_directions):
                # nearest ring first; stop at an accepted start, or after a ring
                done = [attempt(f"shifted {r:.3f} m", s, origin=s) for s in ring]  # where one rests in place
                if any(t["ok"] for t in done) or any(t["in_place"] and t["result"].settled for t in done):
                    break
    if fp.centre_load and not any(t["ok"] for t in tried):
        # at rest in place and holding when tilted, but it or what carries it falls when its carriers are released
        # (a box on a book that overhangs its own supporter): the same rest with its centre of mass moved over its
        # carriers'. Not for a carrier that only rocks under it (the joint release settles that)
        tipping = [t for t in tried if not t["gross"] and t["result"].settled and t["in_place"] and t["robust"]
                   and t["collapses"]]
        if tipping:
            t = min(tipping, key=lambda t: t["cost"])
            mass(t["com"], t["base"])
            for start in _centred_starts(world, oid, t, info["fixed"], context, fp.contact_tol / 2, fp.max_shift):
                moved = attempt("centred", start, origin=start)
                moved["source"] = t  # its body (declared centre of mass, completed base) is t's
                if moved["ok"]:
                    break
    ok = [t for t in tried if t["ok"]]
    if not ok and fp.tilt_test > 0 and not info["leaning"]:
        # the fallback: tilt-test the settled results in rank order (only those in place were tested), up to
        # the first that holds; one that only balances would roll off at the first disturbance
        for t in sorted(tried, key=certify.fallback_rank)[:FALLBACK_TILTS]:
            if t["gross"] or not t["result"].settled or t["tilt_tested"]:
                continue
            if holds(t):
                break
    best = ok[0] if ok else min(tried, key=certify.fallback_rank)
    share = info["visible"]() if not ok and info.get("visible") is not None else None
    hidden = share is not None and share < fp.hidden_share  # nan (outside the image): no
    # the fallback carried it across the scene (remedy held)
    carried_off = not ok and fp.hold_far > 0 and best["moved"] > far_bound(info["diag"], fp)
    if hidden or carried_off:
        # mostly unseen, and its guessed shape held by no start (or the fallback carried it across the scene):
        # kept where it was put, lowered onto what lies beneath it (past the bodies beside and above it: a chair
        # tucked under a table), unless the fallback ends
        # nearer to the input (the corrected pose may have been carried far, or fall far when lowered), nothing
        # touches it from beneath, lowered it reaches into a body (beside it, widening lower down), or the placed
        # objects it touches, released, do not stay (static, it would shove them: its convex pieces may reach into
        # them)
        mass(com)
        world.set_pose(oid, pose)
        overlaps = {k: d for k, (d, _) in world.nearest(oid, context, 0.0).items()}  # as it was put (m, < 0)
        kept = lowered_start(world, oid, pose, context, fp.contact_tol / 2, beneath_only=True)
        world.set_pose(oid, kept)
        lowered = world.nearest(oid, context, fp.contact_tol)
        near = sorted(lowered)  # what touching() reads
        beneath = [k for k, (_, n) in lowered.items() if n[2] >= BENEATH_MIN_Z]
        if any(d < min(overlaps.get(k, 0.0), 0.0) - fp.contact_tol for k, (d, _) in lowered.items()):
            beneath = []  # lowering took it deeper into a body
        far = lambda p: certify.closeness(info["input"], p, info["com"], info["diag"], start=info["input"])  # noqa: E731
        world.set_static(oid)
        carriers = load_carriers(world, oid, near, info["fixed"], fp.contact_tol, fp.load_depth)
        if beneath and far(kept) < far(best["result"].pose) and not (
                carriers and gives_way(world, oid, carriers, fp.load_frames, fp.joint_tol, fp.joint_tol_deg, sp)[0]):
            rec["touching"] = near
            moved, turned = window_motion(pose, kept)
            reason = "; ".join(f"{t['label']}: {t['why']}" for t in tried)
            if hidden:
                why, extra = f"kept: {share:.0%} visible", {"visible_share": rounded(share)}
            else:
                why, extra = (f"kept: the fallback ({best['label']}) went {best['moved']:.2f} m, farther than "
                              f"{far_bound(info['diag'], fp):.2f} m"), {}
            rec.update(settle_frames=sum(t["frames"] for t in tried), settled=bool(hidden),
                       settle_remedy="hidden" if hidden else "held",
                       residual_translation=0.0, residual_rotation=0.0, settle_translation=rounded(moved),
                       settle_rotation=rounded(turned), reason=f"{reason}; {why}", attempts=len(tried), **extra)
            return kept
    result = best["result"]
    source = best.get("source", best)  # a centred start: the attempt whose rest it moved, body and turn included
    if "flush" in source:  # started from the photo's orientation: the flush of _faithful_start undone
        info["flush_angle"] = source["flush"]
        rec["flush_angle"] = rounded(source["flush"])
    if not best["ok"]:
        remedy = "closest"
    else:
        remedy = result.remedy if best["label"] == "none" else best["label"].split()[0]
    reason = "; ".join(f"{t['label']}: {t['why']}" for t in tried if t is not best or not best["ok"])
    final = result.pose
    mass(best["com"], best["base"])
    if best["com"] is not None and best["com"] is not com and source["label"].split()[0] in ("ballast", "base"):
        # declared by the remedy (a base start keeps the input's own declared centre when the ballast had none)
        lowered = resting.com_world(final, own)[2] - resting.com_world(final, best["com"])[2]
        rec["ballast"] = {"com": [rounded(v, 12) for v in best["com"]], "lowered": rounded(lowered)}
    if best["base"] is not None:
        rec["base"] = {"points": np.asarray(best["base"]).round(12).tolist(),
                       "share": float(source["label"].split()[1])}
    world.set_pose(oid, final)
    rec["touching"] = best["touching"]
    world.set_static(oid)
    moved, turned = window_motion(pose, final)
    rec.update(settle_frames=sum(t["frames"] for t in tried), settled=result.settled, settle_remedy=remedy,
               residual_translation=rounded(result.residual_translation, 12),
               residual_rotation=rounded(result.residual_rotation, 12),
               settle_translation=rounded(moved), settle_rotation=rounded(turned), reason=reason,
               attempts=len(tried))
    return final


def far_bound(diag: float, fp: FaithfulParams) -> float:
    """Remedy ``held``'s bound (m) for an object whose bounding-box diagonal is ``diag`` (m): ``hold_far`` times
    ``diag``, at least ``onto_reach`` (:class:`~phiscene.assembly.faithful.FaithfulParams`)."""
    return max(fp.hold_far * diag, fp.onto_reach)


def _unflushed(world, oid: str, pose: np.ndarray, info: dict, below: list[str], clearance: float) -> np.ndarray:
    """``pose`` with the flush turn of :func:`_faithful_start` (``info["flush_rotation"]``) undone about the centre
    of mass, raised out of ``below`` (and the ground) where the turn takes it into them, to ``clearance`` (m)."""
    from scipy.spatial.transform import Rotation

    back = Rotation.from_matrix(info["flush_rotation"].T).as_rotvec()
    return _raised_clear(world, oid, turned_about(pose, back, resting.com_world(pose, info["com"])),
                         _stoppers(world, below), clearance)


def _raised_clear(world, oid: str, pose: np.ndarray, others: list[str], clearance: float) -> np.ndarray:
    """``pose`` (4, 4), raised straight up out of the deepest overlap of body ``oid`` there with ``others`` to
    ``clearance / 2`` (m) above it; unchanged where nothing overlaps. Changes ``pose`` in place and returns it."""
    world.set_pose(oid, pose)
    gaps = world.distances(oid, others, clearance)
    if gaps and min(gaps.values()) < 0:
        pose[2, 3] += clearance / 2 - min(gaps.values())
    return pose


def _centred_starts(world, oid: str, attempt: dict, fixed, context: list[str], clearance: float,
                    reach: float) -> list[np.ndarray]:
    """Starts of remedy ``centred`` (:class:`~phiscene.assembly.faithful.FaithfulParams` ``centre_load``).

    The rest of ``attempt`` (an attempt of :func:`settle_faithful`: ``result.pose``, ``touching``) moved
    horizontally by each of ``CENTRE_FRACTIONS`` of the way from the body's centre of mass to its carriers' (the
    free placed bodies it touches there whose centre of mass lies lower than its own, mass-weighted: a chair
    pushed against a table's edge is not carried by it), at most ``reach`` (m), nearest first, each raised out of
    what it would then overlap of ``context`` to ``clearance`` (m).

    Returns
    -------
    list of (4, 4) poses; empty when nothing carries it.
    """
    rest = attempt["result"].pose
    world.set_pose(oid, rest)
    own = world.com_position(oid)
    coms = {q: world.com_position(q) for q in attempt["touching"]
            if q in world.bodies and q not in fixed and world.bodies[q].props is not None}
    carriers = [q for q, c in coms.items() if c[2] < own[2]]
    if not carriers:
        return []
    masses = np.array([world.bodies[q].props.mass for q in carriers])
    centre = masses @ np.array([coms[q] for q in carriers]) / masses.sum()
    offset = centre[:2] - own[:2]
    out = []
    for share in CENTRE_FRACTIONS:
        shift = share * offset
        length = float(np.linalg.norm(shift))
        start = np.array(rest, dtype=float, copy=True)
        start[:2, 3] += shift * (min(1.0, reach / length) if length > 0 else 0.0)
        out.append(_raised_clear(world, oid, start, context, clearance))
    return out


def _rests(tried: list[dict], bound: float, holds: Callable[[dict], bool]) -> bool:
    """Whether a start of ``tried`` (the attempts of :func:`settle_faithful`) came to rest where it was put, however
    turned: settled, its centre of mass within ``bound`` (m) of its start, and ``holds`` (tilt-tested) it."""
    return any(t["result"].settled and t["travel"] <= bound and holds(t) for t in tried)


def _stoppers(world, below: list[str]) -> list[str]:
    """What a body moved straight up or down meets: ``below``, and the ground whatever the graph says."""
    return list(dict.fromkeys([*below, *(["ground"] if "ground" in world.bodies else [])]))


def lowered_start(world, oid: str, pose: np.ndarray, below: list[str], clearance: float,
                  beneath_only: bool = False) -> np.ndarray:
    """``pose`` moved straight down until within ``clearance`` of the nearest of ``below`` (or of the ground).

    Each step lowers by the Euclidean gap (a lower bound of the vertical gap), so it never penetrates. The ground
    always stops it: a supporter that is no longer beneath the object (it moved, or the graph was wrong) must not
    let it sink through the floor. ``beneath_only``: only a body whose nearest point lies beneath the object (the
    normal there, from the body towards the object, within 60 deg of straight up: :data:`BENEATH_MIN_Z`) stops it,
    so an object put against a table top's underside, or against the side of the table that hides it, is lowered
    to what lies beneath it. It may then reach into a body beside it that widens lower down: the caller checks.
    """
    stoppers = _stoppers(world, below)
    out = pose.copy()
    for _ in range(8):
        world.set_pose(oid, out)
        gaps = {k: d for k, (d, n) in world.nearest(oid, stoppers, 1.0).items()
                if not beneath_only or n[2] >= BENEATH_MIN_Z}
        gap = min(gaps.values()) if gaps else 0.0
        if gap <= clearance:
            break
        out[2, 3] -= gap - clearance / 2
    return out
