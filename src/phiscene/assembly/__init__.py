"""The phi-Scene method: topology-ordered SDF penetration resolution and rigid settling.

- :mod:`~phiscene.assembly.penetration`: translation-only SDF clearance solve (paper §3.1.2).
- :mod:`~phiscene.assembly.settle`: rigid settling with the sliding-window criterion (paper §3.1.3).
- :mod:`~phiscene.assembly.assemble`: the sequential loop over the placement order.
"""

from phiscene.assembly.assemble import AssemblyParams, full_order, ground_scene
from phiscene.assembly.penetration import PenetrationParams, SdfBody, resolve_penetration, sdf_body
from phiscene.assembly.settle import SettleParams, SettleResult, settle_object

__all__ = ["AssemblyParams", "PenetrationParams", "SdfBody", "SettleParams", "SettleResult", "full_order",
           "ground_scene", "resolve_penetration", "sdf_body", "settle_object"]
