"""The HTML report: table pages (phiscene.report), and a tiny workflow's report opened in headless Chromium."""

from __future__ import annotations

import base64
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from PIL import Image

from phiscene import report
from phiscene.errors import InputError
from phiscene.tables import PHYS_COLUMNS, TOPO_COLUMNS, average_rank, write_table

ROOT = Path(__file__).resolve().parents[1]


class _Cells(HTMLParser):
    """Rows of every ``<table>``: (row header, [(cell text, "b" | "u" | "")]), plus the header row."""

    def __init__(self):
        super().__init__()
        self.header: list[str] = []
        self.rows: list[tuple[str, list[tuple[str, str]]]] = []
        self._cell: list[str] | None = None
        self._mark = ""
        self._row: list = []
        self._in_head = False

    def handle_starttag(self, tag, attrs):
        if tag == "thead":
            self._in_head = True
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell, self._mark = [], ""
        elif tag in ("b", "u") and self._cell is not None:
            self._mark = tag

    def handle_endtag(self, tag):
        if tag == "thead":
            self._in_head = False
        elif tag in ("td", "th") and self._cell is not None:
            self._row.append(("".join(self._cell).strip(), self._mark))
            self._cell = None
        elif tag == "tr":
            if self._in_head:
                self.header = [t for t, _ in self._row]
            else:
                self.rows.append((self._row[0][0], self._row[1:]))

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _parse(page: str) -> _Cells:
    p = _Cells()
    p.feed(page)
    return p


def test_table_page_marks_best_and_second(tmp_path):
    # an F-score of exactly 1 (reads back from the CSV as an integer) must still rank, and counts stay integers
    df = pd.DataFrame({"backend": ["a", "b", "c", "d"], "precision": [1.0, 0.5, 0.75, 1.0],
                       "recall": [0.2, 0.9, 0.6, 0.1], "f1": [0.33, 0.64, 0.67, 0.18],
                       "tp": [3, 4, 5, 6], "n_scenes": [2, 2, 2, 2]}).set_index("backend")
    df["avg_rank"] = average_rank(df, TOPO_COLUMNS)
    write_table(df, tmp_path / "topology.csv", tmp_path / "topology.md", "t", TOPO_COLUMNS)
    out = report.tables_html({"topology": tmp_path / "topology.csv"}, tmp_path / "t.html",
                             markdown={"topology": tmp_path / "topology.md"})
    page = out.read_text()
    cells = _parse(page)
    cols = cells.header[1:]
    assert [r for r, _ in cells.rows] == ["a", "b", "c", "d"]
    for col in [*TOPO_COLUMNS, "avg_rank"]:
        values = df[col].to_numpy()
        better_first = values if col == "avg_rank" else -values  # every TOPO column: higher is better
        distinct = np.unique(better_first)
        best = {k for k in range(4) if better_first[k] == distinct[0]}
        # second = rank 2 under "ties share the better rank": only when the best value is unique
        second = {k for k in range(4) if len(best) == 1 and better_first[k] == distinct[1]}
        j = next(i for i, c in enumerate(cols) if c.split(" ")[0] == col)
        marks = [row[j][1] for _, row in cells.rows]
        assert {k for k, m in enumerate(marks) if m == "b"} == best, col
        assert {k for k, m in enumerate(marks) if m == "u"} == second, col
    j = cols.index("precision ↑")
    assert [row[j][0] for _, row in cells.rows] == ["1.0000", "0.5000", "0.7500", "1.0000"]
    assert [row[cols.index("tp")][0] for _, row in cells.rows] == ["3", "4", "5", "6"]
    # downloads carry the files byte for byte
    for name in ("topology.csv", "topology.md"):
        uri = re.search(rf'download="{re.escape(name)}" href="data:[^;]+;base64,([^"]+)"', page).group(1)
        assert base64.b64decode(uri) == (tmp_path / name).read_bytes()
    assert out.read_bytes() == report.tables_html({"topology": tmp_path / "topology.csv"}, tmp_path / "u.html",
                                                  markdown={"topology": tmp_path / "topology.md"}).read_bytes()
    # a table without one of its ranked columns, and an unknown table name
    df.drop(columns="recall").to_csv(tmp_path / "bad.csv")
    with pytest.raises(InputError, match="bad.csv: recall"):
        report.tables_html({"topology": tmp_path / "bad.csv"}, tmp_path / "x.html")
    with pytest.raises(ValueError, match="unknown table"):
        report.tables_html({"nope": tmp_path / "topology.csv"}, tmp_path / "x.html")
    assert not (tmp_path / "x.html").exists()


def test_side_by_side_is_pixel_exact(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (50, 20, 3), dtype=np.uint8)
    Image.fromarray(a).save(tmp_path / "a.png")
    Image.fromarray(b).save(tmp_path / "b.png")
    out = report.side_by_side([tmp_path / "a.png", tmp_path / "b.png"], tmp_path / "ab.png", gap=4)
    img = np.asarray(Image.open(out))
    assert img.shape == (50 + 2 * 4, 40 + 20 + 3 * 4, 3)
    assert np.array_equal(img[4:34, 4:44], a) and np.array_equal(img[4:54, 48:68], b)
    assert (img[34:, 4:44] == 255).all()  # below the shorter image: background
    with pytest.raises(InputError, match="missing.png"):
        report.side_by_side([tmp_path / "missing.png"], tmp_path / "m.png")


def test_gif_page_embeds_the_animation(tmp_path):
    frames = [Image.new("RGB", (8, 6), c) for c in ((255, 0, 0), (0, 0, 255))]
    frames[0].save(tmp_path / "d.gif", save_all=True, append_images=frames[1:], duration=100, loop=0)
    (tmp_path / "d.json").write_text('{"target": "obj_02", "ball_radius": 0.05, "seconds": 2.5, '
                                     '"object_displacement": {"obj_01": 0.0001, "obj_02": 0.25}}')
    page = report.gif_page(tmp_path / "d.gif", tmp_path / "d.html", "demo <1>", tmp_path / "d.json").read_text()
    uri = re.search(r'src="data:image/gif;base64,([^"]+)"', page).group(1)
    assert base64.b64decode(uri) == (tmp_path / "d.gif").read_bytes()
    assert "<title>demo &lt;1&gt;</title>" in page
    assert "ball of radius 5.0 cm; aimed at obj_02; 2.50 s simulated; objects moved: obj_02 25.0 cm" in page
    (tmp_path / "n.gif").write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(InputError, match="n.gif.*not a GIF"):
        report.gif_page(tmp_path / "n.gif", tmp_path / "n.html", "x")


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _run_chromium(exe: str, tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--no-first-run",
             f"--user-data-dir={tmp_path / 'chromium-profile'}", "--virtual-time-budget=10000"]
    res = subprocess.run([exe, *flags, *args], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    return res


@pytest.mark.workflow
def test_report_opens_in_chromium(tmp_path):
    exe = _chromium()
    # one contact scene, convex-hull proxies, cheap table rows, no demo animation
    tiny = {"suites": {"contact": {"n_scenes": 1}}, "proxies": {"backend": "convex"},
            "tables": {"phys": {"suite": "contact", "methods": ["gt", "initial", "phi_scene"]},
                       "topology": {"suite": "contact", "backends": ["geometric"]},
                       "crosssim": {"suite": "contact", "methods": ["initial", "phi_scene"]},
                       "recon": {"suite": "contact", "methods": ["initial", "phi_scene"]},
                       "ablation": {"suite": "contact", "methods": ["initial", "phi_scene"]},
                       **{f"{t}_clutter": None for t in ("phys", "crosssim", "topology", "recon", "ablation")}},
            "export": {"report_demos": 0}, "report": {"method": "phi_scene", "scaling": []}}
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(tiny))
    base = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path)]
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    for extra in (["-j2"], ["--report", "results/report.html"]):
        res = subprocess.run(base + extra + ["--configfile", str(tmp_path / "tiny.yaml")], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=900)
        assert res.returncode == 0, res.stderr[-4000:]
    html_path = tmp_path / "results/report.html"
    page = html_path.read_text()
    for f in ("scenes/contact/scene_000.png", "viewers/contact/scene_000.html", "tables/phys.html",
              "figures/phys_bars.png", "figures/drift_mujoco.png"):
        assert f"results/report/{f}" in page, f
    if exe is None:
        pytest.skip("no Chromium binary (chromium, chromium-browser, google-chrome) on PATH: the report was built, "
                    "but opening it is untested; install Debian's `chromium` (tools/system-deps.sh does)")
    dom = _run_chromium(exe, tmp_path, "--dump-dom", html_path.as_uri()).stdout
    # the front page (rendered by the report's JavaScript) shows every table, with the CSV's values
    from phiscene.table_registry import kind_of

    shown = [t for t, spec in tiny["tables"].items() if spec and kind_of(t, spec).report] + ["runtime"]
    assert dom.count('class="phiscene-table"') == len(shown)
    start = dom.index('id="table-phys"')
    cells = _parse(dom[start:dom.index("</table>", start) + len("</table>")])
    phys = pd.read_csv(tmp_path / "results/tables/phys.csv", index_col=0)
    shown = {name: dict(zip(cells.header[1:], (t for t, _ in row))) for name, row in cells.rows[:len(phys)]}
    assert list(shown) == list(phys.index) == ["gt", "initial", "phi_scene"]
    for m in phys.index:
        for c in PHYS_COLUMNS:
            text = shown[m][c + " ↓"]  # 4 decimals, or 3 significant digits in scientific notation
            tol = 5e-3 * abs(phys.loc[m, c]) if "e" in text else 5.1e-5
            assert float(text) == pytest.approx(phys.loc[m, c], abs=tol), (m, c, text)
    # the initial (degraded) scene penetrates most: never bold in pen_depth; the menu lists the categories
    marks = {name: row[0][1] for name, row in cells.rows[:len(phys)]}
    assert marks["initial"] == "" and "b" in marks.values()
    for cat in ("Tables", "Figures", "Scenes"):
        assert re.search(rf">\s*{cat}\s*<", dom), cat
    shot = tmp_path / "report.png"
    _run_chromium(exe, tmp_path, "--window-size=1400,1000", f"--screenshot={shot}", html_path.as_uri())
    img = np.asarray(Image.open(shot).convert("L"))
    assert img.shape == (1000, 1400) and img.std() > 20  # a drawn page, not a blank one


def test_runtime_page_keeps_stage_and_suite_apart(tmp_path):
    from phiscene.tables import runtime_table

    # the same stage on two suites: two rows, not one row label standing for both
    for suite, secs in [("contact", 1.0), ("rooms", 3.0)]:
        p = tmp_path / "bench" / "proxies" / suite / "scene_000.tsv"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("s\th:m:s\tmax_rss\tcpu_time\n" f"{secs}\t0:00:01\t100\t{secs / 2}\n")
    write_table(runtime_table(tmp_path / "bench"), tmp_path / "runtime.csv", tmp_path / "runtime.md", "Runtime", {})
    page = report.table_block("runtime", tmp_path / "runtime.csv")
    assert "<th>proxies / contact</th><td>1</td><td>1.0000</td>" in page
    assert "<th>proxies / rooms</th><td>1</td><td>3.0000</td>" in page
