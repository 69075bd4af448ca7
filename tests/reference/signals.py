"""Test signals and a least-squares sine fit (no labrig imports)."""

from __future__ import annotations

import numpy as np


def sine_phasor(y: np.ndarray, t: np.ndarray, f_hz: float, n_poly: int = 3) -> complex:
    """Complex amplitude ``Z`` of the component ``Im(Z exp(j 2 pi f t))`` of ``y``.

    Least squares on ``[sin, cos, 1, t, t^2, ...]``: the polynomial absorbs what is left of a
    slowly decaying transient (the algebraic tails of a fractional relaxor, ~ t^-lam, are smooth
    over a few periods and nearly orthogonal to the sine over whole periods).
    """
    w = 2 * np.pi * f_hz
    x = (t - t.mean()) / (t[-1] - t[0])
    cols = [np.sin(w * t), np.cos(w * t)] + [x**k for k in range(n_poly)]
    c, *_ = np.linalg.lstsq(np.column_stack(cols), y, rcond=None)
    # a sin(wt) + b cos(wt) = Im((a + j b) e^{jwt})
    return complex(c[0], c[1])


def unipolar_sweep(n: int, rate_hz: float, f0_hz: float, f1_hz: float, seed: int = 0) -> np.ndarray:
    """0-100 V test drive: a log chirp ``f0 -> f1`` (70 %) plus four random sines (30 %)."""
    t = np.arange(n) / rate_hz
    k = np.log(f1_hz / f0_hz) / t[-1]
    phase = 2 * np.pi * f0_hz * np.expm1(k * t) / k
    rng = np.random.default_rng(seed)
    fs = rng.uniform(0.05, 0.02 * rate_hz, 4)
    ph = rng.uniform(0, 2 * np.pi, 4)
    multi = np.mean(0.5 * (1 + np.sin(2 * np.pi * fs[:, None] * t[None, :] + ph[:, None])), axis=0)
    return 100.0 * (0.7 * 0.5 * (1 - np.cos(phase)) + 0.3 * multi)
