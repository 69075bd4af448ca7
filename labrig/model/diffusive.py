"""The relaxor ``G(s) = 1 / (1 + (tau s)^lam)`` as a bank of first-order modes (``method="fast"``).

Diffusive representation. For ``0 < lam < 2``, ``lam != 1``,

    G(s) = int_0^inf mu(xi) / (s + xi) dxi  [ - (p/lam)/(s - p) + conj.,  p = e^(j pi/lam)/tau,
                                              for lam > 1 ]
    mu(xi) = (1/pi) sin(pi lam) / (r^-1 + 2 cos(pi lam) + r),     r = (tau xi)^lam,

and in ``x = ln xi`` the integrand ``mu(e^x) e^x / (s + e^x)`` decays like ``e^(-lam |x - x0|)``
on both sides of ``x0 = -ln tau``.

Quadrature (node positions fixed for a sample period ``dt``: independent of ``tau`` and ``lam``):

1. **Trapezoidal rule** in ``y`` with step ``h`` (:data:`H_STEP`), ``x = phi(y) = y -
   B e^(-(y - y_c)/B)``: uniform in ``x`` above ``y_c = ln(1 / T)`` (``T`` the accuracy
   horizon, :data:`HORIZON_SAMPLES` samples), ever wider below, where every mode is still an
   integrator over ``T``. The integrand is analytic in a strip about the real axis (the mode
   kernel ``e^(-xi t)`` limits it to ``|Im x| < pi/2``), so the rule converges like
   ``e^(-pi^2/h)``: ``h = 1/3`` gives ~1e-13 of full scale. The lattice stops below at
   ``xi T = 1e-12`` (:data:`EPS_LO`); the mass below is one mode matching ``int mu dxi`` and
   ``int mu / xi dxi`` there (exact DC gain, memory kept far beyond ``T``).
2. **Above ``40/dt``** a mode settles within a sample (``e^-40``): modes there are exactly an
   instantaneous gain (``direct_m1 = sum c/xi``, and ``direct_m2 = sum c/xi^2`` for the linear
   hold). The lattice runs on to ``x_H + 7 sigma`` with the window ``chi = erfc((x - x_H)/sigma)
   /2`` (``x_H = ln(40/dt) + 6 sigma``, :data:`WINDOW_SIGMA`); the rest, ``mu (1 - chi)``, is
   integrated apart (Gauss-Legendre, then in closed form). Those nodes cost nothing at run time.
3. **Pole correction.** ``mu(e^x)`` has simple poles at ``x0 +- j theta``,
   ``theta = pi |1 - lam| / lam``: near ``lam = 1`` (``theta`` small) ``mu`` is a spike narrower
   than any lattice, which is what made a fixed quadrature fail there. The trapezoidal rule's
   error from a pole ``z_p`` is known exactly: ``2 pi j Res E/(1 - E)``, ``E = e^(2 pi j
   y_p / h)`` (``y_p = phi^-1(z_p)``), times the kernel at ``z_p``. Subtracting it is one
   complex mode pair at ``q = -e^(z_p) = -e^(+-j theta)/tau`` (for ``lam > 1`` exactly the
   pole pair of ``G``, merged with it). Used for ``theta < 1.4`` (:data:`CORRECT_THETA`;
   beyond, the pole is outside the kernel's strip and its error below 1e-15). The bank is then
   accurate, and continuous, through ``lam = 1``.

Every mode is then discretised exactly for the input hold (:mod:`labrig.model.modal`), so the
only error is the quadrature. :func:`modes` also returns the derivatives of every pole and
weight with respect to ``ln tau`` and ``lam`` (closed forms; the lattice poles do not move).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from labrig.model.modal import ContinuousModes

H_STEP = 1.0 / 3.0  # trapezoidal step in y (nats of xi where the lattice is uniform)
HORIZON_SAMPLES = 1e8  # accuracy horizon T = HORIZON_SAMPLES * dt
GRADING = 1.0  # B of the map phi: how fast the lattice widens below 1/T
EPS_LO = 1e-12  # the lattice stops at xi = EPS_LO / T
XI_TOP_DT = 40.0  # modes faster than 40/dt are instantaneous gains (e^-40)
WINDOW_SIGMA = 2.0  # width (nats) of the window above 40/dt
CORRECT_THETA = 1.4  # pole correction when theta = pi |1 - lam| / lam is below this

_GX, _GW = np.polynomial.legendre.leggauss(16)


@dataclass(frozen=True)
class Lattice:
    """The fixed nodes for a sample period: ``x = ln xi`` (1/s), trapezoidal weights ``w``
    (window and ``phi'`` included; half weight at the lower end), which are instantaneous.

    Parameters
    ----------
    dt : float
        Sample period (s).
    y : numpy.ndarray
        The uniform grid, before grading.
    x : numpy.ndarray
        The nodes, ``x = phi(y) = ln xi``.
    w : numpy.ndarray
        The trapezoidal weights.
    fast : numpy.ndarray
        Which nodes lie above ``40/dt`` (instantaneous).
    y_c : float
        Where the grading starts (``ln(1 / T)``).
    x_top : float
        ``ln(40 / dt)``.
    x_h : float
        Centre of the window that hands the nodes over to the instantaneous part.
    x_end : float
        The last node's ``x``.
    """

    dt: float
    y: NDArray[np.float64]
    x: NDArray[np.float64]
    w: NDArray[np.float64]
    fast: NDArray[np.bool_]
    y_c: float
    x_top: float
    x_h: float
    x_end: float


def _phi(y: Any, y_c: float) -> Any:
    """``phi(y) = y - B exp(-(y - y_c) / B)`` for an array or a complex number."""
    return y - GRADING * np.exp(-(y - y_c) / GRADING)


def _dphi(y: Any, y_c: float) -> Any:
    """``phi'(y)`` for an array or a complex number."""
    return 1.0 + np.exp(-(y - y_c) / GRADING)


def _phi_inv(z: complex, y_c: float) -> complex:
    """``y`` with ``phi(y) = z`` (Newton; ``phi`` is increasing and convex on the real line)."""
    y = complex(z)
    if (y_c - z.real) / GRADING > 1.0:  # deep in the graded part: start from the asymptote
        y = complex(y_c - GRADING * np.log((y_c - z) / GRADING + 1.0))
    for _ in range(100):
        step = (_phi(y, y_c) - z) / _dphi(y, y_c)
        y -= step
        if abs(step) < 1e-15 * max(1.0, abs(y)):
            break
    return y


@lru_cache(maxsize=32)
def lattice(dt: float) -> Lattice:
    """The quadrature nodes for sample period ``dt`` (s).

    Parameters
    ----------
    dt : float
        Sample period (s).

    Returns
    -------
    Lattice
        The nodes and weights (cached).
    """
    y_c = float(np.log(1.0 / (HORIZON_SAMPLES * dt)))
    x_top = float(np.log(XI_TOP_DT / dt))
    x_h = x_top + 6 * WINDOW_SIGMA
    x_end = x_h + 7 * WINDOW_SIGMA  # chi < 1e-23 beyond
    y_lo = _phi_inv(complex(y_c + np.log(EPS_LO)), y_c).real  # phi(y_c) ~ y_c - B: ln(eps/T)
    k = np.arange(int(np.ceil(y_lo / H_STEP)), int(np.ceil(x_end / H_STEP)) + 1)
    y = (k * H_STEP).astype(np.float64)
    x = _phi(y, y_c)
    w = H_STEP * _dphi(y, y_c) * 0.5 * special.erfc((x - x_h) / WINDOW_SIGMA)
    w[0] *= 0.5  # trapezoidal end point; the slow-tail mode takes the mass below
    return Lattice(dt, y, x, w, x > x_top, y_c, x_top, x_h, x_end)


def mu_parts(x: NDArray, x0: float, lam: float) -> tuple[NDArray, NDArray, NDArray]:
    """``mu(e^x)`` and its derivatives with respect to ``ln tau`` and ``lam`` (``x0 = -ln tau``).

    With ``l = lam (x - x0)``: ``mu = sin(pi lam) / (pi D)``, ``D = e^-l + 2 cos(pi lam) + e^l``,
    written with ``e = e^-|l|`` so nothing overflows. ``dmu/dl = -mu (e^l - e^-l)/D``;
    ``dmu/dlam`` at fixed ``l`` ``= cos(pi lam)/D + 2 sin(pi lam)^2/D^2``;
    ``dl/d ln tau = lam``, ``dl/dlam = x - x0``.

    Parameters
    ----------
    x : numpy.ndarray
        ``ln xi`` (``xi`` in 1/s).
    x0 : float
        ``-ln tau``.
    lam : float
        Order (``0 < lam < 2``).

    Returns
    -------
    mu : numpy.ndarray
        The density.
    dmu_dln_tau : numpy.ndarray
        Its derivative with respect to ``ln tau``.
    dmu_dlam : numpy.ndarray
        Its derivative with respect to ``lam``.

    Examples
    --------
    For ``lam = 1/2`` the density at ``xi = 1/tau`` is ``1 / (2 pi)``:

    >>> import numpy as np
    >>> mu, _, _ = mu_parts(np.array([0.0]), 0.0, 0.5)
    >>> round(float(mu[0]) * 2 * np.pi, 12)
    1.0
    """
    lv = lam * (np.asarray(x, dtype=float) - x0)
    e = np.exp(-np.abs(lv))
    s, c = np.sin(np.pi * lam), np.cos(np.pi * lam)
    den = 1.0 + 2.0 * c * e + e * e  # = D e^-|l| (> 0 unless lam = 1 and l = 0)
    inv_d = e / den
    mu = s * inv_d / np.pi
    dmu_dl = -mu * np.sign(lv) * (1.0 - e * e) / den
    dmu_dlam = c * inv_d + 2.0 * (s * inv_d) ** 2 + dmu_dl * (x - x0)
    return mu, dmu_dl * lam, dmu_dlam


def _gauss(a: float, b: float, x0: float, theta: float) -> tuple[NDArray, NDArray]:
    """Gauss-Legendre nodes and weights on ``[a, b]``: unit panels, graded geometrically
    toward ``x0`` down to the scale ``theta`` when ``x0`` is within reach (the poles of ``mu``
    at ``x0 +- j theta``)."""
    pts = [a, b]
    s = max(theta, 1e-9)
    while s < b - a:
        pts += [p for p in (x0 - s, x0 + s) if a < p < b]
        s *= 2.0
    if a < x0 < b:
        pts.append(x0)
    nodes = np.unique(pts)
    edges = [nodes[0]]
    for p in nodes[1:]:
        n = int(np.ceil((p - edges[-1]) / 1.0))
        edges.extend(np.linspace(edges[-1], p, n + 1)[1:])
    e = np.asarray(edges)
    mid, half = (e[1:] + e[:-1]) / 2, (e[1:] - e[:-1]) / 2
    return (mid[:, None] + half[:, None] * _GX).ravel(), (half[:, None] * _GW).ravel()


def _tail_mass(X: float, x0: float, lam: float, above: bool) -> NDArray:
    """``int mu dx`` below ``X`` (or above it) in closed form, and its derivatives with respect
    to ``ln tau`` and ``lam``: ``[value, d/d ln tau, d/d lam]``.

    With ``U = e^(lam (X - x0))``, ``s = |sin(pi lam)|``, ``c = cos(pi lam)``:
    below ``= sign(sin) atan2(s U, 1 + c U) / (pi lam)``, above ``= sign(sin) atan2(s, U + c)
    / (pi lam)`` (``int du / ((u + c)^2 + s^2)``, ``u = e^l``, written without cancellation).
    """
    sg = np.sign(np.sin(np.pi * lam))
    s, c = abs(np.sin(np.pi * lam)), np.cos(np.pi * lam)
    ds, dc = sg * np.pi * c, -np.pi * sg * s  # d/dlam of |sin| and cos
    ell = lam * (X - x0)
    if above:
        U = np.exp(min(ell, 700.0))
        num, den = s, U + c
        dnum_dlam, dden_dlam = ds, dc
        dden_du = 1.0
        dnum_du = 0.0
    else:
        U = np.exp(min(ell, 700.0))
        num, den = s * U, 1.0 + c * U
        dnum_dlam, dden_dlam = ds * U, dc * U
        dnum_du, dden_du = s, c
    g = np.arctan2(num, den)
    r2 = num * num + den * den
    dg_du = (den * dnum_du - num * dden_du) / r2
    dg_dlam_u = (den * dnum_dlam - num * dden_dlam) / r2
    value = sg * g / (np.pi * lam)
    # U depends on ln tau (dU = lam U) and on lam (dU = (X - x0) U)
    d_ltau = sg / (np.pi * lam) * dg_du * lam * U
    d_lam = sg / (np.pi * lam) * (dg_dlam_u + dg_du * (X - x0) * U) - value / lam
    return np.array([value, d_ltau, d_lam])


@dataclass(frozen=True)
class ModeDerivatives:
    """Derivatives of a :class:`ContinuousModes` with respect to ``(ln tau, lam)``: rows 0 and 1
    of ``dq`` and ``dc`` (2, M) and of ``dm1``, ``dm2`` (2,).

    Parameters
    ----------
    dq, dc : numpy.ndarray
        Derivatives of the poles and residues, (2, M).
    dm1, dm2 : numpy.ndarray
        Derivatives of ``direct_m1`` and ``direct_m2``, (2,).
    """

    dq: NDArray[np.complex128]
    dc: NDArray[np.complex128]
    dm1: NDArray[np.float64]
    dm2: NDArray[np.float64]


def modes(tau_s: float, lam: float, dt: float) -> tuple[ContinuousModes, ModeDerivatives]:
    """The modal bank of ``G`` at sample period ``dt`` and its derivatives (module docstring).

    Mode order: the lattice nodes below ``40/dt`` (fixed for ``dt``), then the special modes:
    the complex pair (pole correction and, for ``lam > 1``, the poles of ``G``), the slow-tail
    mode. ``lam = 1`` is the single pole ``1 / (1 + tau s)``.

    Parameters
    ----------
    tau_s : float
        Time constant (s).
    lam : float
        Order (``0 < lam < 2``).
    dt : float
        Sample period (s).

    Returns
    -------
    modes : ContinuousModes
        The modes.
    derivatives : ModeDerivatives
        Their derivatives with respect to ``(ln tau, lam)``.
    """
    lt = float(np.log(tau_s))
    x0 = -lt
    if lam == 1.0:
        q1 = np.array([-1.0 / tau_s + 0j])
        c1 = np.array([1.0 / tau_s + 0j])
        dq1 = np.array([[1.0 / tau_s + 0j], [0.0]])  # d/d ln tau of -1/tau
        dc1 = np.array([[-1.0 / tau_s + 0j], [0.0]])
        # d/dlam at lam = 1 exists (the realisation is smooth there) but is not needed by the
        # fit, whose lam stays off exactly 1; report 0 rather than a one-sided value
        return ContinuousModes(q1, c1), ModeDerivatives(dq1, dc1, np.zeros(2), np.zeros(2))
    lat = lattice(dt)
    theta = np.pi * abs(1.0 - lam) / lam
    mu, dmu_t, dmu_l = mu_parts(lat.x, x0, lam)
    xi = np.exp(lat.x)
    slow = ~lat.fast
    q: list[NDArray] = [-xi[slow] + 0j]
    c: list[NDArray] = [lat.w[slow] * mu[slow] * xi[slow] + 0j]
    dq: list[NDArray] = [np.zeros((2, int(slow.sum())), dtype=complex)]
    w_s, xi_s = lat.w[slow], xi[slow]
    dc: list[NDArray] = [np.vstack([w_s * dmu_t[slow] * xi_s, w_s * dmu_l[slow] * xi_s]) + 0j]
    # instantaneous part: the lattice above 40/dt, then mu (1 - chi) apart
    f = lat.fast
    m1 = np.array(
        [np.sum(lat.w[f] * mu[f]), np.sum(lat.w[f] * dmu_t[f]), np.sum(lat.w[f] * dmu_l[f])]
    )
    m2 = np.array([np.sum(v[f] * lat.w[f] / xi[f]) for v in (mu, dmu_t, dmu_l)])
    gx, gw = _gauss(lat.x_top, lat.x_end, x0, theta)
    rest = 0.5 * special.erfc((lat.x_h - gx) / WINDOW_SIGMA)
    parts = mu_parts(gx, x0, lam)
    m1 += np.array([np.sum(gw * rest * v) for v in parts])
    m1 += _tail_mass(lat.x_end, x0, lam, above=True)  # 1 - chi = 1 above x_end
    m2 += np.array([np.sum(gw * rest * v * np.exp(-gx)) for v in parts])
    gx, gw = _gauss(lat.x_end, lat.x_end + 40.0, x0, theta)  # e^-x: negligible beyond
    m2 += np.array([np.sum(gw * v * np.exp(-gx)) for v in mu_parts(gx, x0, lam)])
    # the complex pair: pole correction of the trapezoidal rule, and G's poles for lam > 1
    pair_q, pair_c, pair_dq, pair_dc = _pair(tau_s, lam, lat, theta)
    # slow tail below the lattice: int mu dx (closed form) and int mu e^x dx (Gauss)
    x_lo = float(lat.x[0])
    m_1 = _tail_mass(x_lo, x0, lam, above=False)
    gx, gw = _gauss(x_lo - 40.0 / (1.0 + lam), x_lo, x0, theta)
    m0 = np.array([np.sum(gw * v * np.exp(gx)) for v in mu_parts(gx, x0, lam)])
    for qq, cc, dqq, dcc in zip(pair_q, pair_c, pair_dq, pair_dc, strict=True):
        if -qq.real * dt > XI_TOP_DT:  # settles within a sample: an instantaneous gain
            m1 += np.array([(cc / -qq).real, *((dcc / -qq + cc * dqq / qq**2).real)])
            m2 += np.array([(cc / qq**2).real, *((dcc / qq**2 - 2 * cc * dqq / qq**3).real)])
        else:
            q.append(np.array([qq]))
            c.append(np.array([cc]))
            dq.append(dqq[:, None])
            dc.append(dcc[:, None])
    if m0[0] * m_1[0] > 0.0:  # same sign (both negative for lam > 1)
        xe = m0[0] / m_1[0]  # the slow mode -xe with weight m0: DC gain m_1, impulse m0
        q.append(np.array([-xe + 0j]))
        c.append(np.array([m0[0] + 0j]))
        dq.append((-(m0[1:] * m_1[0] - m0[0] * m_1[1:]) / m_1[0] ** 2)[:, None] + 0j)
        dc.append(m0[1:, None] + 0j)
    out = ContinuousModes(
        q=np.concatenate(q), c=np.concatenate(c), direct_m1=float(m1[0]), direct_m2=float(m2[0])
    )
    return out, ModeDerivatives(np.hstack(dq), np.hstack(dc), m1[1:].copy(), m2[1:].copy())


def _pair(
    tau_s: float, lam: float, lat: Lattice, theta: float
) -> tuple[list[complex], list[complex], list[NDArray], list[NDArray]]:
    """The complex modes: the trapezoidal rule's pole correction (``theta <`` :data:
    `CORRECT_THETA`) and, for ``lam > 1``, ``G``'s poles; with derivatives (2,) each."""
    x0 = -np.log(tau_s)
    out_q: list[complex] = []
    out_c: list[complex] = []
    out_dq: list[NDArray] = []
    out_dc: list[NDArray] = []
    sgn = 1.0 if lam < 1.0 else -1.0
    dtheta = -sgn * np.pi / lam**2  # d theta / d lam
    if theta < CORRECT_THETA:
        zp = complex(x0, theta)
        yp = _phi_inv(zp, lat.y_c)
        if yp.real > lat.y[0] + 10 * H_STEP:  # the pole lies over the lattice
            res = sgn / (2j * np.pi * lam)  # residue of mu(e^x) at zp
            E = np.exp(2j * np.pi * yp / H_STEP)
            arg = (zp - lat.x_h) / WINDOW_SIGMA
            chi = 0.5 * special.erfc(arg)
            xp = np.exp(zp)
            gE = E / (1.0 - E)
            cc = -2j * np.pi * res * chi * gE * xp
            # derivatives through zp (d zp = -1 per ln tau, j dtheta per lam) and res (lam)
            dz = np.array([-1.0, 1j * dtheta])
            dyp = dz / _dphi(yp, lat.y_c)
            dE = E * (2j * np.pi / H_STEP) * dyp
            dchi = -np.exp(-(arg**2)) / (np.sqrt(np.pi) * WINDOW_SIGMA) * dz
            dres = np.array([0.0, -res / lam])
            dgE = dE / (1.0 - E) ** 2
            dxp = xp * dz
            dcc = -2j * np.pi * (dres * chi * gE * xp + res * dchi * gE * xp
                                 + res * chi * dgE * xp + res * chi * gE * dxp)  # fmt: skip
            out_q += [-xp, np.conj(-xp)]
            out_c += [cc, np.conj(cc)]
            out_dq += [-dxp, np.conj(-dxp)]
            out_dc += [dcc, np.conj(dcc)]
    if lam > 1.0:
        p = np.exp(1j * np.pi / lam) / tau_s
        dp = np.array([-p, p * (-1j * np.pi / lam**2)])
        r = -p / lam
        dr = -dp / lam + np.array([0.0, p / lam**2])
        if out_q:  # the correction sits on G's poles: merge (the correction's first mode is
            # at conj(p))
            out_q = [p, np.conj(p)]
            out_c = [r + out_c[1], np.conj(r) + out_c[0]]
            out_dq = [dp, np.conj(dp)]
            out_dc = [dr + out_dc[1], np.conj(dr) + out_dc[0]]
        else:
            out_q, out_c = [p, np.conj(p)], [r, np.conj(r)]
            out_dq, out_dc = [dp, np.conj(dp)], [dr, np.conj(dr)]
    return out_q, out_c, out_dq, out_dc
