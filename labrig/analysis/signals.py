"""Test waveforms shared by the analysis: a unipolar sine and a step-and-hold (units V, s, Hz)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["sine", "step_hold"]


def sine(
    amplitude_V: float, frequency_hz: float, duration_s: float, rate_hz: float
) -> NDArray[np.float64]:
    """Unipolar sine ``V = A/2 (1 - cos 2 pi f t)`` from 0 V over whole cycles (at least
    ``duration_s``)."""
    cycles = max(1, int(np.ceil(duration_s * frequency_hz - 1e-9)))
    n = round(cycles / frequency_hz * rate_hz)
    t = np.arange(n) / rate_hz
    return 0.5 * amplitude_V * (1.0 - np.cos(2.0 * np.pi * frequency_hz * t))


def step_hold(
    amplitude_V: float, duration_s: float, rate_hz: float, ramp_s: float = 0.2
) -> NDArray[np.float64]:
    """Raised-cosine ramp to ``amplitude_V`` over ``ramp_s``, held for half of ``duration_s``,
    ramped back and held at 0 V for the other half (the ramp keeps the stack's current small:
    100 V over 0.2 s peaks at 785 V/s, 4.7 mA into 6 uF)."""
    n_ramp = max(1, round(ramp_s * rate_hz))
    n_hold = round(0.5 * duration_s * rate_hz)
    up = 0.5 * amplitude_V * (1.0 - np.cos(np.pi * np.arange(n_ramp) / n_ramp))
    return np.concatenate([up, np.full(n_hold, amplitude_V), up[::-1], np.zeros(n_hold)])
