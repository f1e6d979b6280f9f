"""Pages and figures of the workflow's HTML report (``snakemake --report results/report.html``).

Snakemake's report shows PNG/SVG/JPEG images and HTML pages (in a frame) and
offers every other file (CSV, Markdown, GIF) only as a download. So the
report's tables are HTML pages rendered from the tables' CSV files (best value
of each ranked metric bold, second underlined, as in the Markdown twins, whose
content they show), the demo GIF is wrapped in an HTML page, and the per-scene
figure puts the before/after renders and the support graph side by side.

Every writer works file to file, writes atomically and returns the written
path; pages are self-contained (no network, no external file) and carry no
timestamps, so the same inputs give the same bytes.
"""

from __future__ import annotations

import base64
import html
import logging
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from phiscene.atomic import atomic_path, write_text
from phiscene.errors import InputError
from phiscene.table_registry import TableKind, table_kind

log = logging.getLogger(__name__)

#: Table columns that count things (shown as integers), besides every ``n_*`` column; every other numeric
#: column is a float metric.
COUNT_COLUMNS = frozenset({"tp", "fp", "fn", "jobs"})
#: Largest HTML result (bytes) a single-file report shows in Chromium: base64 (4/3) must stay under 2 MiB.
EMBED_LIMIT_BYTES = 1_500_000
#: Gap (pixels) between and around the images of :func:`side_by_side`.
PANEL_GAP_PX = 6


_CSS = """
body{font:13px/1.4 system-ui,-apple-system,"Segoe UI",sans-serif;margin:16px;color:#222}
.phiscene-table{overflow-x:auto;margin:0 0 18px}
.phiscene-table h3{font-size:14px;margin:10px 0 4px}
.phiscene-table table{border-collapse:collapse;font-size:12px;margin:0}
.phiscene-table th,.phiscene-table td{border-bottom:1px solid #ddd;padding:3px 8px;text-align:right;white-space:nowrap}
.phiscene-table thead th{border-bottom:2px solid #444;background:#f4f4f4}
.phiscene-table tbody th{text-align:left;font-weight:600}
.phiscene-table b{color:#0a4}
.phiscene-table p{font-size:11px;color:#666;margin:2px 0}
"""
#: Extra style of the fragment on Snakemake's report front page (scoped with ``:has`` to the pane holding the
#: tables): top/left-align the content pane (it centres its content, which cuts off the top and left of a page
#: larger than the window) and let the description column grow beyond its 32rem so that wide tables fit.
_FRONT_CSS = """
div.overflow-auto:has(.phiscene-tables){align-items:flex-start;justify-content:flex-start}
div.prose:has(.phiscene-tables){max-width:64rem}
"""
_NOTE = "bold = best, underlined = second; ↓ lower is better, ↑ higher is better; avg_rank is the paper's average rank"


def read_table(table_csv: str | Path, index_columns: int = 1):
    """A table CSV of :mod:`phiscene.tables` (the first ``index_columns`` columns name the rows) as a DataFrame.

    Raises
    ------
    InputError
        The file is missing or not a table.
    """
    import pandas as pd

    table_csv = Path(table_csv)
    try:
        df = pd.read_csv(table_csv, index_col=list(range(index_columns)) if index_columns > 1 else 0)
    except Exception as exc:  # pandas raises several types
        raise InputError(table_csv, None, f"cannot read table ({type(exc).__name__}: {str(exc)[:120]})") from None
    if any(name is None for name in df.index.names):
        raise InputError(table_csv, None, "not a table (no header row naming the first column)")
    return df


def _spec(name: str, kind: str | None = None) -> TableKind:
    """The registered kind of table ``name`` (``kind``, default the name itself)."""
    return table_kind(kind or name)


def table_block(name: str, table_csv: str | Path, markdown: str | Path | None = None, kind: str | None = None,
                title: str | None = None) -> str:
    """HTML block of one table: heading, the table (best bold, second underlined), legend, downloads.

    Parameters
    ----------
    name
        The table's name (``results/tables/<name>.csv``).
    table_csv
        The table's CSV file.
    markdown
        Its Markdown twin: offered for download beside the CSV when given.
    kind
        Its kind (:mod:`phiscene.table_registry`; default ``name``).
    title
        Heading (default the kind's report title).

    Returns
    -------
    ``<div class="phiscene-table">...</div>``
    """
    import pandas as pd

    from phiscene.tables import to_html

    spec = _spec(name, kind)
    directions = spec.ranked()
    df = read_table(table_csv, spec.index_columns)
    for c in directions:
        if c not in df.columns:
            raise InputError(table_csv, c, f"ranked column of the {name} table missing")
    # the CSV does not keep int vs float: a metric whose values all print as integers (an F-score of 1)
    # reads back as int; every numeric column but the counts is a float metric
    for c in df.columns:
        if c not in COUNT_COLUMNS and not str(c).startswith("n_") and pd.api.types.is_numeric_dtype(df[c]):
            df[c] = df[c].astype(float)
    links = [_download(Path(table_csv), "text/csv")]
    if markdown is not None:
        links.append(_download(Path(markdown), "text/markdown"))
    note = _NOTE if directions else "not ranked"
    return (f'<div class="phiscene-table" id="table-{html.escape(name)}">\n'
            f"<h3>{html.escape(title or spec.title)} <small>({html.escape(Path(table_csv).name)})</small></h3>\n"
            f"{to_html(df, directions)}<p>{html.escape(note)}. Download: {' · '.join(links)}</p>\n</div>\n")


def _download(path: Path, mime: str) -> str:
    try:
        data = base64.b64encode(path.read_bytes()).decode("ascii")
    except OSError as exc:
        raise InputError(path, None, f"cannot read ({exc.strerror})") from None
    return f'<a download="{html.escape(path.name)}" href="data:{mime};base64,{data}">{html.escape(path.name)}</a>'


def tables_html(tables: dict[str, str | Path], out_html: str | Path, title: str = "phiscene tables",
                markdown: dict[str, str | Path] | None = None, fragment: bool = False,
                kinds: dict[str, str] | None = None, titles: dict[str, str] | None = None) -> Path:
    """Write the given tables as one HTML page (or a fragment to embed in another page).

    Parameters
    ----------
    tables
        Table name -> its CSV file, in page order.
    out_html
        Output file.
    title
        Page title (a standalone page only).
    markdown
        Table name -> its Markdown twin, offered for download beside the CSV.
    fragment
        Write a ``<div>`` with its own scoped style (for the report's front page) instead of a whole page.
    kinds, titles
        Table name -> its kind and heading, for tables whose name is not their kind (:func:`table_block`).

    Returns
    -------
    The written path.

    Raises
    ------
    InputError
        A table that is missing, unreadable or lacks a ranked column.
    """
    markdown, kinds, titles = markdown or {}, kinds or {}, titles or {}
    blocks = "".join(table_block(n, p, markdown.get(n), kinds.get(n), titles.get(n)) for n, p in tables.items())
    css = _CSS.replace("body{", ".phiscene-tables{").strip()
    if fragment:
        page = f'<div class="phiscene-tables"><style>{css}{_FRONT_CSS.strip()}</style>\n{blocks}</div>\n'
    else:
        page = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
                f"<style>{_CSS.strip()}</style></head>\n<body>\n{blocks}</body></html>\n")
    out_html = Path(out_html)
    write_text(out_html, page)
    return out_html


def bars_figure(name: str, table_csv: str | Path, out_png: str | Path, kind: str | None = None) -> Path:
    """Per-method bar chart of a table's metric columns (its kind says which, and the axis scale).

    Returns
    -------
    The written path (see :func:`phiscene.plots.method_bars` for its size).
    """
    from phiscene.plots import method_bars

    spec = _spec(name, kind)
    if not spec.bar_columns():
        raise ValueError(f"the {name} table has no bar chart")
    return method_bars(table_csv, out_png, spec.bar_columns(), log=spec.log)


def side_by_side(images: Sequence[str | Path], out_png: str | Path, gap: int = PANEL_GAP_PX) -> Path:
    """Place images left to right, pixel for pixel (no resampling), top-aligned on white.

    Parameters
    ----------
    images
        Image files (any format Pillow reads), drawn in this order.
    out_png
        Output PNG.
    gap
        Pixels between the images and around them.

    Returns
    -------
    The written path. Size: ``sum(w) + (n + 1) * gap`` x ``max(h) + 2 * gap`` px.
    """
    from PIL import Image

    if not images:
        raise ValueError("side_by_side needs at least one image")
    ims = []
    for p in images:
        try:
            with Image.open(p) as im:
                ims.append(im.convert("RGB"))
        except OSError as exc:
            raise InputError(p, None, f"cannot read image ({exc})") from None
    width = sum(im.width for im in ims) + (len(ims) + 1) * gap
    height = max(im.height for im in ims) + 2 * gap
    canvas = Image.new("RGB", (width, height), (255, 255, 255))
    x = gap
    for im in ims:
        canvas.paste(im, (x, gap))
        x += im.width + gap
    with atomic_path(out_png) as tmp:
        canvas.save(tmp, format="PNG")
    return Path(out_png)


def display_colors(scene) -> dict[str, tuple[int, int, int]]:
    """Object id -> the RGB (0-255) the renders show it in: ``meta["rgb"]``, else the segmentation colour."""
    out = {}
    for o in scene.objects:
        rgb = o.meta.get("rgb") if o.meta.get("rgb") is not None else o.color
        if rgb is not None:
            out[o.id] = tuple(int(c) for c in np.asarray(rgb)[:3])
    return out


def scene_panel(initial_json: str | Path, method_json: str | Path, camera_json: str | Path,
                topology_json: str | Path, out_png: str | Path, title: str,
                labels: tuple[str, str] = ("initial", "method")) -> Path:
    """The report's picture of one scene: before/after renders with the support graph beside them.

    Left: :func:`phiscene.plots.before_after` (initial vs the method's scene, from the reference
    camera and from an oblique view). Right: :func:`phiscene.plots.support_graph_figure` of
    ``topology_json``, its nodes filled with the objects' render colours.

    Parameters
    ----------
    initial_json, method_json
        The two ``scene.json`` files (left and right column of the renders).
    camera_json
        The scene's reference ``camera.json``.
    topology_json
        The support graph to draw (``phiscene.topology/1``).
    out_png
        Output PNG.
    title
        Title of the graph (e.g. ``contact/scene_003``).
    labels
        Captions of the two render columns.

    Returns
    -------
    The written path. Size: see :func:`side_by_side` of the two figures.
    """
    from phiscene.plots import before_after, support_graph_figure
    from phiscene.scene import load_scene

    initial, method = load_scene(initial_json), load_scene(method_json)
    with tempfile.TemporaryDirectory(prefix="phiscene_panel_") as tmp:
        renders = before_after(initial, method, camera_json, Path(tmp) / "renders.png", labels=labels)
        graph = support_graph_figure(topology_json, Path(tmp) / "graph.png", title, colors=display_colors(method))
        return side_by_side([renders, graph], out_png)


def scene_viewer(scene_json: str | Path, out_html: str | Path, title: str, color_by: str = "rgb") -> Path:
    """Interactive offline 3D viewer page of one ``scene.json`` (see :func:`phiscene.viewer.scene_viewer_html`).

    Logs a warning when the page is larger than :data:`EMBED_LIMIT_BYTES`: the single-file report
    shows HTML results as base64 ``data:`` URLs, which Chromium refuses beyond 2 MiB (``--report *.zip`` does not).
    """
    from phiscene.scene import load_scene
    from phiscene.viewer import scene_viewer_html

    out = scene_viewer_html(load_scene(scene_json), out_html, title, color_by=color_by)
    size = out.stat().st_size
    if size > EMBED_LIMIT_BYTES:
        log.warning("%s: %.2f MB, too large to show inside a single-file report in Chromium (data: URLs > 2 MiB); "
                    "use `snakemake --report results/report.zip`", out, size / 1e6)
    return out


def demo_caption(summary_json: str | Path) -> str:
    """One line describing a demo run from its summary (``results/demo/{suite}/{scene}.json``).

    Uses the summary's ``target``, ``ball_radius`` (m), ``seconds`` and ``object_displacement``
    (object id -> m); keys it lacks are left out of the line.

    Raises
    ------
    InputError
        The file is missing or not a JSON object.
    """
    import json

    summary_json = Path(summary_json)
    try:
        data = json.loads(summary_json.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(summary_json, None, f"cannot read demo summary ({type(exc).__name__}: {str(exc)[:120]})") \
            from None
    if not isinstance(data, dict):
        raise InputError(summary_json, None, "not a JSON object")
    parts = []
    if isinstance(data.get("ball_radius"), (int, float)):
        parts.append(f"ball of radius {100 * data['ball_radius']:.1f} cm")
    if data.get("target"):
        parts.append(f"aimed at {data['target']}")
    if isinstance(data.get("seconds"), (int, float)):
        parts.append(f"{data['seconds']:.2f} s simulated")
    moved = data.get("object_displacement")
    if isinstance(moved, dict) and moved:
        big = sorted(((float(v), k) for k, v in moved.items()), reverse=True)
        shown = [f"{k} {v * 100:.1f} cm" for v, k in big if v >= 1e-3]
        parts.append("objects moved: " + (", ".join(shown) if shown else "none by 1 mm or more")
                     + (f" (the other {len(big) - len(shown)} < 1 mm)" if shown and len(shown) < len(big) else ""))
    return "; ".join(parts)


def gif_page(gif: str | Path, out_html: str | Path, title: str, summary_json: str | Path | None = None) -> Path:
    """A self-contained HTML page showing an animated GIF (the report offers bare GIFs only as downloads).

    Parameters
    ----------
    gif
        The GIF file (embedded as a ``data:`` URI).
    out_html
        Output page.
    title
        Page title and heading.
    summary_json
        The demo's summary: :func:`demo_caption` of it is shown under the animation.

    Returns
    -------
    The written path.

    Raises
    ------
    InputError
        The GIF is missing or not a GIF, or the summary is unreadable.
    """
    gif = Path(gif)
    try:
        data = gif.read_bytes()
    except OSError as exc:
        raise InputError(gif, None, f"cannot read ({exc.strerror})") from None
    if data[:6] not in (b"GIF87a", b"GIF89a"):
        raise InputError(gif, None, "not a GIF file (no GIF87a/GIF89a header)")
    caption = demo_caption(summary_json) if summary_json is not None else ""
    uri = "data:image/gif;base64," + base64.b64encode(data).decode("ascii")
    page = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
            "<style>body{font:13px system-ui,sans-serif;margin:16px}img{max-width:100%}</style></head>\n"
            f'<body><h3>{html.escape(title)}</h3><img alt="{html.escape(title)}" src="{uri}">'
            f"<p>{html.escape(caption)}</p></body></html>\n")
    out_html = Path(out_html)
    write_text(out_html, page)
    return out_html
