"""Aggregation of per-scene metric files into the paper's tables (CSV + Markdown).

Every table has one row per method (or backend), metric columns averaged
over scenes, ``n_scenes``, ``n_failed`` and the paper's average rank
(``avg_rank``: each metric ranks the rows, 1 = best, ties share the better
rank; the ranks are averaged over the metric columns).

Failed scenes. A per-scene metric file may be a failure record
(:mod:`phiscene.failures`): the method, or a stage before it, could not
process that scene. Such a scene is never dropped silently: ``n_scenes``
counts every scene of the suite, ``n_failed`` the failed ones, and the metric
columns are means over the ``n_scenes - n_failed`` scenes that succeeded
(NaN when none did). A scene's metrics file holds every section the tables
read, so a table that joins two sections (cross-simulator, ablation) averages
both over the same scenes. In the Markdown, a row with
failures is marked with a dagger and a footnote says how many scenes its
means leave out, since they are then not comparable with the other rows.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from phiscene.atomic import write_text
from phiscene.failures import is_failure_record

#: Physical table columns and whether lower is better.
PHYS_COLUMNS = {"pen_depth": "min", "float_dist": "min", "drift_trans": "min", "drift_rot": "min"}
#: Topology table columns and whether lower is better.
TOPO_COLUMNS = {"precision": "max", "recall": "max", "f1": "max"}
#: Reconstruction table (paper Tab. 1): ranked columns; the ICP-only and raw-IoU variants are shown unranked.
RECON_COLUMNS = {"scene_cd": "min", "scene_fscore": "max", "object_cd": "min", "object_fscore": "max",
                 "bbox_iou": "max"}
RECON_EXTRA = ["scene_cd_icp", "scene_fscore_icp", "bbox_iou_raw"]
#: Faithfulness columns (unranked) of the physical and ablation tables: displacement and rotation change from the
#: input (mean over scenes of the per-scene mean and max over objects), pose error against ground truth.
POSE_COLUMNS = ["displacement_mean", "displacement_max", "rotation_mean", "rotation_max", "gt_translation_mean",
                "gt_rotation_mean", "gt_adds_mean"]
#: Real-scene table: physical metrics in both simulators and faithfulness to the (levelled) input, ranked.
REAL_COLUMNS = {"pen_depth": "min", "float_dist": "min", "drift_trans": "min", "drift_rot": "min",
                "drift_trans_mujoco": "min", "drift_rot_mujoco": "min", "displacement_mean": "min",
                "displacement_max": "min", "rotation_mean": "min", "rotation_max": "min"}
#: Its unranked columns: attached objects, objects with a declared centre of mass, objects with a completed base,
#: settled fraction and seconds per scene (grounding methods only).
REAL_EXTRA = ["attached", "ballasted", "bases", "settled_frac", "seconds"]
#: Footnote of tables whose drift leaves attached objects out.
ATTACHED_NOTE = ("Objects attached to a wall, the ceiling or the ground (``attached``) are static: they are "
                 "colliders for the others and are left out of the drift and floating averages and of the settled "
                 "fraction. They include the objects grounding kept where the input put them (remedy ``hidden``: "
                 "mostly unseen in the photo, their guessed shape held by no start; remedy ``held``: no start "
                 "held them and the fallback carried them across the scene; counted in the settled fraction, as not "
                 "settled). The displacement "
                 "and rotation averages count every object of the input (an attached object with the motion the "
                 "method gives it: none for phi_scene), so that every method is averaged over the same objects. "
                 "Objects with a declared centre of mass (``ballasted``: grounding's remedy ``ballast``, for an "
                 "object at rest in the input that topples as a uniform solid) are simulated with it in both "
                 "simulators, and objects with a completed base (``bases``: remedy ``base``, for one whose round "
                 "bottom, a guess of its hidden side, cannot stand where the input has it at rest) with that "
                 "flat piece under them. Walls estimated from the objects hanging on them (``structure`` planes "
                 "marked ``estimated``, phiscene.walls) are static colliders in every simulation of a scene in the "
                 "input's frame; a method in its own frame (``rest3d``) is simulated without them.")
#: Ablation table (paper Tab. 6): reference alignment (mask IoU in place of CLIP-I) + the physical metrics.
ABLATION_COLUMNS = {"mask_iou": "max", **PHYS_COLUMNS}


def _read(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())


def _values(path: str | Path, section: str) -> dict:
    """One section of a per-scene metrics file (:func:`phiscene.metrics.evaluate.read_section`)."""
    from phiscene.metrics.evaluate import read_section

    return read_section(_read(path), section, path)


def average_rank(df: pd.DataFrame, directions: dict[str, str]) -> pd.Series:
    """The paper's average rank over ``directions``' columns (1 = best; ties share the better rank)."""
    ranks = [df[c].rank(method="min", ascending=(d == "min")) for c, d in directions.items()]
    return pd.concat(ranks, axis=1).mean(axis=1)


def failed_scenes(files: dict[str, list[str | Path]]) -> dict[str, set[int]]:
    """Per row name, the positions of its per-scene files that are failure records."""
    return {name: {i for i, p in enumerate(paths) if is_failure_record(_read(p))} for name, paths in files.items()}


def mean_table(files: dict[str, list[str | Path]], keys: list[str], section: str, suffix: str = "",
               failed: dict[str, set[int]] | None = None) -> pd.DataFrame:
    """Per row name, the mean over its successful scenes of each key of a metrics section.

    Parameters
    ----------
    files
        Row name -> per-scene metrics files (:mod:`phiscene.metrics.evaluate`; failure records allowed).
    keys
        Metric keys to average (columns ``key + suffix``).
    section
        The metrics file section holding ``keys``.
    failed
        Row name -> positions of scenes to count as failed (defaults to :func:`failed_scenes` of ``files``).

    Returns
    -------
    One row per name: the means, ``n_scenes`` (all scenes) and ``n_failed``.
    """
    failed = failed_scenes(files) if failed is None else failed
    rows = []
    for name, paths in files.items():
        bad = failed.get(name, set())
        vals = [_values(p, section) for i, p in enumerate(paths) if i not in bad]
        row = {"method": name}
        for k in keys:
            row[k + suffix] = float(np.mean([v[k] for v in vals])) if vals else float("nan")
        row["n_scenes"] = len(paths)
        row["n_failed"] = len(bad)
        rows.append(row)
    return pd.DataFrame(rows).set_index("method")


def physical_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 2: per method the mean over scenes of the scene-level physical metrics.

    Parameters
    ----------
    files
        Method name -> per-scene metrics files (``physical`` and ``pose_gt`` sections); the faithfulness
        columns (:data:`POSE_COLUMNS`) are shown unranked.
    """
    failed = failed_scenes(files)
    df = mean_table(files, list(PHYS_COLUMNS), "physical", failed=failed)
    pose = mean_table(files, POSE_COLUMNS, "pose_gt", failed=failed).drop(columns=["n_scenes", "n_failed"])
    df = df.join(pose)[[*PHYS_COLUMNS, *POSE_COLUMNS, "n_scenes", "n_failed"]]
    df["avg_rank"] = average_rank(df, PHYS_COLUMNS)
    return df


def crosssim_table(files: dict[str, list[str | Path]],
                   simulators: list[tuple[str, str, bool]] | None = None) -> pd.DataFrame:
    """Tab. 3: post-simulation drift per simulator, ranked on the engines independent of the grounding's.

    Parameters
    ----------
    files
        Method name -> per-scene metrics files (holding each simulator's section).
    simulators
        Per engine, in column order: its metrics section, its column suffix and whether it is ranked
        (default: every registered simulator, :func:`phiscene.metrics.drift.table_simulators`).
    """
    from phiscene.metrics.drift import table_simulators

    keys = ["drift_trans", "drift_rot"]
    sims = simulators or [(s.section, s.column, s.ranked) for s in table_simulators()]
    failed = failed_scenes(files)
    parts = [mean_table(files, keys, section, f"_{column}", failed) for section, column, _ in sims]
    df = parts[0].drop(columns=["n_scenes", "n_failed"])
    for part in parts[1:]:
        df = df.join(part.drop(columns=["n_scenes", "n_failed"]))
    df = df.join(parts[0][["n_scenes", "n_failed"]])
    ranked = {f"{k}_{column}": "min" for _, column, r in sims if r for k in keys}
    df["avg_rank"] = average_rank(df, ranked)
    return df


def ablation_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 6: reference alignment (mean per-object mask IoU) and physical metrics per method, with pose change.

    Parameters
    ----------
    files
        Method name -> per-scene metrics files (``alignment`` and ``physical`` sections).
    """
    failed = failed_scenes(files)
    align = mean_table(files, ["mask_iou", "pose_change_trans", "pose_change_rot"], "alignment", failed=failed)
    df = align.drop(columns=["n_scenes", "n_failed"]).join(mean_table(files, list(PHYS_COLUMNS), "physical",
                                                                      failed=failed))
    pose = mean_table(files, POSE_COLUMNS, "pose_gt", failed=failed).drop(columns=["n_scenes", "n_failed"])
    df = df.join(pose)[[*ABLATION_COLUMNS, "pose_change_trans", "pose_change_rot", *POSE_COLUMNS, "n_scenes",
                        "n_failed"]]
    df["avg_rank"] = average_rank(df, ABLATION_COLUMNS)
    return df


def _assembly_summary(path: str | Path | None) -> dict:
    """Settled fraction and seconds of one grounding from its assembly log (NaN without one)."""
    nan = float("nan")
    if path is None:
        return {"settled_frac": nan, "seconds": nan}
    data = _read(path)
    if is_failure_record(data) or "summary" not in data:
        return {"settled_frac": nan, "seconds": nan}
    s = data["summary"]
    # static by grounding: attached, or kept where it was put (remedy hidden); attached in the grounded scene. One
    # kept because the fallback carried it across the scene (remedy held) is a failure to settle: counted, unsettled
    free = [r for r in data.get("objects", {}).values() if r.get("settle_remedy") not in ("attached", "hidden")]
    settled = sum(r.get("settled") is True for r in free)
    return {"settled_frac": settled / len(free) if free else nan, "seconds": float(s.get("seconds", nan))}


def real_scene_rows(files: dict[str, list[str | Path]], scenes: list[str],
                    logs: dict[str, list[str | Path]] | None = None) -> pd.DataFrame:
    """Per (method, scene): the real-scene table's columns (failed scenes as NaN with ``failed`` = 1).

    Parameters
    ----------
    files
        Method -> per-scene metrics files (``physical``, ``mujoco`` and ``pose`` sections), in ``scenes`` order.
    scenes
        Scene ids.
    logs
        Method -> per-scene assembly logs (``settled_frac``, ``seconds``); methods without them get NaN.
    """
    rows = []
    for method, paths in files.items():
        for i, (scene, path) in enumerate(zip(scenes, paths)):
            data = _read(path)
            row = {"method": method, "scene": scene, "failed": int(is_failure_record(data))}
            if not row["failed"]:
                phys, mj, pose = (_values(path, s) for s in ("physical", "mujoco", "pose"))
                row.update({k: phys[k] for k in ("pen_depth", "float_dist", "drift_trans", "drift_rot")})
                row.update(drift_trans_mujoco=mj["drift_trans"], drift_rot_mujoco=mj["drift_rot"])
                row.update({k: pose[k] for k in ("displacement_mean", "displacement_max", "rotation_mean",
                                                  "rotation_max", "attached")})
                row["ballasted"] = pose.get("ballasted", 0)  # metrics files older than the column: none
                row["bases"] = pose.get("bases", 0)
            log_path = (logs or {}).get(method, [None] * len(paths))[i]
            row.update(_assembly_summary(log_path))
            rows.append(row)
    return pd.DataFrame(rows).set_index(["method", "scene"])


def real_table(files: dict[str, list[str | Path]], scenes: list[str],
               logs: dict[str, list[str | Path]] | None = None) -> pd.DataFrame:
    """Real scenes: per method the mean over its successful scenes of :func:`real_scene_rows`' columns."""
    per = real_scene_rows(files, scenes, logs)
    ok = per[per["failed"] == 0]
    cols = [*REAL_COLUMNS, *REAL_EXTRA]
    df = ok.groupby(level="method", sort=False)[cols].mean().reindex(list(files))
    df["n_scenes"] = per.groupby(level="method", sort=False).size().reindex(list(files))
    df["n_failed"] = per.groupby(level="method", sort=False)["failed"].sum().reindex(list(files))
    df["avg_rank"] = average_rank(df, REAL_COLUMNS)
    return df


def recon_table(files: dict[str, list[str | Path]]) -> pd.DataFrame:
    """Tab. 1: reconstruction metrics against ground truth (MIDI-3D protocol), means over scenes."""
    df = mean_table(files, [*RECON_COLUMNS, *RECON_EXTRA], "recon")
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


def topology_table(files: dict[str, list[str | Path]], gt_files: list[str | Path]) -> pd.DataFrame:
    """Tab. 7: per backend the micro-averaged edge precision, recall and F1 (plus the macro F1 over scenes), and
    ``relation_acc``: the share of the edges found (``tp``, pooled) that carry the ground truth's relation
    (:func:`phiscene.metrics.topology.relation_counts`; unranked, not in the paper).

    Parameters
    ----------
    files
        Backend -> predicted support graphs (topology JSON), one per scene, in the order of ``gt_files``.
    gt_files
        The scenes' ground-truth support graphs.

    A predicted graph that is a failure record (the backend failed on the scene) is counted in
    ``n_failed`` and left out of the sums (see the module notes).
    """
    from phiscene.failures import FailedInput
    from phiscene.metrics.topology import edge_scores, load_pair, relation_counts, scores_from_counts

    rows = []
    for backend, paths in files.items():
        if len(paths) != len(gt_files):
            raise ValueError(f"topology table: {backend} has {len(paths)} graphs for {len(gt_files)} scenes")
        scores, relations = [], []
        for pred, gt in zip(paths, gt_files):
            try:
                graphs = load_pair(pred, gt)
            except FailedInput:
                continue
            scores.append(edge_scores(*graphs))
            relations.append(relation_counts(*graphs))
        micro = scores_from_counts(sum(v.tp for v in scores), sum(v.fp for v in scores), sum(v.fn for v in scores))
        same, matched = sum(r[0] for r in relations), sum(r[1] for r in relations)
        rows.append({"backend": backend, "precision": micro.precision, "recall": micro.recall, "f1": micro.f1,
                     "f1_macro": float(np.mean([v.f1 for v in scores])) if scores else float("nan"),
                     "relation_acc": same / matched if matched else float("nan"),
                     "tp": micro.tp, "fp": micro.fp, "fn": micro.fn, "n_scenes": len(paths),
                     "n_failed": len(paths) - len(scores)})
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


def marked_cells(df: pd.DataFrame, directions: dict[str, str], digits: int = 4) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Cell texts of a table and the best / second mark of each cell.

    Float columns are formatted like the paper (:func:`_fmt`); other columns are shown as they are.
    Each column of ``directions`` and ``avg_rank`` (lower is better) ranks the rows (ties share the better rank).

    Returns
    -------
    texts : DataFrame of str, same index and columns as ``df``
    marks : DataFrame of int, same shape: 1 = best, 2 = second, 0 = neither or an unranked column
    """
    texts = df.copy().astype(object)
    marks = pd.DataFrame(0, index=df.index, columns=df.columns)
    ranked = {**directions, "avg_rank": "min"}
    for c in df.columns:
        if not pd.api.types.is_float_dtype(df[c]):
            texts[c] = [str(v) for v in df[c]]
            continue
        order = df[c].rank(method="min", ascending=(ranked.get(c) == "min")) if c in ranked else None
        for idx in df.index:
            texts.at[idx, c] = _fmt(df.at[idx, c], digits)
            if order is not None and order[idx] in (1, 2):
                marks.at[idx, c] = int(order[idx])
    return texts, marks


def to_markdown(df: pd.DataFrame, directions: dict[str, str], digits: int = 4) -> str:
    """Markdown table: floats like the paper, the best value of each ranked metric bold, the second underlined."""
    texts, marks = marked_cells(df, directions, digits)
    shown = texts.where(marks != 1, "**" + texts + "**").where(marks != 2, "<u>" + texts + "</u>")
    shown = _flag_failures(shown, df)
    if isinstance(shown.index, pd.MultiIndex):  # e.g. (stage, suite) of the runtime table: one readable column
        shown.index = pd.Index([_label(i) for i in shown.index], name=_label(shown.index.names))
    return shown.to_markdown() + "\n" + failure_note(df)


def _label(key) -> str:
    """A row label (or index name) as text; the parts of a multi-level one joined by ' / '."""
    return " / ".join(map(str, key)) if isinstance(key, (tuple, list)) else str(key)


def _flag_failures(shown: pd.DataFrame, df: pd.DataFrame) -> pd.DataFrame:
    """``shown`` with a dagger after the name of every row of ``df`` that has failed scenes."""
    if "n_failed" not in df.columns:
        return shown
    out = shown.copy()
    out.index = pd.Index([f"{i} †" if n > 0 else i for i, n in zip(df.index, df["n_failed"])], name=df.index.name)
    return out


def failure_note(df: pd.DataFrame) -> str:
    """Footnote for the rows of ``df`` with ``n_failed > 0`` ('' when there are none)."""
    if "n_failed" not in df.columns or not (df["n_failed"] > 0).any():
        return ""
    bad = df.index[df["n_failed"] > 0]
    parts = "; ".join(f"{i}: {int(df.at[i, 'n_failed'])} of {int(df.at[i, 'n_scenes'])}" for i in bad)
    return (f"\n† Failed scenes ({parts}): these rows average only the scenes that succeeded, so they are "
            "not directly comparable with the other rows.\n")


def to_html(df: pd.DataFrame, directions: dict[str, str], digits: int = 4) -> str:
    """HTML ``<table>`` of :func:`to_markdown`'s content: best value bold (``<b>``), second underlined (``<u>``).

    Ranked columns carry ``class="ranked"`` on their header cell; names and values are HTML-escaped.
    """
    import html

    texts, marks = marked_cells(df, directions, digits)
    ranked = {**directions, "avg_rank": "min"}
    head = "".join(f'<th{" class=ranked" if c in ranked else ""}>{html.escape(str(c))}'
                   f'{" ↓" if ranked.get(c) == "min" else " ↑" if c in ranked else ""}</th>' for c in df.columns)
    rows = []
    for idx in df.index:
        cells = []
        for c in df.columns:
            t = html.escape(texts.at[idx, c])
            m = marks.at[idx, c]
            cells.append(f"<td>{'<b>' + t + '</b>' if m == 1 else '<u>' + t + '</u>' if m == 2 else t}</td>")
        rows.append(f"<tr><th>{html.escape(_label(idx))}</th>{''.join(cells)}</tr>")
    names = df.index.names if isinstance(df.index, pd.MultiIndex) else df.index.name
    name = html.escape(_label(names) if names is not None else "")
    return (f"<table>\n<thead><tr><th>{name}</th>{head}</tr></thead>\n<tbody>\n" + "\n".join(rows)
            + "\n</tbody>\n</table>\n")


def write_table(df: pd.DataFrame, csv_path: str | Path, md_path: str | Path, title: str,
                directions: dict[str, str]) -> None:
    """Write a table as CSV (6 significant digits, deterministic) and Markdown (best bold, second underlined)."""
    write_text(csv_path, df.to_csv(float_format="%.6g"))
    write_text(md_path, f"# {title}\n\n" + to_markdown(df, directions))
