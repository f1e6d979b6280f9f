"""Importers of real inputs into phiscene's ``scene.json`` layout (docs/DESIGN.md §4, "Real data plugs in").

``sam3d``
    SAM 3D Objects outputs (per-object mesh or GLB + pose in the PyTorch3D camera frame) -> a
    gravity-aligned, z-up, metric scene with its reference image and segmentation.
``front3d``
    3D-FRONT rooms in MIDI-3D's test layout (render, semantic id map, GT surfaces or meshes) -> the
    benchmark layout ``gt/``, ``initial/``, ``reference/`` of one scene.

``placed``
    Per-object meshes already placed in one frame (GLB/PLY/OBJ; ``rest3d`` is one layout of them) -> a levelled
    scene; ``placed_suite``: a folder of such scenes as a workflow suite.

:func:`run_source_scene` imports one scene of a workflow suite whose ``source`` is a folder of scenes (``sam3d``,
``placed``).

Predictions of other methods are imported by :mod:`phiscene.baselines.external`.
"""

import math
from importlib import import_module
from pathlib import Path

import numpy as np

from phiscene.errors import InputError

#: Up-axis conventions a placed-mesh source may declare (:attr:`phiscene.io.placed.PlacedParams.up`): glTF's ``y``,
#: ``z``, and the others signed (``-y``: OpenCV's camera frame, y down).
UP_AXES = ("y", "z", "x", "-x", "-y", "-z")
#: How a placed-mesh folder's files are read (:func:`phiscene.io.placed.read_placed_dir`): one object per file, or
#: each glTF/GLB file's top-level nodes.
OBJECT_MODES = ("files", "nodes")

#: Source kind -> ``module:function(source, scene, out_dir)`` importing one of its scenes (:func:`run_source_scene`).
SCENE_IMPORTERS = {
    "sam3d": "phiscene.io.sam3d:run_sam3d_scene",
    "placed": "phiscene.io.placed_suite:run_placed_scene",
}


def run_source_scene(source: dict, scene: str, out_dir: str | Path):
    """Workflow stage: scene ``scene`` of a folder-of-scenes ``source`` (``source["kind"]`` in
    :data:`SCENE_IMPORTERS`) as ``OUT_DIR/initial/scene.json`` (+ ``reference/``, ``import.json``); returns the
    :class:`~phiscene.scene.Scene` written."""
    module, _, name = SCENE_IMPORTERS[source["kind"]].partition(":")
    return getattr(import_module(module), name)(source, scene, out_dir)


def finite_numbers(data: dict, path: str | Path, key: str, size: int) -> np.ndarray:
    """Field ``key`` of a JSON object ``data`` read from ``path`` as ``size`` finite numbers, shape (size,).

    Raises
    ------
    InputError
        Naming ``path`` and ``key``: the key missing, a value that is not numeric, or not ``size`` finite numbers.
    """
    if key not in data:
        raise InputError(path, key, "missing")
    try:
        v = np.asarray(data[key], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(path, key, f"not numeric: {data[key]!r}") from None
    if v.shape != (size,) or not np.all(np.isfinite(v)):
        raise InputError(path, key, f"expected {size} finite numbers, got {data[key]!r}")
    return v


def check_unit_scale(value: float) -> None:
    """Reject a unit scale (metres per source unit) that is not a finite number > 0 (``ValueError``)."""
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"unit_scale must be a finite number > 0, got {value}")
