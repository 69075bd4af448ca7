"""Which fitted parameters the data determine, from the fit's covariance (``labrig fit`` and
``labrig report`` flag the others).

A free parameter ``p`` with estimate ``x_p``, standard uncertainty ``s_p`` and correlations
``r_pq`` with the other free parameters is **unidentifiable** when

- its relative standard uncertainty ``s_p / |x_p|`` is over :data:`REL_SD_LIMIT` (100 %: the
  data cannot tell its value from zero), or
- ``|r_pq|`` is over :data:`CORRELATION_LIMIT` (0.99) for another free parameter ``q``: the
  data determine a combination of the two, not each one.

Both limits are strict: exactly 100 % or exactly 0.99 passes. A parameter held fixed (its
uncertainty ``None``, not among the fit's free parameters) is not judged. Two more cases are
unidentifiable whatever the numbers say, when the fit names them: a free parameter the data do
not determine at all (its uncertainty ``None``: the residual does not depend on it, or only
through a combination the Jacobian cannot resolve, :mod:`labrig.analysis.fit_uncertainty`),
and one that ended on a bound of the fit (its 1-sigma is a local estimate that ignores the
bound: not meaningful).

The operator's ``gamma`` and ``Vc`` are strongly correlated on loops much narrower than
``Vc``; what the data do determine is the loop's opening at mid-stroke ``W`` (ue) and its
curvature ``q = span / Vc`` (:class:`~labrig.analysis.engine.LoopScale`, the coordinates the
fit itself uses). :func:`loop_coordinates` gives them with their uncertainties, propagated
from the covariance of ``(gamma, Vc)`` by the Jacobian of the map:
``cov(W, q) = G cov(gamma, Vc) G^T``, ``G = d(W, q) / d(gamma, Vc)``.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from labrig.analysis.engine import LOOP_CURVATURE, LOOP_WIDTH, LoopScale

__all__ = [
    "AT_BOUND",
    "CORRELATION_LIMIT",
    "NOT_DETERMINED",
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
    f"|correlation| over {CORRELATION_LIMIT:g} with another free parameter; also a free "
    "parameter not determined by the data at all, and one that ended at a bound of the fit"
)
#: the reason given for a free parameter without an uncertainty
NOT_DETERMINED = "not determined by these data"
#: the reason given for a parameter that ended on a bound
AT_BOUND = "ended at a bound of the fit: its uncertainty is not meaningful"


def unidentifiable(
    params: Mapping[str, Any],
    uncertainty: Mapping[str, float | None],
    correlation: Mapping[str, Mapping[str, float]],
    *,
    free: Collection[str] = (),
    at_bound: Collection[str] = (),
) -> dict[str, str]:
    """The unidentifiable parameters (module docstring) and why, in words.

    Parameters
    ----------
    params : mapping
        Parameter to its estimate (native units).
    uncertainty : mapping
        Parameter to its 1-sigma (same unit), ``None`` for one held fixed or not determined.
    correlation : mapping
        Parameter to parameter to the correlation of their estimates (a parameter that is not
        determined has no row).
    free : collection of str
        The fit's free parameters: one of them without an uncertainty is not determined by
        the data (without ``free``, a parameter without an uncertainty is taken as fixed).
    at_bound : collection of str
        The parameters that ended on a bound of the fit.

    Returns
    -------
    dict
        ``{name: "relative uncertainty 140 %"}``, ``{name: "|correlation| 0.995 with vc_V"}``,
        :data:`NOT_DETERMINED`, :data:`AT_BOUND`, or several joined by ``; ``.
    """
    out: dict[str, str] = {}
    for name, sd in uncertainty.items():
        why = [AT_BOUND] if name in at_bound else []
        if sd is None:
            why += [NOT_DETERMINED] if name in free else []
        else:
            why += _spread(params.get(name), sd) + _correlated(correlation.get(name) or {}, name)
        if why:
            out[name] = "; ".join(why)
    return out


def _spread(x: Any, sd: float) -> list[str]:
    """Why a 1-sigma ``sd`` of the estimate ``x`` is too large (module docstring), if it is."""
    if not math.isfinite(sd):
        return ["uncertainty not finite"]
    if not isinstance(x, int | float):
        return []
    rel = math.inf if x == 0 else sd / abs(float(x))
    return [f"relative uncertainty {100 * rel:.3g} %"] if rel > REL_SD_LIMIT else []


def _correlated(row: Mapping[str, float | None], name: str) -> list[str]:
    """Why the correlations ``row`` of parameter ``name`` make it unidentifiable, if they do."""
    worst = max(
        (
            (abs(r), q)
            for q, r in row.items()
            if q != name and isinstance(r, int | float) and math.isfinite(r)
        ),
        default=None,
    )
    if worst is None or worst[0] <= CORRELATION_LIMIT:
        return []
    return [f"|correlation| {worst[0]:.4g} with {worst[1]}"]


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
    r = float((correlation.get("gamma_ue_per_V") or {}).get("vc_V") or 0.0)
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
    *,
    free: Collection[str] = (),
    at_bound: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """The JSON of ``labrig fit``'s ``identifiability`` (with or without ``--effect``).

    Parameters
    ----------
    params, uncertainty, correlation : mapping
        As for :func:`unidentifiable` (an effect's parameters named ``"effect.param"``).
    span_V : float or None
        The stroke (V) of the operator's loop coordinates (:func:`loop_coordinates`).
    free : collection of str
        The fit's free parameters.
    at_bound : mapping, optional
        The parameters that ended on a bound of the fit, with their values.

    Returns
    -------
    dict
        ``rule``; the ``unidentifiable`` parameters with their reasons; ``at_bound``
        (parameter to the bound it ended on); the operator's ``loop`` coordinates.
    """
    bound = dict(at_bound or {})
    return {
        "rule": RULE,
        "unidentifiable": unidentifiable(
            params, uncertainty, correlation, free=free, at_bound=bound
        ),
        "at_bound": bound,
        "loop": loop_coordinates(params, uncertainty, correlation, span_V),
    }
