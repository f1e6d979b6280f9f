"""Registry of metric sections: what a per-scene metrics file can hold, and how each part is computed.

A section is one entry: a name, the function computing it from a :class:`SectionContext`, the settings it reads
(names of the ``metrics`` config sub-sections, or ``sim``) and the input files it needs (fields of
:class:`~phiscene.metrics.evaluate.MetricInputs`). Tables (:mod:`phiscene.table_registry`) name the sections they
read; the workflow asks a metrics job for exactly those, passes it exactly their settings and inputs, and
:func:`phiscene.metrics.evaluate.scene_metrics` computes them in registration order. A drift simulator registers
its section through :func:`phiscene.metrics.drift.register_simulator`.

Adding a metric is one :func:`register_section` call (plus its ``metrics.<name>`` config, when it has settings)::

    register_section(MetricSection("my_metric", my_fn, settings=("my_metric",), inputs=("gt",)))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from phiscene.metrics.evaluate import MetricInputs
    from phiscene.scene import Scene

#: Input files a section may need (the fields of :class:`~phiscene.metrics.evaluate.MetricInputs`).
INPUT_NAMES = ("proxies", "gt", "initial", "reference_dir", "cache_dir")


@dataclass
class SectionContext:
    """What a section's function computes from: the scene, its input files and the settings, read lazily once.

    Attributes
    ----------
    scene
        The method's scene.
    inputs
        The files the requested sections need.
    settings
        Settings name -> mapping for that parameter class' ``from_dict`` (a missing one takes the defaults).
    align
        Pose sections compare after the best rigid alignment (the method's scenes are in their own frame).
    """

    scene: "Scene"
    inputs: "MetricInputs"
    settings: dict
    align: bool = False
    _loaded: dict = field(default_factory=dict, repr=False)

    def _once(self, key: str, load: Callable[[], Any]) -> Any:
        if key not in self._loaded:
            self._loaded[key] = load()
        return self._loaded[key]

    def params(self, cls, name: str):
        """``cls.from_dict`` of settings ``name`` (defaults when absent)."""
        return cls.from_dict(self.settings.get(name, {}))

    def proxies(self) -> dict:
        """The convex proxies of the scene's objects (``inputs.proxies``)."""
        from phiscene.proxies import read_proxies

        return self._once("proxies", lambda: read_proxies(self.inputs.proxies))

    def initial(self) -> "Scene":
        """The initial scene (``inputs.initial``)."""
        from phiscene.scene import load_scene

        return self._once("initial", lambda: load_scene(self.inputs.initial))

    def gt(self) -> "Scene":
        """The ground-truth scene (``inputs.gt``)."""
        from phiscene.scene import load_scene

        return self._once("gt", lambda: load_scene(self.inputs.gt))

    def sim(self):
        """The shared :class:`~phiscene.sim.settings.SimSettings`."""
        from phiscene.sim.settings import SimSettings

        return self.params(SimSettings, "sim")

    def cache_dir(self) -> Path:
        """The content-addressed cache folder."""
        return Path(self.inputs.cache_dir)


@dataclass(frozen=True)
class MetricSection:
    """One section of a metrics file.

    Attributes
    ----------
    name
        Section name (key in the metrics file).
    compute
        ``compute(ctx) -> dict`` (JSON-ready).
    settings
        Settings names it reads (``sim``, or a key of the ``metrics`` config section).
    inputs
        Input files it needs (:data:`INPUT_NAMES`).
    summary
        ``summary(result) -> str``: the one-line log of a computed section (``None``: no line).
    """

    name: str
    compute: Callable[[SectionContext], dict]
    settings: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    summary: Callable[[dict], str] | None = None

    def __post_init__(self) -> None:
        unknown = sorted(set(self.inputs) - set(INPUT_NAMES))
        if unknown:
            raise ValueError(f"metric section {self.name!r}: unknown inputs {unknown}; known: {list(INPUT_NAMES)}")


#: Registered sections by name, in computing order.
SECTIONS: dict[str, MetricSection] = {}


def register_section(section: MetricSection) -> MetricSection:
    """Add a section to :data:`SECTIONS` (``ValueError`` if the name is taken); return it."""
    if section.name in SECTIONS:
        raise ValueError(f"metric section {section.name!r} is already registered")
    SECTIONS[section.name] = section
    return section


def unregister_section(name: str) -> None:
    """Remove a section (tests and plugins that register temporarily)."""
    SECTIONS.pop(name, None)


def get_section(name: str) -> MetricSection:
    """The registered section ``name``; ``ValueError`` listing the known ones."""
    if name not in SECTIONS:
        raise ValueError(f"unknown metric section {name!r}; known: {list(SECTIONS)}")
    return SECTIONS[name]


# -- the built-in sections ------------------------------------------------------------------------------------------
def _physical(ctx: SectionContext) -> dict:
    from phiscene.metrics.physical import PhysicalParams, physical_metrics

    return physical_metrics(ctx.scene, ctx.proxies(), ctx.params(PhysicalParams, "physical"), ctx.sim(),
                            ctx.cache_dir())


def _alignment(ctx: SectionContext) -> dict:
    from phiscene.metrics.alignment import AlignmentParams, alignment_metrics

    return alignment_metrics(ctx.scene, ctx.initial(), Path(ctx.inputs.reference_dir),
                             ctx.params(AlignmentParams, "alignment"))


def _recon(ctx: SectionContext) -> dict:
    from phiscene.metrics.reconstruction import ReconParams, reconstruction_metrics

    return reconstruction_metrics(ctx.scene, ctx.gt(), ctx.params(ReconParams, "recon"))


def _pose(with_gt: bool) -> Callable[[SectionContext], dict]:
    def compute(ctx: SectionContext) -> dict:
        from phiscene.metrics.pose import PoseParams, pose_metrics

        pp = ctx.params(PoseParams, "pose")
        return {**pose_metrics(ctx.scene, ctx.initial(), ctx.gt() if with_gt else None, ctx.align, pp.samples,
                               pp.seed), "attached": len(ctx.scene.attached_ids),
                "ballasted": sum(o.com is not None for o in ctx.scene.objects),
                "bases": sum(o.base is not None for o in ctx.scene.objects)}

    return compute


def _pose_line(r: dict) -> str:
    return (f"displacement {r['displacement_mean']:.4f} m (max {r['displacement_max']:.4f}), rotation change "
            f"{r['rotation_mean']:.2f} deg (max {r['rotation_max']:.2f})")


register_section(MetricSection(
    "physical", _physical, settings=("physical", "sim"), inputs=("proxies", "cache_dir"),
    summary=lambda r: (f"pen {r['pen_depth']:.4f} m, float {r['float_dist']:.4f} m, drift {r['drift_trans']:.4f} m"
                       f" / {r['drift_rot']:.2f} deg")))
register_section(MetricSection(
    "alignment", _alignment, settings=("alignment",), inputs=("initial", "reference_dir"),
    summary=lambda r: (f"mask IoU {r['mask_iou']:.3f}, pose change {r['pose_change_trans']:.4f} m / "
                       f"{r['pose_change_rot']:.2f} deg")))
register_section(MetricSection(
    "recon", _recon, settings=("recon",), inputs=("gt",),
    summary=lambda r: (f"scene CD {r['scene_cd']:.4f}, F {r['scene_fscore']:.3f}, object CD {r['object_cd']:.4f}, "
                       f"F {r['object_fscore']:.3f}, bbox IoU {r['bbox_iou']:.3f}")))
register_section(MetricSection("pose", _pose(False), settings=("pose",), inputs=("initial",), summary=_pose_line))
register_section(MetricSection("pose_gt", _pose(True), settings=("pose",), inputs=("initial", "gt"),
                               summary=_pose_line))
