"""The noise floor: the NRMSE a perfect model would reach on a set of records.

One estimator serves every command that prints a floor (``labrig fit``, ``report``,
``validate`` and ``diagnose``), so one file and one model's residual get one floor (another
model's residual, or our model identified on other records, can read a little differently). It
is measured on a model's
residual ``r = measured - predicted`` (ue), after the warm-up:

- a periodic entry of period ``P`` samples holding at least :data:`MIN_PERIODS` periods: over
  its second half, ``sigma = RMS(r[k + P] - r[k]) / sqrt 2``: errors of the model locked to the
  drive repeat every period and cancel, white noise adds in quadrature;
- any other entry: ``sigma = RMS(second difference of r) / sqrt 6``: a smooth model error
  cancels, white noise of RMS ``sigma`` gives ``6 sigma^2``. A periodic entry of fewer periods
  is one of them: its second half would not hold two periods, and the differences would take in
  how the residual settles after the entry's start (the relaxors' memory of a start from rest,
  or from a state the model does not know in a part cut from a longer record), which is model
  error, not noise. Where that RMS exceeds the second difference's robust spread
  (``1.4826 x`` its median absolute deviation, the RMS of Gaussian noise) by more than
  :data:`HEAVY_TAIL_RATIO`, model error concentrated in few samples dominates it (a step or a
  PRBS edge the model follows late: a 7x floor on such a record), and the robust spread is
  used, never below the measured strain's resolution ``q / sqrt 12`` (``q`` its smallest
  non-zero sample-to-sample change; a quantised sensor's differences are mostly zero).

The floor of an entry is ``100 sigma / (max m - min m)`` percent, like the NRMSE, and the floor
of the records is the mean over entries (the NRMSE is averaged the same way). A model that
misses an effect changing from period to period (a drift, a slow creep) raises the estimate a
little; a configured gauge noise is not used, so a simulated bench and a real one are measured
alike.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.metrics import drive_frequency_hz, is_periodic
from labrig.analysis.records import Record

__all__ = [
    "HEAVY_TAIL_RATIO",
    "MIN_PERIODS",
    "SOURCE",
    "NoiseFloor",
    "entry_period",
    "noise_floor",
    "residual_noise",
]

#: the periods a periodic entry's residual must hold for the period-to-period rule (its second
#: half then holds two)
MIN_PERIODS = 4
#: the second-difference rule's RMS over its robust spread beyond which the spread is used
#: (Gaussian noise: 1.00 +- 0.03 on 2 000 samples; the real and simulated records of the
#: tests: 0.97-1.07; a step-driven record's model error: 6)
HEAVY_TAIL_RATIO = 1.5
#: the median absolute deviation of a normal variable, in standard deviations
_MAD_PER_SIGMA = 0.6744897501960817
#: where the floor's noise RMS comes from, in words (printed beside the floor)
SOURCE = "the period-to-period scatter of the model's residual"


@dataclass(frozen=True)
class NoiseFloor:
    """The NRMSE of a perfect model (percent), the noise RMS behind it (ue, mean over
    entries) and where that RMS came from."""

    nrmse_pct: float
    noise_ue: float
    source: str


def residual_noise(res: NDArray[np.float64], period: int | None, resolution: float = 0.0) -> float:
    """The white-noise RMS in a residual ``res`` (its unit), module docstring.

    Parameters
    ----------
    res : ndarray
        Residual, measured minus predicted, after the warm-up.
    period : int or None
        Samples per period of a periodic entry, else ``None``.
    resolution : float
        The measured signal's resolution ``q`` (its unit; 0: unknown): the second-difference
        rule's robust spread is kept at or above ``q / sqrt 12``.

    Returns
    -------
    float
        The noise RMS; 0.0 for a residual too short to tell.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> locked = np.tile(np.sin(np.linspace(0, 6.3, 100)), 40)  # repeats every 100 samples
    >>> round(residual_noise(locked + rng.normal(0, 0.1, 4000), 100), 2)
    0.1
    """
    if period and res.size >= MIN_PERIODS * period:
        x = res[-(res.size // 2) :]
        d = x[period:] - x[:-period]
        return float(np.sqrt(np.mean(d * d)) / np.sqrt(2.0))
    d = np.diff(res, 2)
    if not d.size:
        return 0.0
    rms = float(np.sqrt(np.mean(d * d)) / np.sqrt(6.0))
    robust = float(np.median(np.abs(d - np.median(d)))) / _MAD_PER_SIGMA / np.sqrt(6.0)
    if rms > HEAVY_TAIL_RATIO * robust:
        return max(robust, resolution / np.sqrt(12.0))
    return rms


def resolution_of(x: NDArray[np.float64]) -> float:
    """A signal's resolution: its smallest non-zero sample-to-sample change (0 for fewer than
    two samples or a constant)."""
    d = np.abs(np.diff(np.asarray(x, dtype=float)))
    d = d[d > 0]
    return float(d.min()) if d.size else 0.0


def entry_period(record: Record) -> int | None:
    """Samples per period of ``record``'s drive when it is periodic, else ``None``."""
    f0 = drive_frequency_hz(record)
    if f0 and is_periodic(record.voltage_V, record.rate_hz, f0):
        return round(record.rate_hz / f0)
    return None


def noise_floor(
    records: Sequence[Record],
    predictions: Mapping[str, NDArray[np.float64]],
    warmup_s: float = 0.0,
) -> NoiseFloor | None:
    """The noise floor of ``records`` from a model's ``predictions`` (module docstring).

    Parameters
    ----------
    records : sequence of Record
        The scored entries.
    predictions : mapping
        Entry name -> predicted strain (ue) over the whole record, offsets included; entries
        without a prediction are left out.
    warmup_s : float
        Seconds at the start of each entry left out of the score.

    Returns
    -------
    NoiseFloor or None
        ``None`` when no entry has a prediction and a strain span.
    """
    pct, ue = [], []
    for r in records:
        if r.name not in predictions:
            continue
        i0 = min(round(max(warmup_s, 0.0) * r.rate_hz), r.n - 1)
        m = r.strain_ue[i0:]
        span = float(np.ptp(m))
        if span <= 0:
            continue
        sigma = residual_noise(m - predictions[r.name][i0:], entry_period(r), resolution_of(m))
        pct.append(100.0 * sigma / span)
        ue.append(sigma)
    if not pct:
        return None
    return NoiseFloor(float(np.mean(pct)), float(np.mean(ue)), SOURCE)
