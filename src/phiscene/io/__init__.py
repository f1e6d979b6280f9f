"""Importers of real inputs into phiscene's ``scene.json`` layout (docs/DESIGN.md §4, "Real data plugs in").

``sam3d``
    SAM 3D Objects outputs (per-object mesh or GLB + pose in the PyTorch3D camera frame) -> a
    gravity-aligned, z-up, metric scene with its reference image and segmentation.
``front3d``
    3D-FRONT rooms in MIDI-3D's test layout (render, semantic id map, GT surfaces or meshes) -> the
    benchmark layout ``gt/``, ``initial/``, ``reference/`` of one scene.

Predictions of other methods are imported by :mod:`phiscene.baselines.external`.
"""
