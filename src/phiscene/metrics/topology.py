"""Support-graph accuracy: precision, recall and F1 of predicted edges against ground truth.

An edge is the pair ``(from, to)``; the ground node counts like any other,
and ``relation``, ``confidence`` and ``reason`` are ignored. Edges dropped to
break cycles are not predictions (only a graph's kept ``edges`` are scored).

Edge cases (so that every score is defined):

* ``precision = tp / (tp + fp)``; with no predicted edges it is 1 if the GT
  has no edges either, else 0;
* ``recall = tp / (tp + fn)``; with no GT edges it is 1 if nothing was
  predicted, else 0;
* ``f1 = 2 tp / (2 tp + fp + fn)``, 1 when both sets are empty. This equals
  the harmonic mean of the two above in every case (0 when either is 0).

Over several scenes, :func:`micro_scores` pools the counts (every edge
weighs the same) and :func:`macro_scores` averages the per-scene scores.

The relation is scored apart (:func:`relation_counts`): of the edges both
graphs have, how many carry the ground truth's relation (``supports``,
``contains``, ``leans_on``, ``attached``). Grounding acts on it (a leaning
object is not flushed onto its supporter), which the pair scores cannot see.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class EdgeScores:
    """Edge counts and the scores derived from them.

    Attributes
    ----------
    tp, fp, fn
        True positive, false positive and false negative edge counts (summed over scenes
        for micro scores).
    precision, recall, f1
        In [0, 1] (see the module docstring for empty sets).
    """

    tp: int
    fp: int
    fn: int
    precision: float
    recall: float
    f1: float

    def to_dict(self) -> dict:
        return asdict(self)


def edge_pairs(edges) -> set[tuple[str, str]]:
    """Normalise a graph, edge objects or pairs into a set of ``(from, to)`` pairs.

    Parameters
    ----------
    edges
        A :class:`~phiscene.topology.graph.SupportGraph` (its kept edges), an iterable of
        :class:`~phiscene.topology.graph.SupportEdge`, of edge dicts with ``from``/``to``,
        or of 2-tuples.
    """
    if hasattr(edges, "pairs"):
        return set(edges.pairs())
    out = set()
    for e in edges:
        if hasattr(e, "pair"):
            out.add(e.pair)
        elif isinstance(e, dict):
            out.add((e["from"], e["to"]))
        else:
            u, v = e
            out.add((u, v))
    return out


def scores_from_counts(tp: int, fp: int, fn: int) -> EdgeScores:
    """Precision, recall and F1 from counts, with the documented values for empty sets."""
    precision = tp / (tp + fp) if tp + fp else (1.0 if fn == 0 else 0.0)
    recall = tp / (tp + fn) if tp + fn else (1.0 if fp == 0 else 0.0)
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
    return EdgeScores(tp, fp, fn, float(precision), float(recall), float(f1))


def edge_counts(pred, gt) -> tuple[int, int, int]:
    """``(tp, fp, fn)`` of predicted against GT edges (anything :func:`edge_pairs` accepts)."""
    p, g = edge_pairs(pred), edge_pairs(gt)
    return len(p & g), len(p - g), len(g - p)


def edge_scores(pred, gt) -> EdgeScores:
    """Scores of one scene's predicted edges against its GT edges."""
    return scores_from_counts(*edge_counts(pred, gt))


def micro_scores(preds: Sequence, gts: Sequence) -> EdgeScores:
    """Scores with counts pooled over scenes (``preds[i]`` and ``gts[i]`` belong to scene i)."""
    if len(preds) != len(gts):
        raise ValueError(f"{len(preds)} predicted graphs but {len(gts)} ground-truth graphs")
    tp = fp = fn = 0
    for p, g in zip(preds, gts):
        a, b, c = edge_counts(p, g)
        tp, fp, fn = tp + a, fp + b, fn + c
    return scores_from_counts(tp, fp, fn)


def macro_scores(preds: Sequence, gts: Sequence) -> dict[str, float]:
    """Per-scene precision, recall and F1 averaged over scenes (``nan`` for no scenes)."""
    if len(preds) != len(gts):
        raise ValueError(f"{len(preds)} predicted graphs but {len(gts)} ground-truth graphs")
    per = [edge_scores(p, g) for p, g in zip(preds, gts)]
    n = len(per)
    mean = (lambda xs: float(sum(xs) / n)) if n else (lambda xs: float("nan"))
    return {"precision": mean([s.precision for s in per]), "recall": mean([s.recall for s in per]),
            "f1": mean([s.f1 for s in per])}


def relations(graph) -> dict[tuple[str, str], str]:
    """``(from, to) -> relation`` of a :class:`~phiscene.topology.graph.SupportGraph`'s kept edges (or of an
    iterable of :class:`~phiscene.topology.graph.SupportEdge`)."""
    return {e.pair: e.relation for e in getattr(graph, "edges", graph)}


def relation_counts(pred, gt) -> tuple[int, int]:
    """``(same, matched)``: how many of the edges both graphs have (the same ``(from, to)``) carry GT's relation.

    ``pred`` and ``gt`` are :class:`~phiscene.topology.graph.SupportGraph` (their kept edges) or iterables of
    :class:`~phiscene.topology.graph.SupportEdge`.
    """
    truth = relations(gt)
    matched = [(e.relation, truth[e.pair]) for e in getattr(pred, "edges", pred) if e.pair in truth]
    return sum(a == b for a, b in matched), len(matched)


def load_pair(pred_path, gt_path) -> tuple:
    """``(pred, gt)``: a predicted topology JSON and a GT topology JSON as
    :class:`~phiscene.topology.graph.SupportGraph`, both validated on load (the prediction against GT's objects)."""
    from phiscene.topology.graph import load

    gt = load(gt_path)
    return load(pred_path, scene_ids=gt.object_ids), gt


def file_scores(pred_path, gt_path) -> EdgeScores:
    """Scores of one predicted topology JSON against a GT topology JSON (both validated on load)."""
    return edge_scores(*load_pair(pred_path, gt_path))


def score_pairs(pairs: Iterable[tuple]) -> EdgeScores:
    """Micro scores of ``(pred, gt)`` tuples, one per scene."""
    pairs = list(pairs)
    return micro_scores([p for p, _ in pairs], [g for _, g in pairs])
