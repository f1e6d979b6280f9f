"""Accepting and ranking the results of faithful grounding, and the certificate each object ends with.

The bounds a settled result must stay within (:func:`within_bounds`), how close a result is to the corrected input
(:func:`closeness`), the order fallbacks are taken in (:func:`fallback_rank`), gross failures
(:func:`gross_failure`) and the per-object :func:`certificate` of the assembly log.
"""

from __future__ import annotations

import math

import numpy as np

from phiscene.assembly.faithful import FaithfulParams
from phiscene.assembly.resting import com_world
from phiscene.transforms import decompose, rotation_angle


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
        result), ``attached``, ``hidden`` and ``held`` (kept static where it was put; :mod:`phiscene.assembly.guarded`).
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
