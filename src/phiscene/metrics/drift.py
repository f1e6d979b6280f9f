"""Registry of drift simulators: the engines a scene is released in to measure post-simulation drift.

Every simulator follows one protocol (paper supplement): lift each free object by ``upward_offset``, simulate
``frames`` frames, and report per object and on average over the free objects the translation of the centre of
mass (m) and the rotation (degrees). A simulator is one :class:`DriftSimulator` entry: its name, the metrics
section its drift lands in, the column suffix of the cross-simulator table, whether that table ranks it, and (for
a simulator with a section of its own) the drift function. :func:`register_simulator` registers that section
(:mod:`phiscene.metrics.sections`), so the cross-simulator table (:mod:`phiscene.table_registry`) shows a new
engine with no other edit::

    register_simulator(DriftSimulator("bullet_pgs", section="bullet_pgs", column="bullet_pgs",
                                      drift=my_drift, settings=("physical", "sim", "bullet_pgs")))

pybullet's drift is part of the ``physical`` section (it runs with the contact metrics); MuJoCo's is the
``mujoco`` section.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from phiscene.metrics.sections import MetricSection, SectionContext, register_section, unregister_section

#: Per-object and mean keys every drift result holds.
DRIFT_KEYS = ("drift_trans", "drift_rot")


@dataclass(frozen=True)
class DriftSimulator:
    """One engine of the drift protocol.

    Attributes
    ----------
    name
        Engine name (drift figure ``drift_<name>.png``).
    section
        Metrics section holding its ``drift_trans`` / ``drift_rot``.
    column
        Suffix of its cross-simulator table columns (``drift_trans_<column>``).
    ranked
        The cross-simulator table ranks its columns (engines independent of the grounding's own).
    drift
        ``drift(ctx) -> dict`` with :data:`DRIFT_KEYS` means and ``objects``; ``None`` when another section
        computes it (pybullet's drift is in ``physical``).
    settings, inputs
        What its section reads (see :class:`~phiscene.metrics.sections.MetricSection`).
    """

    name: str
    section: str
    column: str
    ranked: bool = True
    drift: Callable[[SectionContext], dict] | None = None
    settings: tuple[str, ...] = ("physical", "sim")
    inputs: tuple[str, ...] = ("proxies",)


#: Registered simulators by name, in registration order.
SIMULATORS: dict[str, DriftSimulator] = {}


def _drift_line(r: dict) -> str:
    return f"drift {r['drift_trans']:.4f} m / {r['drift_rot']:.2f} deg"


def register_simulator(sim: DriftSimulator) -> DriftSimulator:
    """Add a simulator (and its metrics section when it brings a drift function); return it."""
    if sim.name in SIMULATORS:
        raise ValueError(f"drift simulator {sim.name!r} is already registered")
    if sim.drift is not None:
        register_section(MetricSection(sim.section, sim.drift, sim.settings, sim.inputs, _drift_line))
    SIMULATORS[sim.name] = sim
    return sim


def unregister_simulator(name: str) -> None:
    """Remove a simulator and the section it registered (tests and temporary plugins)."""
    sim = SIMULATORS.pop(name, None)
    if sim is not None and sim.drift is not None:
        unregister_section(sim.section)


def table_simulators() -> list[DriftSimulator]:
    """The simulators of the cross-simulator table: ranked ones first, each group in registration order."""
    sims = list(SIMULATORS.values())
    return [s for s in sims if s.ranked] + [s for s in sims if not s.ranked]


def _mujoco(ctx: SectionContext) -> dict:
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.sim.mujoco import MujocoParams, drift_mujoco

    return drift_mujoco(ctx.scene, ctx.proxies(), ctx.params(PhysicalParams, "physical"), ctx.sim(),
                        ctx.params(MujocoParams, "mujoco"))


register_simulator(DriftSimulator("pybullet", section="physical", column="bullet", ranked=False))
register_simulator(DriftSimulator("mujoco", section="mujoco", column="mujoco", drift=_mujoco,
                                  settings=("physical", "sim", "mujoco")))
