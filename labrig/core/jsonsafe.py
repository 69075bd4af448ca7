"""Strict JSON out, bounded JSON in: the one sanitizer the commands print and write through, and
the one parser of JSON text that comes from files.

JSON has no NaN or infinity, so a non-finite float (an undefined metric, a parameter without an
uncertainty) becomes ``null``; tuples become lists and mapping keys strings, as ``json.dumps``
would write them. Reading, :func:`loads_bounded` refuses text longer or nested deeper than its
limits before parsing it (the standard parser recurses: 100 000 nested ``[`` raise
``RecursionError``), numbers with thousands of digits (naming where the number is:
:class:`JSONLimitError`), and a key given twice in one object (the standard parser silently
keeps the last one).
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


class JSONLimitError(ValueError):
    """A bound of :func:`loads_bounded` broken at one place of the document: ``what`` broke it,
    ``where`` is the place as a path of keys and indices (``params.vc_V``, ``effects[0]``; ``""``
    for the document itself) and ``limit`` the bound, in words."""

    def __init__(self, what: str, where: str, limit: str):
        self.what, self.where, self.limit = what, where, limit
        super().__init__(f"{what} at {where or 'the top level'} ({limit})")


class _LongInteger:
    """Stands for an integer of more than :data:`MAX_INT_DIGITS` digits while the text is
    parsed (never converted: Python refuses more than 4300 digits, and slowly)."""

    __slots__ = ("digits",)

    def __init__(self, digits: int):
        self.digits = digits


def _place_of(doc: Any, target: object, where: str = "") -> str | None:
    """The path of ``target`` (by identity) in ``doc``, in document order, or ``None``."""
    if doc is target:
        return where
    items: Any = ()
    if isinstance(doc, dict):
        items = ((f"{where}.{k}" if where else str(k), v) for k, v in doc.items())
    elif isinstance(doc, list):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(doc))
    for place, value in items:
        found = _place_of(value, target, place)
        if found is not None:
            return found
    return None


def loads_bounded(
    text: str, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH
) -> Any:
    """``json.loads(text)`` within limits: raises :class:`ValueError` saying which limit
    (length, nesting, digits of an integer, a key given twice) or what is wrong with the JSON
    (:class:`json.JSONDecodeError`, a subclass, with its line and column); an integer of too
    many digits as a :class:`JSONLimitError` (a subclass too) naming where it is (the first in
    the document)."""
    if len(text) > max_bytes:
        raise ValueError(f"longer than {max_bytes} characters")
    depth = json_depth(text)
    if depth > max_depth:
        raise ValueError(f"nested {depth} deep; at most {max_depth} levels are read")
    long: list[_LongInteger] = []

    def parse_int(digits: str) -> Any:
        n = len(digits.lstrip("-"))
        if n > MAX_INT_DIGITS:
            long.append(_LongInteger(n))
            return long[-1]
        return int(digits)

    doc = json.loads(text, parse_int=parse_int, object_pairs_hook=_unique_keys)
    if long:
        first = long[0]
        where = _place_of(doc, first) or ""
        raise JSONLimitError(
            f"an integer with {first.digits} digits", where, f"at most {MAX_INT_DIGITS} are read"
        )
    return doc


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"the key {key!r} is given twice in one object")
        out[key] = value
    return out
