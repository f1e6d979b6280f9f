"""Registry of table kinds: every table of ``results/tables/`` is one entry here plus one ``tables:`` config entry.

A :class:`TableKind` says everything the workflow, the tables writer and the report need of a table: how to
build it from its inputs (:class:`TableInputs`), its ranked columns, the metric sections it reads from the
methods' per-scene metrics files (so the metrics jobs compute exactly those), which inputs the generic ``table``
rule gathers for it, its titles, its bar chart and footnote. A ``tables.<name>`` config entry makes a table of
a kind (``kind:``, default the name) on one suite for a list of rows (``methods``, or ``backends``), so the same
kind can show several suites (``phys`` on ``contact``, ``phys_clutter`` on ``clutter``)::

    tables:
      phys_clutter: {kind: phys, suite: clutter, methods: [initial, phi_scene]}

Adding a new kind is one :func:`register_table` call (the workflow's ``table`` rule, ``rule all``, the report's
pages and bar figures and the metrics jobs read the registry) plus its config entry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from phiscene import tables as T

#: How the ``table`` rule gathers a kind's inputs: per-scene metrics files of each method, predicted support
#: graphs of each backend (and the ground truth's), or the Snakemake benchmark TSVs of every other table's jobs.
READS = ("metrics", "topology", "benchmarks")


@dataclass(frozen=True)
class TableInputs:
    """What a table is built from.

    Attributes
    ----------
    files
        Row name (method or backend) -> its per-scene files (metrics files, or predicted graphs), in ``scenes``
        order.
    scenes
        Scene ids of the table's suite.
    gt_files
        Ground-truth support graphs, one per scene (``reads="topology"``).
    logs
        Method -> per-scene assembly logs (kinds with ``logs=True``; grounding methods only).
    benchmark_dir
        Folder of the Snakemake benchmark TSVs (``reads="benchmarks"``).
    """

    files: dict[str, list] = field(default_factory=dict)
    scenes: list[str] = field(default_factory=list)
    gt_files: list = field(default_factory=list)
    logs: dict[str, list] = field(default_factory=dict)
    benchmark_dir: str | Path | None = None


def _value(v):
    """A field that may be given as a function (evaluated now, so that later registrations count)."""
    return v() if callable(v) else v


@dataclass(frozen=True)
class TableKind:
    """One kind of table.

    Attributes
    ----------
    name
        Kind name (a ``tables.<name>`` config entry without ``kind:`` is of this kind).
    heading
        Markdown heading of the table file.
    title
        Heading of its report page.
    build
        ``build(inputs) -> DataFrame`` (one row per method or backend).
    directions
        Ranked columns -> ``"min"`` / ``"max"``, or a function returning them.
    sections
        Metric sections it reads from the methods' metrics files, or a function returning them.
    reads
        Inputs the ``table`` rule gathers (:data:`READS`).
    rows
        Config key listing the rows (``methods`` or ``backends``; ``None``: no rows, e.g. runtime).
    logs
        Also gather the assembly logs of its phi_scene-kind methods.
    scene_rows
        ``scene_rows(inputs) -> DataFrame`` of per-(row, scene) values, written as ``<table>_scenes.csv``
        (``None``: no such file).
    note
        Footnote appended to the Markdown.
    bars
        Columns of its report bar chart, or a function returning them (empty: no chart).
    log
        Logarithmic bar axes.
    index_columns
        Leading CSV columns that name a row.
    report
        The report shows it.
    """

    name: str
    heading: str
    title: str
    build: Callable[[TableInputs], pd.DataFrame]
    directions: dict | Callable[[], dict] = field(default_factory=dict)
    sections: tuple | Callable[[], tuple] = ()
    reads: str = "metrics"
    rows: str | None = "methods"
    logs: bool = False
    scene_rows: Callable[[TableInputs], pd.DataFrame] | None = None
    note: str = ""
    bars: tuple | Callable[[], tuple] = ()
    log: bool = False
    index_columns: int = 1
    report: bool = True

    def __post_init__(self) -> None:
        if self.reads not in READS:
            raise ValueError(f"table kind {self.name!r}: reads must be one of {READS}, got {self.reads!r}")

    def ranked(self) -> dict:
        """Ranked columns -> direction."""
        return dict(_value(self.directions))

    def metric_sections(self) -> tuple[str, ...]:
        """Metric sections it reads."""
        return tuple(_value(self.sections))

    def bar_columns(self) -> tuple[str, ...]:
        """Columns of its bar chart."""
        return tuple(_value(self.bars))


#: Registered table kinds by name, in registration order.
TABLE_KINDS: dict[str, TableKind] = {}


def register_table(kind: TableKind) -> TableKind:
    """Add a table kind (``ValueError`` if the name is taken); return it."""
    if kind.name in TABLE_KINDS:
        raise ValueError(f"table kind {kind.name!r} is already registered")
    TABLE_KINDS[kind.name] = kind
    return kind


def unregister_table(name: str) -> None:
    """Remove a table kind (tests and temporary plugins)."""
    TABLE_KINDS.pop(name, None)


def table_kind(name: str) -> TableKind:
    """The registered kind ``name``; ``ValueError`` listing the known ones."""
    if name not in TABLE_KINDS:
        raise ValueError(f"unknown table kind {name!r}; known: {list(TABLE_KINDS)}")
    return TABLE_KINDS[name]


def kind_of(name: str, spec: dict | None) -> TableKind:
    """The kind of configured table ``name`` (its ``kind:``, default the name itself)."""
    return table_kind((spec or {}).get("kind", name))


def heading_of(name: str, spec: dict | None) -> str:
    """Markdown heading of configured table ``name``: its kind's, with the suite when the name is not the kind's."""
    kind = kind_of(name, spec)
    if name == kind.name or not spec or "suite" not in spec:
        return kind.heading
    return f"{kind.heading} ({spec['suite']} suite)"


def write_kind_table(kind: TableKind, inputs: TableInputs, csv_path: str | Path, md_path: str | Path,
                     heading: str | None = None) -> None:
    """Build a table of ``kind`` and write its CSV and Markdown (with the kind's note).

    Parameters
    ----------
    kind
        The table's kind.
    inputs
        What it is built from.
    csv_path, md_path
        Output files (:func:`phiscene.tables.write_table`).
    heading
        Markdown heading (default the kind's).
    """
    from phiscene.atomic import write_text

    T.write_table(kind.build(inputs), csv_path, md_path, title=heading or kind.heading, directions=kind.ranked())
    if kind.note:
        write_text(md_path, Path(md_path).read_text() + "\n" + kind.note + "\n")


def write_scene_rows(kind: TableKind, inputs: TableInputs, csv_path: str | Path) -> None:
    """Write the per-(row, scene) CSV of a kind with ``scene_rows`` (``ValueError`` for one without)."""
    from phiscene.atomic import write_text

    if kind.scene_rows is None:
        raise ValueError(f"table kind {kind.name!r} has no per-scene rows")
    write_text(csv_path, kind.scene_rows(inputs).to_csv(float_format="%.6g"))


# -- the built-in kinds (paper tables and the real-scene table) -----------------------------------------------------
def _crosssim_sections() -> tuple[str, ...]:
    from phiscene.metrics.drift import table_simulators

    return tuple(dict.fromkeys(s.section for s in table_simulators()))


def _crosssim_ranked() -> dict:
    from phiscene.metrics.drift import table_simulators

    return {f"{k}_{s.column}": "min" for s in table_simulators() if s.ranked for k in ("drift_trans", "drift_rot")}


def _crosssim_bars() -> tuple[str, ...]:
    from phiscene.metrics.drift import table_simulators

    return tuple(f"{k}_{s.column}" for s in table_simulators() for k in ("drift_trans", "drift_rot"))


def _crosssim(inputs: TableInputs) -> pd.DataFrame:
    from phiscene.metrics.drift import table_simulators

    return T.crosssim_table(inputs.files, [(s.section, s.column, s.ranked) for s in table_simulators()])


register_table(TableKind(
    "phys", "Physical plausibility", "Physical plausibility (paper Tab. 2; metres, degrees)",
    lambda i: T.physical_table(i.files), T.PHYS_COLUMNS, ("physical", "pose_gt"), bars=tuple(T.PHYS_COLUMNS),
    log=True))
register_table(TableKind(
    "crosssim", "Cross-simulator drift (MuJoCo; pybullet beside it)",
    "Cross-simulator drift (paper Tab. 3; MuJoCo ranked, pybullet beside)", _crosssim, _crosssim_ranked,
    _crosssim_sections, bars=_crosssim_bars, log=True))
register_table(TableKind(
    "ablation", "Ablation: ordering, joint vs sequential, settling stages",
    "Ablations and baselines (paper Tab. 6; mask IoU in place of CLIP-I)", lambda i: T.ablation_table(i.files),
    T.ABLATION_COLUMNS, ("physical", "alignment", "pose_gt"), bars=tuple(T.ABLATION_COLUMNS), log=True))
register_table(TableKind(
    "recon", "Reconstruction against ground truth",
    "Reconstruction against ground truth (paper Tab. 1; MIDI-3D protocol)", lambda i: T.recon_table(i.files),
    T.RECON_COLUMNS, ("recon",), bars=tuple(T.RECON_COLUMNS)))
register_table(TableKind(
    "real", "Real scenes: physical plausibility and faithfulness to the levelled input",
    "Real scenes (physical plausibility, faithfulness to the levelled input)",
    lambda i: T.real_table(i.files, i.scenes, i.logs), T.REAL_COLUMNS, ("physical", "mujoco", "pose"), logs=True,
    scene_rows=lambda i: T.real_scene_rows(i.files, i.scenes, i.logs), note=T.ATTACHED_NOTE, report=False))
register_table(TableKind(
    "topology", "Support graph accuracy", "Support graph accuracy (paper Tab. 7; edges against ground truth)",
    lambda i: T.topology_table(i.files, i.gt_files), T.TOPO_COLUMNS, reads="topology", rows="backends",
    bars=(*T.TOPO_COLUMNS, "f1_macro")))
register_table(TableKind(
    "runtime", "Runtime per stage", "Runtime per stage (seconds, MB)",
    lambda i: T.runtime_table(i.benchmark_dir), reads="benchmarks", rows=None, index_columns=2))
