"""One line on what grounding did to a scene, for its log and the ``phiscene ground`` command.

The motion is measured as the tables measure it (:func:`phiscene.metrics.pose.pose_metrics`: each free object's
bounding-box centre and rotation against the input), so the line shows what ``real.csv`` will show for the scene,
and the assembly log's summary gives the rest: settled, kept static (``held``, ``hidden``), attached, still moving
in the final release, ending far from the input.
"""

from __future__ import annotations

import numpy as np

from phiscene.metrics.pose import object_centre, pose_metrics
from phiscene.scene import Scene


def outcome_line(grounded: Scene, initial: Scene, record: dict) -> str:
    """What grounding did, in one line.

    Parameters
    ----------
    grounded
        The grounded scene (:func:`phiscene.assembly.assemble.ground_scene`'s first result).
    initial
        Its input.
    record
        The assembly log (its ``summary``).

    Returns
    -------
    e.g. ``"result: 11 of 11 objects settled; from the input: moved 4.3 cm on average, 6.6 cm at most (jug),
    turned 9.9 deg on average, 14.8 deg at most"`` followed by the objects not settled, held, hidden, attached,
    still moving and far from their input, where there are any.
    """
    s = record.get("summary", {})
    parts = [f"result: {s.get('settled', 0)} of {s.get('objects', len(initial.objects))} objects settled"]
    m = pose_metrics(grounded, initial)
    ids = [o for o in initial.free_ids if o in set(grounded.ids)]
    if ids:
        moved = [float(np.linalg.norm(object_centre(grounded.get(o)) - object_centre(initial.get(o)))) for o in ids]
        far = ids[int(np.argmax(moved))]
        parts.append(f"from the input: moved {100 * m['displacement_mean']:.1f} cm on average, "
                     f"{100 * m['displacement_max']:.1f} cm at most ({far}), turned {m['rotation_mean']:.1f} deg on "
                     f"average, {m['rotation_max']:.1f} deg at most")
    lists = [("not settled", s.get("unsettled")), ("kept static, carried too far otherwise", s.get("held")),
             ("kept static, mostly unseen", s.get("hidden")), ("attached", s.get("attached")),
             ("moving in the final release", s.get("joint_unstable")), ("far from the input", s.get("gross"))]
    parts += [f"{what}: {', '.join(sorted(names))}" for what, names in lists if names]
    return "; ".join(parts)
