"""Importers of real inputs into phiscene's ``scene.json`` layout (docs/DESIGN.md §4, "Real data plugs in").

``sam3d``
    SAM 3D Objects outputs (per-object mesh or GLB + pose in the PyTorch3D camera frame) -> a
    gravity-aligned, z-up, metric scene with its reference image and segmentation.
``front3d``
    3D-FRONT rooms in MIDI-3D's test layout (render, semantic id map, GT surfaces or meshes) -> the
    benchmark layout ``gt/``, ``initial/``, ``reference/`` of one scene.

``placed``
    Per-object meshes already placed in one frame (GLB/PLY/OBJ; ``rest3d`` is one layout of them) -> a levelled
    scene.

Predictions of other methods are imported by :mod:`phiscene.baselines.external`.
"""

import math


def check_unit_scale(value: float) -> None:
    """Reject a unit scale (metres per source unit) that is not a finite number > 0 (``ValueError``)."""
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"unit_scale must be a finite number > 0, got {value}")
