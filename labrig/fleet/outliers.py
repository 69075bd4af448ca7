"""Which runs of a fleet stand out: a robust z-score per quantity and the rule that flags a run.

Robust z-score (Iglewicz and Hoaglin's modified z-score) of a value ``x`` among the fleet's
values of the same quantity::

    z = 0.6745 (x - median) / MAD,      MAD = median(|x - median|)

(0.6745 makes ``z`` the ordinary z-score for normally distributed values; when more than half
the values are equal, MAD is 0 and ``z = (x - median) / (1.2533 * mean |x - median|)``). Time
constants are compared on a log scale. The quantities (:data:`QUANTITIES`) are the fitted
parameters and the creep the fitted model describes; only runs whose task succeeded take part,
and with fewer than :data:`MIN_RUNS` of them no quantity is tested.

**A run is flagged** when any quantity has ``|z| > 3.5`` (:data:`Z_LIMIT`), or diagnose added
an effect, or diagnose's verdict is ``unexplained`` (a residual above the noise that no effect
of the library explains). What the flag points to (``named_effect``): the effects diagnose
added, else the outlying quantities with their direction (``alpha0_ue_per_V low``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

Z_LIMIT = 3.5
MIN_RUNS = 5
#: (column, scale): the quantities tested for outliers
QUANTITIES: tuple[tuple[str, str], ...] = (
    ("alpha0_ue_per_V", "linear"),
    ("gamma_ue_per_V", "linear"),
    ("vc_V", "linear"),
    ("lam_t", "linear"),
    ("tau_t_s", "log"),
    ("lam_d", "linear"),
    ("tau_d_s", "log"),
    ("creep_pct_per_decade", "linear"),
)


def robust_z(values: Sequence[float] | NDArray) -> NDArray:
    """The modified z-score of each value (module docstring); NaN stays NaN."""
    x = np.asarray(values, dtype=float)
    ok = np.isfinite(x)
    z = np.full(x.shape, np.nan)
    if not ok.any():
        return z
    med = float(np.median(x[ok]))
    dev = np.abs(x[ok] - med)
    mad = float(np.median(dev))
    if mad > 0:
        z[ok] = 0.6745 * (x[ok] - med) / mad
        return z
    mean_ad = float(np.mean(dev))
    if mean_ad > 0:
        z[ok] = (x[ok] - med) / (1.2533 * mean_ad)
    else:
        z[ok] = 0.0
    return z


def _values(rows: Sequence[dict[str, Any]], col: str, scale: str) -> NDArray:
    out = []
    for r in rows:
        v = r.get(col)
        v = float(v) if isinstance(v, int | float) else float("nan")
        if scale == "log":
            v = float(np.log(v)) if v > 0 else float("nan")
        out.append(v)
    return np.array(out)


def present_quantities(rows: list[dict[str, Any]]) -> list[str]:
    """The quantities of :data:`QUANTITIES` that some successful run has a number for (shown
    on the fleet page whatever the fleet's size; tested for outliers only from
    :data:`MIN_RUNS` runs)."""
    ok = [r for r in rows if r.get("status") == "ok"]
    return [
        q
        for q, _ in QUANTITIES
        if any(isinstance(r.get(q), int | float) and not isinstance(r.get(q), bool) for r in ok)
    ]


def flag_runs(rows: list[dict[str, Any]]) -> list[str]:
    """Add ``z_<quantity>``, ``flagged``, ``flags`` and ``named_effect`` to each row (in place)
    by the rule of the module docstring; returns the quantities tested."""
    ok = [r for r in rows if r.get("status") == "ok"]
    tested = [q for q in QUANTITIES if any(isinstance(r.get(q[0]), int | float) for r in ok)]
    if len(ok) < MIN_RUNS:
        tested = []
    for col, scale in tested:
        for r, z in zip(ok, robust_z(_values(ok, col, scale)), strict=True):
            r[f"z_{col}"] = None if not np.isfinite(z) else float(z)
    for r in rows:
        if r.get("status") != "ok":
            r["flagged"], r["flags"], r["named_effect"] = None, "", ""
            continue
        reasons, outlying = [], []
        for col, _ in tested:
            z = r.get(f"z_{col}")
            if z is not None and abs(z) > Z_LIMIT:
                reasons.append(f"{col} z={z:+.1f}")
                outlying.append(f"{col} {'high' if z > 0 else 'low'}")
        effects = [e for e in str(r.get("effects") or "").split(",") if e]
        if effects:
            reasons.append("diagnose added " + ", ".join(effects))
        if r.get("verdict_class") == "unexplained":
            reasons.append("unexplained residual")
        r["flagged"] = bool(reasons)
        r["flags"] = "; ".join(reasons)
        named = ", ".join(effects) or ", ".join(outlying)
        if not named and r.get("verdict_class") == "unexplained":
            named = "unexplained residual"
        r["named_effect"] = named
    return [c for c, _ in tested]
