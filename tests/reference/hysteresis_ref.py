"""Independent reference for the quasi-static hysteresis operator (spec model.md section 1).

Nothing here imports :mod:`labrig`. The operator is integrated from its definition,

    dS = (alpha0 + h(|u - u_s|)) du,      u_s = input at the last reversal,

sample to sample with adaptive Gauss-Kronrod quadrature of the slope (scipy.integrate.quad, tight
tolerances); the closed-form branch of the code under test is never used. Reversals are found
by an explicit sample-by-sample scan: a sample is a reversal point when the input's direction of
travel changes sign after it (flat stretches keep the previous direction). The actuator starts
at rest at 0 V with zero strain and ``u_s = 0``.

Memory rules: ``"last_reversal"`` (``u_s`` is the last extremum) or ``"return_point"`` (Madelung:
a stack of turning points; when the input passes the turning point below the current one, that
minor loop is forgotten and ``u_s`` goes back to the turning point before it). For the latter a
step that passes a turning point is integrated in pieces, each with its own ``u_s``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import integrate


def hysteresis_ref(
    u: Sequence[float],
    alpha0: float,
    h: Callable[[float], float],
    memory: str = "last_reversal",
) -> np.ndarray:
    """Strain for the voltage samples ``u`` (the operator is rate-independent: only the order
    of the values matters). ``h`` maps ``x >= 0`` to the hysteretic slope, ``h(0) = 0``."""

    def integral(a: float, b: float, u_s: float) -> float:
        val, _ = integrate.quad(
            lambda v: alpha0 + h(abs(v - u_s)), a, b, epsabs=1e-12, epsrel=1e-12, limit=200
        )
        return val

    s = 0.0
    turning = [0.0]  # turning points, oldest first; the last one is u_s
    u_prev = 0.0
    direction = 0.0
    out = np.empty(len(u))
    for n, x in enumerate(u):
        x = float(x)
        step = np.sign(x - u_prev)
        if step != 0:
            if direction != 0 and step != direction:
                # the previous sample was a local extremum
                if memory in ("return_point", "return_point_open"):
                    turning.append(u_prev)
                else:
                    turning = [u_prev]
            direction = step
            a = u_prev
            # the open rule never closes a loop onto the rest state (the bottom turning point)
            floor = 3 if memory == "return_point_open" else 2
            while len(turning) >= floor and step * (x - turning[-2]) > 0:
                # passes the turning point where the current minor loop began: integrate up to
                # it, forget the loop (the bottom turning point, the rest state, stays)
                c = turning[-2]
                s += integral(a, c, turning[-1])
                a = c
                del turning[-2 if len(turning) >= 3 else -1 :]
            s += integral(a, x, turning[-1])
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
