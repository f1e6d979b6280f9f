"""The embedded benchmark (docs/DESIGN.md §4): scenes built from shipped meshes, physical by construction.

Modules: ``assets`` (the asset library), ``cleanmesh`` (making meshes usable rigid
bodies), ``templates`` (scene templates per suite), ``groundtruth`` (settling,
verification, support graph), ``degrade`` (the initial scene), ``render``
(reference image, segmentation, camera) and ``build`` (:func:`build_scene`, the
workflow's entry point).
"""
