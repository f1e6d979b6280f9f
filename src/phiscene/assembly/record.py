"""Values of the assembly log (``assembly.json``): its format tag and how numbers are written into it."""

from __future__ import annotations

import numpy as np

#: Format tag of the assembly log.
LOG_FORMAT = "phiscene.assembly_log/1"


def rounded(v, digits: int = 9) -> float | None:
    """``v`` rounded for the log; ``None`` for missing or non-finite values (JSON has no NaN)."""
    return None if v is None or not np.isfinite(v) else float(round(float(v), digits))
