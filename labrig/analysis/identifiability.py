"""Which fitted parameters the data determine, from the fit's covariance (``labrig fit`` and
``labrig report`` flag the others).

A free parameter ``p`` with estimate ``x_p``, standard uncertainty ``s_p`` and correlations
``r_pq`` with the other free parameters is **unidentifiable** when

- its relative standard uncertainty ``s_p / |x_p|`` is over :data:`REL_SD_LIMIT` (100 %: the
  data cannot tell its value from zero), or
- ``|r_pq|`` is over :data:`CORRELATION_LIMIT` (0.99) for another free parameter ``q``: the
  data determine a combination of the two, not each one.

Both limits are strict: exactly 100 % or exactly 0.99 passes. A parameter held fixed (its
uncertainty ``None``) is not judged.

The operator's ``gamma`` and ``Vc`` are strongly correlated on loops much narrower than
``Vc``; what the data do determine is the loop's opening at mid-stroke ``W`` (ue) and its
curvature ``q = span / Vc`` (:class:`~labrig.analysis.engine.LoopScale`, the coordinates the
fit itself uses). :func:`loop_coordinates` gives them with their uncertainties, propagated
from the covariance of ``(gamma, Vc)`` by the Jacobian of the map:
``cov(W, q) = G cov(gamma, Vc) G^T``, ``G = d(W, q) / d(gamma, Vc)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from labrig.analysis.engine import LOOP_CURVATURE, LOOP_WIDTH, LoopScale

__all__ = [
    "CORRELATION_LIMIT",
    "REL_SD_LIMIT",
    "RULE",
    "identifiability",
    "loop_coordinates",
    "unidentifiable",
]

#: a relative standard uncertainty over this (1 = 100 %) makes a parameter unidentifiable
REL_SD_LIMIT = 1.0
#: an absolute correlation over this with another free parameter makes it unidentifiable
CORRELATION_LIMIT = 0.99
#: the rule, in words (the JSON's ``rule``)
RULE = (
    f"unidentifiable: relative standard uncertainty over {100 * REL_SD_LIMIT:g} % or "
    f"|correlation| over {CORRELATION_LIMIT:g} with another free parameter"
)


def unidentifiable(
    params: Mapping[str, Any],
    uncertainty: Mapping[str, float | None],
    correlation: Mapping[str, Mapping[str, float]],
) -> dict[str, str]:
    """The unidentifiable parameters (module docstring) and why, in words: ``{name:
    "relative uncertainty 140 %"}``, ``{name: "|correlation| 0.995 with vc_V"}`` or both,
    joined by ``; ``."""
    out: dict[str, str] = {}
    for name, sd in uncertainty.items():
        if sd is None:
            continue
        why = []
        x = params.get(name)
        if isinstance(x, int | float) and math.isfinite(sd):
            rel = math.inf if x == 0 else sd / abs(float(x))
            if rel > REL_SD_LIMIT:
                why.append(f"relative uncertainty {100 * rel:.3g} %")
        elif not math.isfinite(sd):
            why.append("uncertainty not finite")
        row = correlation.get(name, {})
        worst = max(
            ((abs(r), q) for q, r in row.items() if q != name and math.isfinite(r)),
            default=None,
        )
        if worst is not None and worst[0] > CORRELATION_LIMIT:
            r = row[worst[1]]
            why.append(f"|correlation| {abs(r):.4g} with {worst[1]}")
        if why:
            out[name] = "; ".join(why)
    return out


def loop_coordinates(
    params: Mapping[str, Any],
    uncertainty: Mapping[str, float | None],
    correlation: Mapping[str, Mapping[str, float]],
    span_V: float | None,
) -> dict[str, float | None] | None:
    """The operator's loop width ``W`` (ue, its opening at mid-stroke of a loop spanning
    ``span_V``) and curvature ``q = span_V / Vc`` with their 1-sigma (``None`` when ``gamma``
    or ``Vc`` is fixed); ``None`` without a span or for the linear shape."""
    shape = str(params.get("shape", ""))
    if not span_V or span_V <= 0 or shape == "linear":
        return None
    try:
        scale = LoopScale(float(span_V), shape)
        g, vc = float(params["gamma_ue_per_V"]), float(params["vc_V"])
        w, q = scale.to_loop(g, vc)
    except (KeyError, ValueError, TypeError):
        return None
    out: dict[str, float | None] = {
        "span_V": float(span_V),
        LOOP_WIDTH: float(w),
        f"{LOOP_WIDTH}_sd": None,
        LOOP_CURVATURE: float(q),
        f"{LOOP_CURVATURE}_sd": None,
    }
    sg, sv = uncertainty.get("gamma_ue_per_V"), uncertainty.get("vc_V")
    if sg is None or sv is None:
        return out
    r = float(correlation.get("gamma_ue_per_V", {}).get("vc_V", 0.0))
    cov = np.array([[sg * sg, r * sg * sv], [r * sg * sv, sv * sv]])
    # LoopScale.jacobian is d(gamma, vc) / d(W, ln q); its inverse, with d q = q d ln q
    G = np.linalg.inv(scale.jacobian(w, q)) * np.array([[1.0], [q]])
    c = G @ cov @ G.T
    out[f"{LOOP_WIDTH}_sd"] = float(np.sqrt(max(c[0, 0], 0.0)))
    out[f"{LOOP_CURVATURE}_sd"] = float(np.sqrt(max(c[1, 1], 0.0)))
    return out


def identifiability(
    params: Mapping[str, Any],
    uncertainty: Mapping[str, float | None],
    correlation: Mapping[str, Mapping[str, float]],
    span_V: float | None,
) -> dict[str, Any]:
    """The JSON of ``labrig fit``'s ``identifiability``: the ``rule``, the ``unidentifiable``
    parameters with their reasons, and the operator's ``loop`` coordinates
    (:func:`loop_coordinates`)."""
    return {
        "rule": RULE,
        "unidentifiable": unidentifiable(params, uncertainty, correlation),
        "loop": loop_coordinates(params, uncertainty, correlation, span_V),
    }
