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
#: Cross-simulator table: ranked on the MuJoCo drift (the independent engine); pybullet shown beside it.
CROSSSIM_COLUMNS = {"drift_trans_mujoco": "min", "drift_rot_mujoco": "min"}
#: Reconstruction table (paper Tab. 1): ranked columns; the ICP-only and raw-IoU variants are shown unranked.
RECON_COLUMNS = {"scene_cd": "min", "scene_fscore": "max", "object_cd": "min", "object_fscore": "max",
                 "bbox_iou": "max"}
RECON_EXTRA = ["scene_cd_icp", "scene_fscore_icp", "bbox_iou_raw"]
#: Ablation table (paper Tab. 6): reference alignment (mask IoU in place of CLIP-I) + the physical metrics.
ABLATION_COLUMNS = {"mask_iou": "max", **PHYS_COLUMNS}


def _read(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())


def average_rank(df: pd.DataFrame, directions: dict[str, str]) -> pd.Series:
    """The paper's average rank over ``directions``' columns (1 = best; ties share the better rank)."""
    ranks = [df[c].rank(method="min", ascending=(d == "min")) for c, d in directions.items()]
    return pd.concat(ranks, axis=1).mean(axis=1)


def mean_table(files: dict[str, list[str | Path]], keys: list[str], suffix: str = "") -> pd.DataFrame:
    """Per row name, the mean over its per-scene JSON files of each key (columns ``key + suffix``, plus ``n_scenes``)."""
    rows = []
    for name, paths in files.items():
        vals = [_read(p) for p in paths]
        row = {"method": name}
        for k in keys:
            row[k + suffix] = float(np.mean([v[k] for v in vals])) if vals else float("nan")
        row["n_scenes"] = len(vals)
        rows.append(row)
    return pd.DataFrame(rows).set_index("method")


def physical_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 2: per method the mean over scenes of the scene-level physical metrics.

    Parameters
    ----------
    files
        Method name -> per-scene physical metric JSON files.
    """
    df = mean_table(files, list(PHYS_COLUMNS))
    df["avg_rank"] = average_rank(df, PHYS_COLUMNS)
    return df


def crosssim_table(bullet: dict[str, list[str | Path]], mujoco: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 3: post-simulation drift in MuJoCo (ranked) beside the same protocol in pybullet."""
    keys = ["drift_trans", "drift_rot"]
    mj = mean_table(mujoco, keys, "_mujoco")
    pb = mean_table(bullet, keys, "_bullet").drop(columns="n_scenes")
    df = mj.join(pb)[[*CROSSSIM_COLUMNS, "drift_trans_bullet", "drift_rot_bullet", "n_scenes"]]
    df["avg_rank"] = average_rank(df, CROSSSIM_COLUMNS)
    return df


def ablation_table(physical: dict[str, list[str | Path]], alignment: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 6: reference alignment (mean per-object mask IoU) and physical metrics per method, with pose change."""
    align = mean_table(alignment, ["mask_iou", "pose_change_trans", "pose_change_rot"]).drop(columns="n_scenes")
    df = align.join(mean_table(physical, list(PHYS_COLUMNS)))
    df = df[[*ABLATION_COLUMNS, "pose_change_trans", "pose_change_rot", "n_scenes"]]
    df["avg_rank"] = average_rank(df, ABLATION_COLUMNS)
    return df


def recon_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 1: reconstruction metrics against ground truth (MIDI-3D protocol), means over scenes."""
    df = mean_table(files, [*RECON_COLUMNS, *RECON_EXTRA])
    df["avg_rank"] = average_rank(df, RECON_COLUMNS)
    return df


def runtime_table(benchmark_dir: str | Path) -> pd.DataFrame:
    """Runtime per stage (and method/backend) and suite from Snakemake's ``benchmark:`` TSV files.

    A TSV at ``<benchmark_dir>/<stage...>/<suite>/<scene>.tsv`` counts as one job of
    ``<stage...>`` on ``<suite>``. Columns: jobs, mean and total wall seconds, mean CPU seconds,
    max resident memory (MB).
    """
    rows = []
    root = Path(benchmark_dir)
    for tsv in sorted(root.rglob("*.tsv")):
        rel = tsv.relative_to(root).parts
        if len(rel) < 3:
            continue
        df = pd.read_csv(tsv, sep="\t")
        rows.append({"stage": "/".join(rel[:-2]), "suite": rel[-2], "s": float(df["s"].iloc[0]),
                     "cpu_s": float(pd.to_numeric(df["cpu_time"], errors="coerce").iloc[0]),
                     "max_rss_mb": float(pd.to_numeric(df["max_rss"], errors="coerce").iloc[0])})
    if not rows:
        return pd.DataFrame(columns=["jobs", "mean_s", "total_s", "mean_cpu_s", "max_rss_mb"])
    g = pd.DataFrame(rows).groupby(["stage", "suite"])
    return pd.DataFrame({"jobs": g["s"].count(), "mean_s": g["s"].mean(), "total_s": g["s"].sum(),
                         "mean_cpu_s": g["cpu_s"].mean(), "max_rss_mb": g["max_rss_mb"].max()})


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
    """Markdown table: floats like the paper, the best value of each ranked metric bold, the second underlined."""
    shown = df.copy().astype(object)
    ranked = {**directions, "avg_rank": "min"}
    for c in df.columns:
        if not pd.api.types.is_float_dtype(df[c]):
            continue
        order = df[c].rank(method="min", ascending=(ranked.get(c) == "min")) if c in ranked else None
        for idx in df.index:
            s = _fmt(df.at[idx, c], digits)
            if order is not None and order[idx] == 1:
                s = f"**{s}**"
            elif order is not None and order[idx] == 2:
                s = f"<u>{s}</u>"
            shown.at[idx, c] = s
    return shown.to_markdown() + "\n"


def write_table(df: pd.DataFrame, csv_path: str | Path, md_path: str | Path, title: str,
                directions: dict[str, str]) -> None:
    """Write a table as CSV (6 significant digits, deterministic) and Markdown (best bold, second underlined)."""
    write_text(csv_path, df.to_csv(float_format="%.6g"))
    write_text(md_path, f"# {title}\n\n" + to_markdown(df, directions))
