"""The relaxor banks' previous quadrature, kept to be timed and compared in the same run.

Until the pole-corrected trapezoidal rule of ``labrig.model.diffusive``, ``method="fast"`` put
8 Gauss-Legendre nodes on each half-decade panel of ``ln xi`` over ``[1e-10 rad/s, 40/dt]``
(narrower panels as ``lam`` nears 1), one moment-matched slow mode below, the instantaneous
gain above, the pole pair for ``lam > 1`` and one mode at ``1/tau`` holding the DC gain the
panels miss near ``lam = 1``. This is that code, unchanged but for its names; the benchmarks
run it with the numpy block realisation (``run_bank(..., engine="numpy")``) and the numpy
operator, which together were the fast path before the compiled kernels.
"""

from __future__ import annotations

import numpy as np

from labrig.model.mittag_leffler import pole_pair
from labrig.model.modal import ContinuousModes

XI_MIN_RAD_S = 1e-10
PANELS_PER_DECADE = 2
GL_NODES = 8
_TAIL_X, _TAIL_W = np.polynomial.legendre.leggauss(16)


def _mu(xi: np.ndarray, tau_s: float, lam: float) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):
        r = (tau_s * np.asarray(xi, dtype=float)) ** lam
        return np.sin(np.pi * lam) / (np.pi * (1.0 / r + 2.0 * np.cos(np.pi * lam) + r))


def _mu_moment(tau_s: float, lam: float, lo: float, hi: float, power: int) -> float:
    """``int_lo^hi mu(xi) xi^power dxi`` by 16-point Gauss-Legendre unit panels in ln xi."""
    x0 = -np.log(tau_s)
    lo_x = np.log(lo) if lo > 0 else None
    hi_x = np.log(hi) if np.isfinite(hi) else None
    if lo_x is None:
        lo_x = min(hi_x, x0) - 50.0 / (power + 1 + lam)
    if hi_x is None:
        hi_x = max(lo_x, x0) + 50.0 / (lam - power - 1)
    if hi_x <= lo_x:
        return 0.0
    n = max(1, int(np.ceil(hi_x - lo_x)))
    edges = np.linspace(lo_x, hi_x, n + 1)
    mid, half = (edges[1:] + edges[:-1]) / 2, (edges[1:] - edges[:-1]) / 2
    x = (mid[:, None] + half[:, None] * _TAIL_X[None, :]).ravel()
    w = (half[:, None] * _TAIL_W[None, :]).ravel()
    r = np.exp(lam * (x - x0))
    mu = np.sin(np.pi * lam) / (np.pi * (1.0 / r + 2.0 * np.cos(np.pi * lam) + r))
    return float(np.sum(w * mu * np.exp((power + 1) * x)))


def previous_modes(tau_s: float, lam: float, dt: float) -> ContinuousModes:
    """The previous modal approximation of ``1 / (1 + (tau s)^lam)`` at sample period ``dt``."""
    if lam == 1.0:
        return ContinuousModes(q=np.array([-1.0 / tau_s + 0j]), c=np.array([1.0 / tau_s + 0j]))
    xi_lo, xi_hi = XI_MIN_RAD_S, 40.0 / dt
    q_list, c_list = [], []
    d = min(np.pi / 2, np.pi * abs(1.0 - lam) / lam)
    half = min(np.log(10) / (2 * PANELS_PER_DECADE), max(0.6 * d, 0.02))
    n_pan = int(np.ceil((np.log(xi_hi) - np.log(xi_lo)) / (2 * half)))
    edges = np.linspace(np.log(xi_lo), np.log(xi_hi), n_pan + 1)
    gx, gw = np.polynomial.legendre.leggauss(GL_NODES)
    mid, hw = (edges[1:] + edges[:-1]) / 2, (edges[1:] - edges[:-1]) / 2
    x = (mid[:, None] + hw[:, None] * gx[None, :]).ravel()
    w = (hw[:, None] * gw[None, :]).ravel()
    xi = np.exp(x)
    q_list.append(-xi + 0j)
    c_list.append(w * _mu(xi, tau_s, lam) * xi + 0j)
    m0 = _mu_moment(tau_s, lam, 0.0, xi_lo, 0)
    m_1 = _mu_moment(tau_s, lam, 0.0, xi_lo, -1)
    if m0 != 0.0 and m_1 != 0.0:
        q_list.append(np.array([-m0 / m_1 + 0j]))
        c_list.append(np.array([m0 + 0j]))
    m1 = _mu_moment(tau_s, lam, xi_hi, np.inf, -1)
    m2 = _mu_moment(tau_s, lam, xi_hi, np.inf, -2)
    p = pole_pair(tau_s, lam)
    if p is not None:
        r = -p / lam
        q_list.append(np.array([p, np.conj(p)]))
        c_list.append(np.array([r, np.conj(r)]))
    q, c = np.concatenate(q_list), np.concatenate(c_list)
    missing = 1.0 - (float(np.sum(c / -q).real) + m1)
    if abs(missing) > 1e-12:
        q = np.append(q, -1.0 / tau_s + 0j)
        c = np.append(c, missing / tau_s + 0j)
    return ContinuousModes(q=q, c=c, direct_m1=m1, direct_m2=m2)
