"""A phiscene plugin used by the seam tests: one entry per extension point, nothing else.

- a drift simulator ``bullet_coarse``: a second pybullet world with other solver settings (a quarter of the
  solver iterations and substeps), so the cross-simulator table gains ``drift_*_bullet_coarse`` columns;
- a table kind ``faithfulness``: displacement and pose error against ground truth per method, ranked;
- a baseline ``drop``: every free object lowered (or raised) so that its lowest vertex rests on the ground.

Config that uses it: ``plugins: [seam_plugin]`` with ``tests/plugins`` on ``PYTHONPATH``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from phiscene.baselines.registry import Baseline, register_baseline
from phiscene.metrics.drift import DriftSimulator, register_simulator
from phiscene.params import Params
from phiscene.table_registry import TableKind, register_table

COARSE = {"solver_iterations": 12, "substeps": 2}


def coarse_drift(ctx):
    """pybullet drift of the scene with :data:`COARSE` solver settings."""
    from phiscene.metrics.drift import drift_bullet
    from phiscene.metrics.physical import PhysicalParams

    return drift_bullet(ctx.scene, ctx.proxies(), ctx.params(PhysicalParams, "physical"),
                        replace(ctx.sim(), **COARSE), ctx.cache_dir())


FAITHFUL_COLUMNS = {"displacement_mean": "min", "gt_translation_mean": "min"}


def faithfulness_table(inputs):
    """Per method the scene means of :data:`FAITHFUL_COLUMNS` (``pose_gt`` section)."""
    from phiscene.tables import average_rank, mean_table

    df = mean_table(inputs.files, list(FAITHFUL_COLUMNS), "pose_gt")
    df["avg_rank"] = average_rank(df, FAITHFUL_COLUMNS)
    return df


@dataclass(frozen=True)
class DropParams(Params):
    """Settings of the ``drop`` baseline.

    Attributes
    ----------
    clearance
        Height (m) of each object's lowest vertex above the ground.
    """

    _label = "drop baseline parameters"

    clearance: float = 0.0


def drop(inputs, params: DropParams):
    """Translate every free object vertically so that its lowest vertex is ``clearance`` above the ground."""
    poses = {}
    for o in inputs.scene.objects:
        if o.attached is not None:
            continue
        low = float(o.world_mesh().vertices[:, 2].min())
        pose = np.array(o.pose, dtype=float)
        pose[2, 3] += inputs.scene.ground_height + params.clearance - low
        poses[o.id] = pose
    return inputs.scene.with_poses(poses), {"moved": sorted(poses)}


register_simulator(DriftSimulator("bullet_coarse", section="bullet_coarse", column="bullet_coarse",
                                  drift=coarse_drift))
register_table(TableKind("faithfulness", "Faithfulness to the input", "Faithfulness to the input (plugin)",
                         faithfulness_table, FAITHFUL_COLUMNS, ("pose_gt",), bars=tuple(FAITHFUL_COLUMNS)))
register_baseline(Baseline("drop", drop, DropParams))
