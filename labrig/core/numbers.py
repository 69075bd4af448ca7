"""Numbers in limit messages: enough digits to show that a value is beyond its limit, never
hundreds of them.

A value over a limit is printed with the fewest significant digits (at least four) that still
put it beyond the limit (100.000001 V against 100 V prints ``100.000001``); limits are printed
exactly (the shortest text that reads back as the same number); recommendations are rounded
towards the safe side; huge values switch to exponent notation (``1e+300``, not 301 digits).
"""

from __future__ import annotations

import math

__all__ = ["amps", "at_least", "at_most", "beyond", "exact", "fixed"]

#: fixed-point notation below this magnitude, exponent notation above
_FIXED_BELOW = 1e6


def exact(x: float) -> str:
    """``x`` as the shortest text that reads back as ``x`` (``100``, ``-20``, ``0.18``)."""
    s = f"{x:g}"
    return s if not math.isfinite(x) or float(s) == x else repr(float(x))


def beyond(x: float, limit: float) -> str:
    """``x`` with the fewest significant digits (4 to 17) that keep it on its side of
    ``limit`` (strictly), so a value over a limit never prints as the limit."""
    if not (math.isfinite(x) and math.isfinite(limit)) or x == limit:
        return f"{x:.4g}"
    for sig in range(4, 18):
        s = f"{x:.{sig}g}"
        if (float(s) > limit) == (x > limit) and float(s) != limit:
            return s
    return repr(float(x))


def _rounded(x: float, up: bool) -> str:
    """``x`` rounded up (``up``) or down to 3 significant digits, or more when the rounded text
    does not read back on the right side of ``x``; fixed-point for ``1e-4 <= |x| < 1e6``."""
    short = f"{x:g}"
    if not math.isfinite(x) or float(short) == x:
        return short
    mag = math.floor(math.log10(abs(x)))
    fixed_point = 1e-4 <= abs(x) < _FIXED_BELOW
    for sig in range(3, 18):
        step = 10.0 ** (mag - sig + 1)
        v = (math.ceil(x / step) if up else math.floor(x / step)) * step
        s = f"{v:.{max(0, sig - 1 - mag)}f}" if fixed_point else f"{v:.{sig}g}"
        if (float(s) >= x) if up else (float(s) <= x):
            return s
    return repr(float(x))


def at_most(x: float) -> str:
    """``x`` rounded down to few digits (an upper bound to recommend)."""
    return _rounded(x, up=False)


def at_least(x: float) -> str:
    """``x`` rounded up to few digits (a lower bound to recommend)."""
    return _rounded(x, up=True)


def fixed(x: float, decimals: int) -> str:
    """``x`` with ``decimals`` decimals; exponent notation when ``|x| >= 1e6``."""
    if math.isfinite(x) and abs(x) >= _FIXED_BELOW:
        return f"{x:.4g}"
    return f"{x:.{decimals}f}"


def fixed_down(x: float, decimals: int) -> str:
    """``x`` rounded down to ``decimals`` decimals (a highest value to recommend: rounding to
    the nearest could name one just past the limit); as :func:`fixed` otherwise."""
    if not math.isfinite(x) or abs(x) >= _FIXED_BELOW:
        return fixed(x, decimals)
    scale = 10.0**decimals
    # a limit computed a hair below a round value (199.99999999997 for 200) is that value: the
    # preflight's comparisons allow the same relative 1e-9
    return f"{math.floor(x * scale * (1 + 1e-9)) / scale:.{decimals}f}"


def _amps_text(x: float, digits: int) -> str:
    if 0.1 <= abs(x) < _FIXED_BELOW:
        return f"{x:.{digits}f}"
    return f"{x:.{digits + 1}g}"


def amps(x: float, other: float | None = None) -> str:
    """A current (A) for a message: two decimals, more when it would print as ``other`` (the
    limit it is compared with), and beyond ``other`` when it is on the other side of it."""
    for digits in (2, 3, 4, 6):
        s = _amps_text(x, digits)
        if other is None or s != _amps_text(other, digits):
            return f"{s} A"
    assert other is not None  # (without ``other`` the loop returned)
    return f"{beyond(x, other)} A"
