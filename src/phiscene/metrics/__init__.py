"""Evaluation metrics: physical plausibility (:mod:`phiscene.metrics.physical`) and, alongside it,
reconstruction, reference alignment and support-graph metrics.

Submodules are imported on use, so importing this package stays cheap.
"""
