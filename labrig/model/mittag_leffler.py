"""Mittag-Leffler function and the closed-form responses of a fractional relaxor.

The two-parameter Mittag-Leffler function ``E_{a,b}(z) = sum_k z^k / Gamma(a k + b)`` is evaluated
with the maintained ``pymittagleffler`` package (Garrappa's Laplace-inversion algorithm, accurate
to about 1e-15 for real negative arguments); the naive power series is useless for the large
arguments a slow relaxor produces. Our own accuracy check against a high-precision mpmath
reference lives in ``tests/model/test_mittag_leffler.py``.

For the relaxor ``G(s) = 1 / (1 + (tau s)^lam)`` (the paper's Eq. 4-9):

- step response      ``s(t) = 1 - E_lam(-(t/tau)^lam)``
- ramp response      ``r(t) = t^(lam+1) / tau^lam * E_{lam,lam+2}(-(t/tau)^lam)``  (integral of s)
- for ``1 < lam < 2`` the pair of poles ``p = exp(+-j pi/lam) / tau`` contributes
  ``-(2/lam) Re exp(p t)`` to ``s(t)``; the rest (the branch-cut part) is smooth in ``log t``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pymittagleffler import mittag_leffler as _garrappa


def mittag_leffler(z: ArrayLike, alpha: float, beta: float = 1.0) -> NDArray[np.float64]:
    """Real-valued ``E_{alpha,beta}(z)`` for real ``z`` (Garrappa's algorithm)."""
    z = np.asarray(z, dtype=np.float64)
    out = np.asarray(_garrappa(np.atleast_1d(z), float(alpha), float(beta)))
    return out.real.reshape(z.shape)


def relaxor_step(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """Step response ``1 - E_lam(-(t/tau)^lam)`` of ``1/(1 + (tau s)^lam)``; 0 for ``t <= 0``."""
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros(t.shape)
    pos = t > 0
    if np.any(pos):
        out[pos] = 1.0 - mittag_leffler(-((t[pos] / tau_s) ** lam), lam, 1.0)
    return out


def relaxor_ramp(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """Ramp response ``int_0^t s`` of ``1/(1 + (tau s)^lam)`` in s (unit-slope input)."""
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros(t.shape)
    pos = t > 0
    if np.any(pos):
        tp = t[pos]
        out[pos] = (
            tp ** (lam + 1.0) / tau_s**lam * mittag_leffler(-((tp / tau_s) ** lam), lam, lam + 2.0)
        )
    return out


def pole_pair(tau_s: float, lam: float) -> complex | None:
    """Upper pole ``exp(j pi / lam) / tau`` of the relaxor for ``1 < lam < 2``, else ``None``."""
    if lam <= 1.0:
        return None
    return complex(np.exp(1j * np.pi / lam) / tau_s)


def relaxor_step_pole_part(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """The poles' share ``-(2/lam) Re exp(p t)`` of the step response (0 when ``lam <= 1``)."""
    t = np.asarray(t_s, dtype=np.float64)
    p = pole_pair(tau_s, lam)
    out = np.zeros(t.shape)
    if p is None:
        return out
    live = (t > 0) & (t * p.real > -70.0)  # e^(Re p t) < 4e-31 beyond: exactly 0 here
    out[live] = -(2.0 / lam) * np.exp(p * t[live]).real
    return out
