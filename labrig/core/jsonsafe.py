"""Strict JSON out, bounded JSON in: the one sanitizer the commands print and write through, and
the one parser of JSON text that comes from files.

JSON has no NaN or infinity, so a non-finite float (an undefined metric, a parameter without an
uncertainty) becomes ``null``; tuples become lists and mapping keys strings, as ``json.dumps``
would write them. Reading, :func:`loads_bounded` refuses text longer or nested deeper than its
limits before parsing it (the standard parser recurses: 100 000 nested ``[`` raise
``RecursionError``), numbers with thousands of digits, and a key given twice in one object
(the standard parser silently keeps the last one).
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

#: the most bytes of JSON text :func:`loads_bounded` parses by default
MAX_JSON_BYTES = 20_000_000
#: the deepest nesting of arrays and objects :func:`loads_bounded` accepts by default
MAX_JSON_DEPTH = 64
#: the most digits a JSON integer may have (Python refuses more than 4300)
MAX_INT_DIGITS = 100

_BRACKET_OR_STRING = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', re.DOTALL)


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


def json_depth(text: str) -> int:
    """The deepest nesting of ``[``/``{`` in JSON ``text`` (brackets inside strings do not
    count), found in one pass without parsing."""
    depth = deepest = 0
    for m in _BRACKET_OR_STRING.finditer(text):
        c = m.group()
        if c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _parse_int(digits: str) -> int:
    if len(digits.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"an integer with {len(digits.lstrip('-'))} digits")
    return int(digits)


def loads_bounded(
    text: str, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH
) -> Any:
    """``json.loads(text)`` within limits: raises :class:`ValueError` saying which limit
    (length, nesting, digits of an integer, a key given twice) or what is wrong with the JSON
    (:class:`json.JSONDecodeError`, a subclass, with its line and column)."""
    if len(text) > max_bytes:
        raise ValueError(f"longer than {max_bytes} characters")
    depth = json_depth(text)
    if depth > max_depth:
        raise ValueError(f"nested {depth} deep; at most {max_depth} levels are read")
    return json.loads(text, parse_int=_parse_int, object_pairs_hook=_unique_keys)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"the key {key!r} is given twice in one object")
        out[key] = value
    return out
