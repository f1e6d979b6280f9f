"""Base class of backend parameter dataclasses (``from_dict`` that rejects unknown keys).

``BackendParams`` is :class:`phiscene.params.Params` under the name the topology backends
(``topology.<backend>`` in ``config.yaml``) import; unknown keys raise
``ValueError("unknown <ClassName> keys [...]; known: [...]")``.
"""

from __future__ import annotations

from phiscene.params import Params

BackendParams = Params

__all__ = ["BackendParams"]
