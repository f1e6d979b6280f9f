"""Figures of the report: metric bars, drift distributions, support graphs, before/after renders.

Every function draws on a bare :class:`matplotlib.figure.Figure` with the Agg
canvas (no pyplot, no global backend switch), writes its file atomically
(:func:`phiscene.atomic.atomic_path`) and returns the path. The output format
follows the file suffix (``.png``, ``.svg`` or ``.pdf``).

Reproducibility: figure sizes are fixed functions of the data shape (stated
in each docstring, in pixels at :data:`DPI`), and files carry no timestamps or
version strings (PNG ``Software``, SVG ``Date``/``Creator``, PDF dates and
producer are cleared; SVG ids use a fixed hash salt), so the same inputs give
the same bytes on the same machine.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from phiscene.atomic import atomic_path
from phiscene.errors import InputError
from phiscene.scene import Scene

#: Resolution of every figure (pixels per inch).
DPI = 100
#: Size of one metric panel of :func:`method_bars` (pixels).
BAR_PANEL_PX = (320, 300)
#: Panels per row of :func:`method_bars`.
BAR_PANELS_PER_ROW = 4
#: Height of :func:`drift_distribution` (pixels); its width is ``2 * drift_panel_width(n_methods)``.
DRIFT_HEIGHT_PX = 360
#: Node spacing of :func:`support_graph_figure` (pixels per layer slot, per layer) and its minimum size.
GRAPH_SLOT_PX = (150, 120)
GRAPH_MIN_PX = (480, 360)
#: Title strip above each image of :func:`before_after` and the gap between images (pixels).
CAPTION_PX = 22
GAP_PX = 6
#: Azimuth step (deg) from the reference camera to the oblique view of :func:`before_after`.
OBLIQUE_AZIMUTH_DEG = 60.0

_METADATA = {
    "png": {"Software": None},
    "svg": {"Date": None, "Creator": None},
    "pdf": {"CreationDate": None, "ModDate": None, "Creator": None, "Producer": None},
}
_RC = {"svg.hashsalt": "phiscene", "font.family": "DejaVu Sans", "font.size": 9, "axes.titlesize": 10}


def _figure(width_px: int, height_px: int):
    """A bare Agg figure of exactly ``width_px`` x ``height_px`` pixels at :data:`DPI`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` atomically, format from the suffix, without timestamps."""
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in _METADATA:
        raise ValueError(f"unsupported figure format {path.suffix!r} for {path}; use one of {sorted(_METADATA)}")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, dpi=DPI, metadata=_METADATA[fmt])
    return path


def _rc():
    import matplotlib

    return matplotlib.rc_context(_RC)


def _method_colors(n: int) -> list:
    """``n`` qualitative colours (tab10, cycled)."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return [cmap(k % 10) for k in range(n)]


def _fmt(v: float) -> str:
    return "n/a" if not np.isfinite(v) else f"{v:.3g}"


def method_bars(table_csv: str | Path, out_png: str | Path, columns: Sequence[str], log: bool = False) -> Path:
    """Bar chart per metric column of a table: one bar per row (method or backend), value on top.

    Parameters
    ----------
    table_csv
        A table written by :mod:`phiscene.tables` (first column = row names).
    out_png
        Output figure.
    columns
        Metric columns to draw, one panel each.
    log
        Logarithmic value axes (rows with values <= 0 are then left out of a panel).

    Returns
    -------
    The written path. Size: ``min(n, 4) * 320`` x ``ceil(n / 4) * 300`` px for ``n`` columns.

    Raises
    ------
    InputError
        Unreadable table or a column it lacks.
    """
    import pandas as pd

    table_csv = Path(table_csv)
    try:
        df = pd.read_csv(table_csv, index_col=0)
    except Exception as exc:  # pandas raises several types
        raise InputError(table_csv, None, f"cannot read table ({type(exc).__name__}: {str(exc)[:120]})") from None
    columns = list(columns)
    if not columns:
        raise ValueError("method_bars needs at least one column")
    for c in columns:
        if c not in df.columns:
            raise InputError(table_csv, c, f"no such column (columns: {', '.join(map(str, df.columns))})")
    n_cols = min(len(columns), BAR_PANELS_PER_ROW)
    n_rows = math.ceil(len(columns) / BAR_PANELS_PER_ROW)
    names = [str(i) for i in df.index]
    colors = _method_colors(len(names))
    x = np.arange(len(names))
    with _rc():
        fig = _figure(n_cols * BAR_PANEL_PX[0], n_rows * BAR_PANEL_PX[1])
        fig.set_layout_engine("constrained")
        axes = fig.subplots(n_rows, n_cols, squeeze=False)
        for ax in axes.ravel()[len(columns):]:
            ax.set_visible(False)
        for ax, c in zip(axes.ravel(), columns):
            vals = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=float)
            ok = np.isfinite(vals) & ((vals > 0) if log else True)
            ax.bar(x[ok], vals[ok], color=[colors[k] for k in np.flatnonzero(ok)], width=0.7)
            if log and ok.any():
                ax.set_yscale("log")
            for k in range(len(names)):
                y = vals[k] if ok[k] else (ax.get_ylim()[0] if log else 0.0)
                ax.annotate(_fmt(vals[k]), (x[k], y), xytext=(0, 2), textcoords="offset points", ha="center",
                            va="bottom", fontsize=7)
            ax.set_title(c)
            ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
            ax.margins(y=0.15)
            ax.grid(axis="y", alpha=0.3)
        return _save(fig, out_png)


def drift_panel_width(n_methods: int) -> int:
    """Width (px) of one panel of :func:`drift_distribution`: 100 px per method, at least 320."""
    return max(320, 100 * n_methods)


def _read_drift(path: Path, section: str) -> tuple[float, float] | None:
    """``(drift_trans, drift_rot)`` of one metrics file's section; ``None`` for a failed scene's record."""
    from phiscene.failures import is_failure_record
    from phiscene.metrics.evaluate import read_section

    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise InputError(path, None, f"cannot read metric file ({type(exc).__name__}: {str(exc)[:120]})") from None
    values = read_section(data, section, path)
    if is_failure_record(values):
        return None
    out = []
    for key in ("drift_trans", "drift_rot"):
        v = values.get(key)
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise InputError(path, f"{section}.{key}", "missing or not a number")
        out.append(float(v))
    return out[0], out[1]


def _value_scale(ax, values: np.ndarray) -> None:
    """Log axis for positive data, symmetric log (linear below the smallest positive decade) with zeros."""
    pos = values[values > 0]
    if len(pos) == 0:
        return
    if (values > 0).all():
        ax.set_yscale("log")
    else:
        ax.set_yscale("symlog", linthresh=10.0 ** math.floor(math.log10(pos.min())))


def drift_distribution(metric_files_by_method: dict[str, list[str | Path]], out_png: str | Path,
                       seed: int = 0, section: str = "physical") -> Path:
    """Per-scene distribution of the drift metrics per method: box plot plus the scenes as points.

    Parameters
    ----------
    metric_files_by_method
        Method name -> per-scene metrics files (:mod:`phiscene.metrics.evaluate`); failed scenes'
        records are left out (the tables count them).
    out_png
        Output figure.
    seed
        Seed of the horizontal jitter of the points.
    section
        The section whose ``drift_trans`` (m) and ``drift_rot`` (deg) are shown: ``physical`` (pybullet)
        or ``mujoco``.

    Returns
    -------
    The written path. Size: ``2 * drift_panel_width(n_methods)`` x 360 px. Axes are logarithmic
    (symmetric-log when some scene has zero drift).

    Raises
    ------
    InputError
        A metric file that is unreadable, not a metrics file, or lacks the section or a drift value.
    """
    methods = list(metric_files_by_method)
    if not methods:
        raise ValueError("drift_distribution needs at least one method")
    data = {}
    for m in methods:
        values = [_read_drift(Path(p), section) for p in metric_files_by_method[m]]
        data[m] = np.array([v for v in values if v is not None], dtype=float).reshape(-1, 2)
    rng = np.random.default_rng(seed)
    colors = _method_colors(len(methods))
    with _rc():
        fig = _figure(2 * drift_panel_width(len(methods)), DRIFT_HEIGHT_PX)
        fig.set_layout_engine("constrained")
        axes = fig.subplots(1, 2, squeeze=False)[0]
        for j, (ax, label) in enumerate(zip(axes, ("drift_trans (m)", "drift_rot (deg)"))):
            cols = [data[m][:, j] for m in methods]
            pos = [k for k, v in enumerate(cols) if len(v)]
            if pos:
                ax.boxplot([cols[k] for k in pos], positions=pos, widths=0.5, showfliers=False,
                           medianprops={"color": "black"})
            for k, v in enumerate(cols):
                jitter = rng.uniform(-0.15, 0.15, size=len(v))
                ax.scatter(k + jitter, v, s=12, color=colors[k], alpha=0.8, zorder=3, linewidths=0)
            _value_scale(ax, np.concatenate(cols) if cols else np.zeros(0))
            ax.set_xticks(range(len(methods)), [f"{m} (n={len(data[m])})" for m in methods], rotation=30,
                          ha="right", fontsize=8)
            ax.set_xlim(-0.6, len(methods) - 0.4)
            ax.set_title(label)
            ax.grid(axis="y", alpha=0.3)
        return _save(fig, out_png)


def graph_layers(graph) -> dict[str, int]:
    """Layer of every node of a support graph: ground 0, an object 1 + the highest layer of its supporters.

    Layers are longest-path depths over the kept edges; nodes on a cycle (a graph whose cycles
    were not broken) share the layer of their strongly connected component.

    Parameters
    ----------
    graph : phiscene.topology.graph.SupportGraph

    Returns
    -------
    node -> layer (ground 0, objects >= 1)
    """
    import networkx as nx

    g = graph.to_networkx(include_ground=True)
    cond = nx.condensation(g)
    layer_of_scc: dict[int, int] = {}
    for c in nx.topological_sort(cond):
        members = cond.nodes[c]["members"]
        preds = list(cond.predecessors(c))
        base = 0 if members & graph.fixed_nodes else 1  # the ground and walls at the bottom
        layer_of_scc[c] = max([base] + [layer_of_scc[p] + 1 for p in preds])
    return {n: layer_of_scc[cond.graph["mapping"][n]] for n in g.nodes}


def graph_positions(graph) -> dict[str, tuple[float, float]]:
    """Layered drawing positions: ``y`` = layer (ground at the bottom), ``x`` spread within a layer.

    Within a layer, nodes are sorted by the mean ``x`` of their supporters (fewer crossings), then by
    their place in ``graph.order`` (file order when there is none), and centred on ``x = 0``.

    Returns
    -------
    node -> (x, y)
    """
    layers = graph_layers(graph)
    rank = {n: k for k, n in enumerate(graph.order or graph.object_ids)}
    pos: dict[str, tuple[float, float]] = {}
    for L in range(max(layers.values()) + 1):
        nodes = [n for n in [*graph.objects, *graph.structure] if layers[n] == L]

        def key(n: str) -> tuple[float, int]:
            xs = [pos[p][0] for p in graph.parents(n) if p in pos]
            return (float(np.mean(xs)) if xs else 0.0, rank.get(n, -1))

        nodes.sort(key=key)
        for k, n in enumerate(nodes):
            pos[n] = (k - (len(nodes) - 1) / 2, float(L))
    return pos


def support_graph_figure(topology_json: str | Path, out_png: str | Path, title: str,
                         colors: dict[str, Sequence[int]] | None = None) -> Path:
    """Draw a support graph: ground at the bottom, supported objects above their supporters.

    Kept edges are solid black arrows, dropped (cycle-breaking) edges dashed red; every edge is
    labelled with its relation. Edges are drawn as arcs, so the two directions of a pair stay apart.

    Parameters
    ----------
    topology_json
        A topology file (``phiscene.topology/1``).
    out_png
        Output figure.
    title
        Figure title.
    colors
        Optional object id -> RGB (0-255) fill of its node (e.g. the segmentation colours); default light blue.

    Returns
    -------
    The written path. Size: ``max(480, 150 * widest layer)`` x ``max(360, 120 * (layers + 1))`` px.

    Raises
    ------
    InputError
        An invalid topology file (see :func:`phiscene.topology.graph.load`).
    """
    import networkx as nx

    from phiscene.topology.graph import GROUND, load

    graph = load(topology_json)
    pos = graph_positions(graph)
    n_layers = int(max(y for _, y in pos.values())) + 1
    widest = max(sum(1 for _, y in pos.values() if y == L) for L in range(n_layers))
    width = max(GRAPH_MIN_PX[0], GRAPH_SLOT_PX[0] * widest)
    height = max(GRAPH_MIN_PX[1], GRAPH_SLOT_PX[1] * (n_layers + 1))
    kept, dropped = nx.DiGraph(), nx.DiGraph()
    for g, edges in ((kept, graph.edges), (dropped, graph.dropped_edges)):
        g.add_nodes_from([*graph.objects, *graph.structure])
        for e in edges:
            g.add_edge(e.source, e.target, relation=e.relation)
    objects = graph.object_ids
    fill = [tuple(c / 255 for c in colors[o]) if colors and o in colors else (0.75, 0.85, 0.95) for o in objects]
    arc = "arc3,rad=0.15"
    node_size = 900
    with _rc():
        fig = _figure(width, height)
        ax = fig.add_axes((0.02, 0.02, 0.96, 0.86))
        fixed = [GROUND, *graph.structure]  # the ground and the walls: brown squares
        nx.draw_networkx_nodes(kept, pos, nodelist=fixed, node_shape="s", node_color=[(0.6, 0.5, 0.4)] * len(fixed),
                               node_size=node_size * 1.6, ax=ax)
        nx.draw_networkx_nodes(kept, pos, nodelist=objects, node_color=fill, edgecolors="black", linewidths=0.8,
                               node_size=node_size, ax=ax)
        nx.draw_networkx_labels(kept, pos, font_size=8, ax=ax)
        for g, style, color in ((kept, "solid", "black"), (dropped, "dashed", "tab:red")):
            if g.number_of_edges() == 0:
                continue
            nx.draw_networkx_edges(g, pos, style=style, edge_color=color, arrows=True, arrowsize=14,
                                   connectionstyle=arc, node_size=node_size, ax=ax)
            nx.draw_networkx_edge_labels(g, pos, edge_labels=nx.get_edge_attributes(g, "relation"),
                                         font_size=7, font_color=color, connectionstyle=arc, node_size=node_size,
                                         bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none",
                                               "alpha": 0.8}, ax=ax)
        xs = [x for x, _ in pos.values()]
        ax.set_xlim(min(xs) - 0.7, max(xs) + 0.7)
        ax.set_ylim(-0.6, n_layers - 0.4)
        ax.axis("off")
        n_drop = len(graph.dropped_edges)
        sub = f"{graph.backend or 'topology'}: {len(graph.edges)} edges" + (f", {n_drop} dropped (dashed)"
                                                                            if n_drop else "")
        fig.suptitle(f"{title}\n{sub}", fontsize=10)
        return _save(fig, out_png)


def orbit_camera(camera: dict, azimuth_deg: float, bounds: np.ndarray | None = None) -> dict:
    """The reference camera swung by ``azimuth_deg`` about the vertical axis through its target.

    Parameters
    ----------
    camera
        A camera dict (``camera.json``, see :mod:`phiscene.render`) with ``eye`` and ``target``.
    azimuth_deg
        Rotation (deg, counter-clockwise seen from above).
    bounds : (2, 3) float, optional
        World box that must stay in view: the camera backs off along its new direction when needed
        (by the benchmark's framing margin), and never comes closer than the reference camera.

    Returns
    -------
    camera dict of the same image size, field of view and clipping planes.
    """
    from phiscene.render import RenderParams, fit_distance, look_at_camera
    from phiscene.transforms import rotation_z

    eye, target = np.asarray(camera["eye"], dtype=float), np.asarray(camera["target"], dtype=float)
    back = rotation_z(np.radians(azimuth_deg)) @ (eye - target)
    dist = float(np.linalg.norm(back))
    back /= dist
    W, H = int(camera["width"]), int(camera["height"])
    pb = camera["pybullet"]
    if bounds is not None:
        need = fit_distance(np.asarray(bounds, dtype=float), target, back, np.radians(pb["fov_y_deg"]) / 2, W / H)
        dist = max(dist, RenderParams().margin * need)
    return look_at_camera(target + dist * back, target, W, H, pb["fov_y_deg"], pb["near"], pb["far"])


def before_after(initial_scene: Scene, method_scene: Scene, camera_json: str | Path, out_png: str | Path,
                 labels: tuple[str, str] = ("initial", "method"),
                 oblique_deg: float = OBLIQUE_AZIMUTH_DEG) -> Path:
    """Side-by-side renders of the initial and the method scene from the reference and an oblique view.

    Row 1 is the reference camera, row 2 the reference camera swung by ``oblique_deg`` about the
    vertical axis through its target (backed off so both scenes fit). Objects are drawn in their
    ``meta["rgb"]`` colour (else the segmentation colour) by :func:`phiscene.render.render`;
    images are placed pixel for pixel (no resampling).

    Parameters
    ----------
    initial_scene, method_scene
        The two scenes (left and right column).
    camera_json
        The reference ``camera.json``.
    out_png
        Output figure.
    labels
        Column captions.
    oblique_deg
        Azimuth step of the second row (deg).

    Returns
    -------
    The written path. Size: ``2 W + 3 * 6`` x ``2 (H + 22) + 3 * 6`` px for a W x H camera.
    """
    from phiscene.render import read_camera, render, scene_bounds

    cam = read_camera(camera_json)
    bounds = np.concatenate([scene_bounds(initial_scene), scene_bounds(method_scene)])
    bounds = np.array([bounds.min(axis=0), bounds.max(axis=0)])
    views = [("reference view", cam), (f"oblique view ({oblique_deg:+.0f}°)", orbit_camera(cam, oblique_deg, bounds))]
    W, H = int(cam["width"]), int(cam["height"])
    fw, fh = 2 * W + 3 * GAP_PX, 2 * (H + CAPTION_PX) + 3 * GAP_PX
    with _rc():
        fig = _figure(fw, fh)
        for r, (view_name, c) in enumerate(views):
            for k, (scene, name) in enumerate(zip((initial_scene, method_scene), labels)):
                rgb = render(scene, c)
                left = GAP_PX + k * (W + GAP_PX)
                top = GAP_PX + r * (H + CAPTION_PX + GAP_PX) + CAPTION_PX
                ax = fig.add_axes((left / fw, 1 - (top + H) / fh, W / fw, H / fh))
                ax.imshow(rgb, interpolation="nearest", aspect="auto")
                ax.set_axis_off()
                fig.text((left + W / 2) / fw, 1 - (top - 4) / fh, f"{name} — {view_name}", ha="center",
                         va="bottom", fontsize=9)
        return _save(fig, out_png)
