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
    """Real-valued ``E_{alpha,beta}(z)`` for real ``z`` (Garrappa's algorithm).

    Parameters
    ----------
    z : array_like
        Real arguments.
    alpha : float
        First parameter (``alpha > 0``).
    beta : float
        Second parameter.

    Returns
    -------
    numpy.ndarray
        ``E_{alpha,beta}(z)``, the shape of ``z``.

    Examples
    --------
    ``E_1(z) = exp(z)`` and ``E_2(-x^2) = cos(x)``:

    >>> round(float(mittag_leffler(-1.0, 1.0)), 12)
    0.367879441171
    >>> round(float(mittag_leffler(-4.0, 2.0)), 12)
    -0.416146836547
    """
    z = np.asarray(z, dtype=np.float64)
    out = np.asarray(_garrappa(np.atleast_1d(z), float(alpha), float(beta)))
    return out.real.reshape(z.shape)


def relaxor_step(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """Step response ``1 - E_lam(-(t/tau)^lam)`` of ``1/(1 + (tau s)^lam)``; 0 for ``t <= 0``.

    Parameters
    ----------
    t_s : array_like
        Times (s).
    tau_s : float
        Time constant ``tau`` (s).
    lam : float
        Order ``lam`` (``0 < lam < 2``).

    Returns
    -------
    numpy.ndarray
        The step response (dimensionless, DC gain 1) at ``t_s``.

    Examples
    --------
    For ``lam = 1``, ``1 - exp(-t / tau)``:

    >>> [round(float(s), 9) for s in relaxor_step([-1.0, 0.0, 1e-3], 1e-3, 1.0)]
    [0.0, 0.0, 0.632120559]
    """
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros(t.shape)
    pos = t > 0
    if np.any(pos):
        out[pos] = 1.0 - mittag_leffler(-((t[pos] / tau_s) ** lam), lam, 1.0)
    return out


def relaxor_ramp(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """Ramp response ``int_0^t s`` of ``1/(1 + (tau s)^lam)`` in s (unit-slope input).

    Parameters
    ----------
    t_s : array_like
        Times (s).
    tau_s : float
        Time constant ``tau`` (s).
    lam : float
        Order ``lam`` (``0 < lam < 2``).

    Returns
    -------
    numpy.ndarray
        The ramp response (s, for a unit slope) at ``t_s``; 0 for ``t <= 0``.
    """
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
    """Upper pole ``exp(j pi / lam) / tau`` of the relaxor for ``1 < lam < 2``, else ``None``.

    Parameters
    ----------
    tau_s : float
        Time constant ``tau`` (s).
    lam : float
        Order ``lam``.

    Returns
    -------
    complex or None
        The pole (1/s) with positive imaginary part, or ``None`` for ``lam <= 1``.

    Examples
    --------
    >>> pole_pair(1.0, 0.5) is None
    True
    >>> p = pole_pair(1.0, 1.5)
    >>> round(p.real, 12), round(p.imag, 12)
    (-0.5, 0.866025403784)
    """
    if lam <= 1.0:
        return None
    return complex(np.exp(1j * np.pi / lam) / tau_s)


def relaxor_step_pole_part(t_s: ArrayLike, tau_s: float, lam: float) -> NDArray[np.float64]:
    """The poles' share ``-(2/lam) Re exp(p t)`` of the step response (0 when ``lam <= 1``).

    Parameters
    ----------
    t_s : array_like
        Times (s).
    tau_s : float
        Time constant ``tau`` (s).
    lam : float
        Order ``lam``.

    Returns
    -------
    numpy.ndarray
        The poles' part of the step response at ``t_s`` (0 for ``t <= 0``).
    """
    t = np.asarray(t_s, dtype=np.float64)
    p = pole_pair(tau_s, lam)
    out = np.zeros(t.shape)
    if p is None:
        return out
    live = (t > 0) & (t * p.real > -70.0)  # e^(Re p t) < 4e-31 beyond: exactly 0 here
    out[live] = -(2.0 / lam) * np.exp(p * t[live]).real
    return out
