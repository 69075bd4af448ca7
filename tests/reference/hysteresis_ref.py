"""Independent reference for the quasi-static hysteresis operator (spec model.md section 1).

Nothing here imports :mod:`labrig`. The operator is integrated from its definition,

    dS = (alpha0 + h(|u - u_s|)) du,      u_s = input at the last reversal,

sample to sample with adaptive Gauss-Kronrod quadrature of the slope (scipy.integrate.quad, tight
tolerances); the closed-form branch of the code under test is never used. Reversals are found
by an explicit sample-by-sample scan: a sample is a reversal point when the input's direction of
travel changes sign after it (flat stretches keep the previous direction). The actuator starts
at rest at 0 V with zero strain and ``u_s = 0``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import integrate


def hysteresis_ref(u: Sequence[float], alpha0: float, h: Callable[[float], float]) -> np.ndarray:
    """Strain for the voltage samples ``u`` (the operator is rate-independent: only the order
    of the values matters). ``h`` maps ``x >= 0`` to the hysteretic slope, ``h(0) = 0``."""
    s = 0.0
    u_s = 0.0
    u_prev = 0.0
    direction = 0.0
    out = np.empty(len(u))
    for n, x in enumerate(u):
        x = float(x)
        step = np.sign(x - u_prev)
        if step != 0:
            if direction != 0 and step != direction:
                u_s = u_prev  # the previous sample was a local extremum
            direction = step
            u_s_now = u_s
            val, _ = integrate.quad(
                lambda v, u_s_now=u_s_now: alpha0 + h(abs(v - u_s_now)),
                u_prev,
                x,
                epsabs=1e-12,
                epsrel=1e-12,
                limit=200,
            )
            s += val
        out[n] = s
        u_prev = x
    return out


def polyline(turns: Sequence[float], counts: Sequence[int]) -> np.ndarray:
    """Samples from 0 V through the turning points ``turns``: ``counts[i]`` samples from the
    previous point (exclusive) to ``turns[i]`` (inclusive), evenly spaced."""
    out = []
    prev = 0.0
    for target, k in zip(turns, counts, strict=True):
        out.append(np.linspace(prev, target, int(k) + 1)[1:])
        prev = target
    return np.concatenate(out) if out else np.zeros(0)
