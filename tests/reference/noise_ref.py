"""Independent references for the noise floor (nothing here imports :mod:`labrig`).

- :func:`configured_noise_ue`: the simulated bench's gauge noise as its run file configures it
  (``instrument.bench.config.gauge.noise_ue``) with the ADC's quantisation ``LSB / sqrt 12``
  added in quadrature: the truth the estimator must find on a simulated run.
- :func:`hold_noise_ue`: the strain's scatter where the voltage is held constant for 0.5 s or
  longer, ``std(diff(strain)) / sqrt 2`` pooled over the holds: a model-free estimate from the
  raw data (first differences remove a slow creep at constant voltage).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np


def configured_noise_ue(instrument: Mapping[str, Any]) -> float | None:
    """The configured gauge noise (ue rms) with the quantisation, or ``None`` when the run file
    describes no clean simulated bench (other disturbances configured, or real hardware)."""
    try:
        gauge = instrument["bench"]["config"]["gauge"]
        noise = float(gauge["noise_ue"])
    except (KeyError, TypeError, ValueError):
        return None
    if instrument["bench"]["config"].get("effects"):
        return None
    q = 0.0
    try:
        lo, hi = instrument["daq"].get("ai_range_V", [-10.0, 10.0])
        bits = instrument["daq"].get("ai_bits")
        cal = instrument["calibration"]
        sens = float(cal["sensitivity_mV_per_ue"]) * float(cal.get("conditioner_gain", 1.0))
        if bits and sens > 0:
            q = (float(hi) - float(lo)) / 2 ** int(bits) / (sens * 1e-3) / math.sqrt(12.0)
    except (KeyError, TypeError, ValueError):
        pass
    return math.sqrt(noise**2 + q**2)


def hold_noise_ue(
    voltages: Sequence[np.ndarray], strains: Sequence[np.ndarray], rates_hz: Sequence[float]
) -> float | None:
    """Noise RMS (ue) from stretches of constant voltage at least 0.5 s long, else ``None``."""
    diffs = []
    for v, s, rate in zip(voltages, strains, rates_hz, strict=True):
        tol = 1e-6 * max(float(np.ptp(v)), 1e-12)
        same = np.abs(np.diff(v)) <= tol
        n_min = max(round(0.5 * rate), 8)
        edges = np.flatnonzero(np.diff(np.r_[0, same.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a + 1 >= n_min:
                d = np.diff(s[a : b + 1])
                diffs.append(d - d.mean())
    if not diffs:
        return None
    d = np.concatenate(diffs)
    return float(np.sqrt(np.mean(d**2) / 2.0))
