"""Registry of baselines: a method ``kind`` -> the function that computes it, its parameter class and its inputs.

One generic workflow rule (``workflow/rules/baseline.smk``) builds every method whose kind is registered here:
it gathers the initial scene and, as the entry asks, the scene's convex proxies and the support graph of the
method's ``topology`` backend, then calls :func:`phiscene.pipeline.run_baseline`. The config module checks a
method's ``params`` against the entry's class while the DAG is built. A new baseline is one
:func:`register_baseline` call plus a ``methods.<name>: {kind: <kind>, params: {...}}`` config entry::

    register_baseline(Baseline("my_baseline", my_run, MyParams, needs=("proxies",)))

where ``my_run(inputs: BaselineInputs, params: MyParams) -> (Scene, dict)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from phiscene.params import Params
    from phiscene.proxies import Proxy
    from phiscene.scene import Scene
    from phiscene.sim.settings import SimSettings
    from phiscene.topology.graph import SupportGraph

#: Inputs a baseline may need besides the initial scene.
NEEDS = ("proxies", "topology")


@dataclass(frozen=True)
class BaselineInputs:
    """What a baseline computes from.

    Attributes
    ----------
    scene
        The initial scene.
    sim
        Shared rigid-body settings.
    cache_dir
        Content-addressed cache folder (hull files, SDF grids).
    proxies
        Convex proxies by object id (entries needing ``proxies``), else ``None``.
    graph
        Support graph of the method's ``topology`` backend (entries needing ``topology``), else ``None``.
    """

    scene: "Scene"
    sim: "SimSettings"
    cache_dir: Path
    proxies: "dict[str, Proxy] | None" = None
    graph: "SupportGraph | None" = None


@dataclass(frozen=True)
class Baseline:
    """One baseline method kind.

    Attributes
    ----------
    kind
        The ``methods.<name>.kind`` it answers to.
    run
        ``run(inputs, params) -> (scene, log dict)``.
    params
        Its parameter class (:class:`~phiscene.params.Params`), for ``methods.<name>.params``.
    needs
        Inputs besides the initial scene (:data:`NEEDS`).
    """

    kind: str
    run: Callable[[BaselineInputs, "Params"], "tuple[Scene, dict]"]
    params: type
    needs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = sorted(set(self.needs) - set(NEEDS))
        if unknown:
            raise ValueError(f"baseline {self.kind!r}: unknown needs {unknown}; known: {list(NEEDS)}")


#: Registered baselines by kind.
BASELINES: dict[str, Baseline] = {}


def register_baseline(baseline: Baseline) -> Baseline:
    """Add a baseline kind (``ValueError`` if taken); return it."""
    if baseline.kind in BASELINES:
        raise ValueError(f"baseline kind {baseline.kind!r} is already registered")
    BASELINES[baseline.kind] = baseline
    return baseline


def unregister_baseline(kind: str) -> None:
    """Remove a baseline kind (tests and temporary plugins)."""
    BASELINES.pop(kind, None)


def get_baseline(kind: str) -> Baseline:
    """The registered baseline ``kind``; ``ValueError`` listing the known ones."""
    if kind not in BASELINES:
        raise ValueError(f"unknown baseline kind {kind!r}; known: {sorted(BASELINES)}")
    return BASELINES[kind]


# -- the paper's baselines (Tab. 6) ---------------------------------------------------------------------------------
def _joint_sdf(i: BaselineInputs, p):
    from phiscene.baselines.joint_sdf import joint_sdf

    return joint_sdf(i.scene, p, i.cache_dir)


def _joint_sim(i: BaselineInputs, p):
    from phiscene.baselines.joint_sim import joint_sim

    return joint_sim(i.scene, i.proxies, i.sim, p, i.cache_dir)


def _joint_sdf_sim(i: BaselineInputs, p):
    from phiscene.baselines.joint_sim import joint_sdf_sim

    return joint_sdf_sim(i.scene, i.proxies, i.sim, p, i.cache_dir)


def _lift_sim(i: BaselineInputs, p):
    from phiscene.baselines.lift import lift_sim

    return lift_sim(i.scene, i.graph, i.proxies, i.sim, p, i.cache_dir)


def _register_paper_baselines() -> None:
    from phiscene.baselines.joint_sdf import JointSdfParams
    from phiscene.baselines.joint_sim import JointSdfSimParams, JointSimParams
    from phiscene.baselines.lift import LiftParams

    register_baseline(Baseline("joint_sdf", _joint_sdf, JointSdfParams))
    register_baseline(Baseline("joint_sim", _joint_sim, JointSimParams, needs=("proxies",)))
    register_baseline(Baseline("joint_sdf_sim", _joint_sdf_sim, JointSdfSimParams, needs=("proxies",)))
    register_baseline(Baseline("lift_sim", _lift_sim, LiftParams, needs=("proxies", "topology")))


_register_paper_baselines()
