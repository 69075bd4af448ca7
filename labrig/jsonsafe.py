"""Strict JSON from analysis results: the one sanitizer the commands print and write through.

JSON has no NaN or infinity, so a non-finite float (an undefined metric, a parameter without an
uncertainty) becomes ``null``; tuples become lists and mapping keys strings, as ``json.dumps``
would write them.
"""

from __future__ import annotations

import math
from typing import Any


def json_safe(x: Any) -> Any:
    """``x`` with every non-finite float replaced by ``None``, tuples by lists and mapping keys
    by strings, recursively (``json.dumps(json_safe(x), allow_nan=False)`` then succeeds)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    return x
