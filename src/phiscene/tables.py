"""Aggregation of per-scene metric files into the paper's tables (CSV + Markdown).

Every table has one row per method (or backend), metric columns averaged
over scenes, ``n_scenes``, and the paper's average rank (``avg_rank``: each
metric ranks the rows, 1 = best, ties share the better rank; the ranks are
averaged over the metric columns).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from phiscene.atomic import write_text

#: Physical table columns and whether lower is better.
PHYS_COLUMNS = {"pen_depth": "min", "float_dist": "min", "drift_trans": "min", "drift_rot": "min"}
#: Topology table columns and whether lower is better.
TOPO_COLUMNS = {"precision": "max", "recall": "max", "f1": "max"}


def _read(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())


def average_rank(df: pd.DataFrame, directions: dict[str, str]) -> pd.Series:
    """The paper's average rank over ``directions``' columns (1 = best; ties share the better rank)."""
    ranks = [df[c].rank(method="min", ascending=(d == "min")) for c, d in directions.items()]
    return pd.concat(ranks, axis=1).mean(axis=1)


def physical_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 2: per method the mean over scenes of the scene-level physical metrics.

    Parameters
    ----------
    files
        Method name -> per-scene physical metric JSON files.
    """
    rows = []
    for method, paths in files.items():
        vals = [_read(p) for p in paths]
        row = {"method": method}
        for c in PHYS_COLUMNS:
            row[c] = float(np.mean([v[c] for v in vals])) if vals else float("nan")
        row["n_scenes"] = len(vals)
        rows.append(row)
    df = pd.DataFrame(rows).set_index("method")
    df["avg_rank"] = average_rank(df, PHYS_COLUMNS)
    return df


def topology_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 7: per backend the micro-averaged edge precision, recall and F1 (plus the macro F1 over scenes)."""
    rows = []
    for backend, paths in files.items():
        vals = [_read(p) for p in paths]
        tp = sum(v["tp"] for v in vals)
        fp = sum(v["fp"] for v in vals)
        fn = sum(v["fn"] for v in vals)
        p = tp / (tp + fp) if tp + fp else 1.0
        r = tp / (tp + fn) if tp + fn else 1.0
        f1 = 2 * p * r / (p + r) if p + r else 0.0
        rows.append({"backend": backend, "precision": p, "recall": r, "f1": f1,
                     "f1_macro": float(np.mean([v["f1"] for v in vals])) if vals else float("nan"),
                     "tp": tp, "fp": fp, "fn": fn, "n_scenes": len(vals)})
    df = pd.DataFrame(rows).set_index("backend")
    df["avg_rank"] = average_rank(df, TOPO_COLUMNS)
    return df


def _fmt(v: float, digits: int) -> str:
    """Fixed-point like the paper, scientific for values too small to show that way."""
    if pd.isna(v):
        return "nan"
    if v != 0 and abs(v) < 0.5 * 10.0**-digits:
        return f"{v:.{max(digits - 2, 1)}e}"
    return f"{v:.{digits}f}"


def to_markdown(df: pd.DataFrame, directions: dict[str, str], digits: int = 4) -> str:
    """Markdown table with the best value of each metric in bold and the second underlined."""
    shown = df.copy().astype(object)
    for c, d in {**directions, "avg_rank": "min"}.items():
        if c not in df:
            continue
        order = df[c].rank(method="min", ascending=(d == "min"))
        for idx in df.index:
            v = df.at[idx, c]
            s = _fmt(v, digits)
            if order[idx] == 1:
                s = f"**{s}**"
            elif order[idx] == 2:
                s = f"<u>{s}</u>"
            shown.at[idx, c] = s
    return shown.to_markdown() + "\n"


def write_table(df: pd.DataFrame, csv_path: str | Path, md_path: str | Path, title: str,
                directions: dict[str, str]) -> None:
    """Write a table as CSV (6 significant digits, deterministic) and Markdown (best bold, second underlined)."""
    write_text(csv_path, df.to_csv(float_format="%.6g"))
    write_text(md_path, f"# {title}\n\n" + to_markdown(df, directions))
