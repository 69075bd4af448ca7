"""Model-versus-measurement metrics (one definition each, used everywhere).

- **NRMSE** (percent): ``100 * RMS(measured - predicted) / (max(measured) - min(measured))`` per
  entry; a set of entries is summarised by the plain mean of the per-entry values.
- **Max error** (ue): ``max |measured - predicted|``.
- **Loop area** (V ue): signed area of the voltage-strain loop over the *last full period*,
  by the shoelace formula on the closed polygon of its samples; positive when the loop runs
  counter-clockwise in the (V, strain) plane, i.e. the rising branch lies below the falling one
  (strain lagging the voltage, the piezo's orientation). An ellipse ``V = a cos(wt)``,
  ``S = b cos(wt - phi)`` has area ``pi a b sin(phi)``.
- **Strain at zero voltage** ("strain shift", the paper's Fig. 10b; ue): over the last period, the
  strain where the voltage crosses zero (mean over the crossings, linearly interpolated); when
  the voltage only touches its minimum (a unipolar sine), the mean strain over the contiguous
  samples around the smallest ``|V|`` whose ``|V|`` is within 1e-4 of the loop's voltage span
  of it (a few samples at 1 Hz and 1 kHz, one at higher frequencies).
- **Hysteresis width** (ue): over the last period, the largest vertical distance between the
  falling and the rising branch at equal voltage, signed as falling minus rising (positive for
  the piezo's orientation), both branches interpolated on 101 voltages spanning the middle 90 %
  of the loop.

The period comes from the drive frequency in ``record.meta`` (``frequency_hz``) or, when absent,
from the voltage (:func:`~labrig.analysis.spectra.estimate_frequency_hz`); it is rounded to
whole samples.
Loop metrics are ``None`` for entries that are not periodic (:func:`is_periodic`: at least two
full periods at the end of the record that repeat).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.analysis.records import Record
from labrig.analysis.spectra import drive_frequency_hz, estimate_frequency_hz

__all__ = [
    "compare",
    "drive_frequency_hz",
    "estimate_frequency_hz",
    "hysteresis_width",
    "is_periodic",
    "last_period",
    "loop_area",
    "max_error",
    "mean_nrmse_pct",
    "nrmse_pct",
    "scores_json",
    "strain_at_zero_voltage",
]


def nrmse_pct(measured: ArrayLike, predicted: ArrayLike, span_ue: float | None = None) -> float:
    """``100 * RMS(measured - predicted) / (max(measured) - min(measured))`` (percent); with
    ``span_ue`` that span instead (the entry's, when only part of it is scored)."""
    m = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    if m.shape != p.shape or m.size == 0:
        raise ValueError(f"measured {m.shape} and predicted {p.shape} must match and be non-empty")
    span = float(np.max(m) - np.min(m)) if span_ue is None else float(span_ue)
    if not span > 0:
        raise ValueError("NRMSE is undefined for a constant measured signal")
    return 100.0 * float(np.sqrt(np.mean((m - p) ** 2))) / span


def second_half_nrmse_pct(
    measured: ArrayLike, predicted: ArrayLike, fit_offset: bool = False
) -> float:
    """Held-out score of an entry whose nuisance terms (offset, drift, hum) were fitted on its
    first half: the RMS error over the second half, in percent of the **whole entry's** measured
    span, the normaliser of its NRMSE. (Normalised by the second half's own span, the quiet 0 V
    tail of a vanishing envelope scored 11 % for a perfect model: its span is a few ue.)
    ``fit_offset``: add to ``predicted`` the mean of ``measured - predicted`` over the first half
    (the only nuisance term of ``labrig fit --offset``)."""
    m = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    half = m.size // 2
    if fit_offset:
        p = p + float(np.mean(m[:half] - p[:half]))
    return nrmse_pct(m[half:], p[half:], span_ue=float(np.ptp(m)) if m.size else None)


def scores_json(
    nrmse: float,
    per_entry: dict[str, float],
    heldout: float | None,
    method: str,
    entries: list[str],
) -> dict[str, Any]:
    """The scores of a fitted model as ``labrig fit --json`` gives them (plain JSON types)."""
    return {
        "nrmse_pct": float(nrmse),
        "per_entry": {k: float(v) for k, v in per_entry.items()},
        "heldout_nrmse_pct": None if heldout is None else float(heldout),
        "method": method,
        "entries": list(entries),
    }


def mean_nrmse_pct(values: ArrayLike | dict[str, float]) -> float:
    """The summary of a set of entries: the mean of their NRMSE values."""
    vals = list(values.values()) if isinstance(values, dict) else list(np.ravel(values))
    return float(np.mean(vals))


def max_error(measured: ArrayLike, predicted: ArrayLike) -> float:
    """``max |measured - predicted|`` (ue)."""
    m = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    return float(np.max(np.abs(m - p)))


# -- periods -----------------------------------------------------------------------------------


def _period_samples(rate_hz: float, frequency_hz: float | None) -> int | None:
    if frequency_hz is None or not frequency_hz > 0:
        return None
    p = round(rate_hz / frequency_hz)
    return p if p >= 4 else None


def is_periodic(
    voltage: ArrayLike, rate_hz: float, frequency_hz: float | None, tol: float = 0.05
) -> bool:
    """True when the last two full periods of the voltage repeat (RMS difference below ``tol``
    of their span) and that span is not negligible (above ``tol`` of the record's span)."""
    v = np.asarray(voltage, dtype=float)
    p = _period_samples(rate_hz, frequency_hz)
    if p is None or v.size < 2 * p:
        return False
    v1, v2 = v[-2 * p : -p], v[-p:]
    span = float(np.ptp(v[-2 * p :]))
    if not span > tol * float(np.ptp(v)) or not span > 0:
        return False
    return float(np.sqrt(np.mean((v2 - v1) ** 2))) < tol * span


def last_period(n: int, rate_hz: float, frequency_hz: float | None) -> slice | None:
    """Indices of the last full period of an ``n``-sample record, or ``None``."""
    p = _period_samples(rate_hz, frequency_hz)
    if p is None or n < p:
        return None
    return slice(n - p, n)


def _window(voltage, strain, rate_hz, frequency_hz):
    v = np.asarray(voltage, dtype=float)
    s = np.asarray(strain, dtype=float)
    if v.shape != s.shape:
        raise ValueError(f"voltage {v.shape} and strain {s.shape} must have the same shape")
    f = frequency_hz if frequency_hz is not None else estimate_frequency_hz(v, rate_hz)
    sl = last_period(v.size, rate_hz, f)
    if sl is None:
        raise ValueError("no full period in the record (unknown frequency or too short)")
    return v[sl], s[sl]


# -- loop metrics ------------------------------------------------------------------------------


def loop_area(
    voltage: ArrayLike, strain: ArrayLike, rate_hz: float, frequency_hz: float | None = None
) -> float:
    """Signed area (V ue) of the voltage-strain loop over the last full period (module doc)."""
    v, s = _window(voltage, strain, rate_hz, frequency_hz)
    return 0.5 * float(np.sum(v * np.roll(s, -1) - np.roll(v, -1) * s))


def strain_at_zero_voltage(
    voltage: ArrayLike, strain: ArrayLike, rate_hz: float, frequency_hz: float | None = None
) -> float:
    """Strain (ue) at zero voltage over the last full period (module doc)."""
    v, s = _window(voltage, strain, rate_hz, frequency_hz)
    # strict sign changes, including the closing edge of the period
    vn, sn = np.roll(v, -1), np.roll(s, -1)
    cross = v * vn < 0
    if np.any(cross):
        a, b = v[cross], vn[cross]
        w = a / (a - b)
        return float(np.mean(s[cross] + w * (sn[cross] - s[cross])))
    # touching zero: the contiguous samples around the smallest |V| within 1e-4 of the span
    av = np.abs(v)
    i = int(np.argmin(av))
    near = av <= av[i] + 1e-4 * float(np.ptp(v))
    lo = i
    while lo > 0 and near[lo - 1]:
        lo -= 1
    hi = i
    while hi < v.size - 1 and near[hi + 1]:
        hi += 1
    return float(np.mean(s[lo : hi + 1]))


def hysteresis_width(
    voltage: ArrayLike, strain: ArrayLike, rate_hz: float, frequency_hz: float | None = None
) -> float:
    """Falling-minus-rising strain gap (ue) of largest size at equal voltage, last period."""
    v, s = _window(voltage, strain, rate_hz, frequency_hz)
    i_lo, i_hi = int(np.argmin(v)), int(np.argmax(v))
    p = v.size
    # rising: from the minimum to the maximum (cyclically), falling: back again
    rise = (i_lo + np.arange((i_hi - i_lo) % p + 1)) % p
    fall = (i_hi + np.arange((i_lo - i_hi) % p + 1)) % p
    if rise.size < 2 or fall.size < 2:
        return 0.0
    lo, hi = float(v[i_lo]), float(v[i_hi])
    grid = lo + (hi - lo) * np.linspace(0.05, 0.95, 101)

    def branch(idx: NDArray) -> NDArray:
        order = np.argsort(v[idx], kind="stable")
        return np.interp(grid, v[idx][order], s[idx][order])

    gap = branch(fall) - branch(rise)
    return float(gap[np.argmax(np.abs(gap))])


def compare(record: Record, predicted: ArrayLike, warmup_s: float = 0.0) -> dict[str, Any]:
    """All metrics of one entry, measured versus ``predicted`` (same sampling as the record).

    Keys: ``nrmse_pct``, ``max_error_ue`` (over the samples after ``warmup_s``), and for
    periodic entries (else ``None``) ``loop_area_Vue`` / ``loop_area_pred_Vue`` /
    ``loop_area_error_pct`` (relative to the measured area), ``strain_shift_ue`` /
    ``strain_shift_pred_ue`` / ``strain_shift_error_ue`` (predicted minus measured) and
    ``hysteresis_width_ue`` / ``hysteresis_width_pred_ue``.
    """
    p = np.asarray(predicted, dtype=float)
    if p.shape != record.strain_ue.shape:
        raise ValueError(f"prediction {p.shape} does not match record {record.strain_ue.shape}")
    i0 = min(round(warmup_s * record.rate_hz), record.n - 1)
    out: dict[str, Any] = {
        "nrmse_pct": nrmse_pct(record.strain_ue[i0:], p[i0:]),
        "max_error_ue": max_error(record.strain_ue[i0:], p[i0:]),
    }
    f = drive_frequency_hz(record)
    keys = (
        "loop_area_Vue",
        "loop_area_pred_Vue",
        "loop_area_error_pct",
        "strain_shift_ue",
        "strain_shift_pred_ue",
        "strain_shift_error_ue",
        "hysteresis_width_ue",
        "hysteresis_width_pred_ue",
    )
    out.update(dict.fromkeys(keys))
    if not is_periodic(record.voltage_V, record.rate_hz, f):
        return out
    v, r = record.voltage_V, record.rate_hz
    am, ap = loop_area(v, record.strain_ue, r, f), loop_area(v, p, r, f)
    sm, sp = strain_at_zero_voltage(v, record.strain_ue, r, f), strain_at_zero_voltage(v, p, r, f)
    out.update(
        loop_area_Vue=am,
        loop_area_pred_Vue=ap,
        loop_area_error_pct=100.0 * (ap - am) / abs(am) if am != 0 else None,
        strain_shift_ue=sm,
        strain_shift_pred_ue=sp,
        strain_shift_error_ue=sp - sm,
        hysteresis_width_ue=hysteresis_width(v, record.strain_ue, r, f),
        hysteresis_width_pred_ue=hysteresis_width(v, p, r, f),
    )
    return out
