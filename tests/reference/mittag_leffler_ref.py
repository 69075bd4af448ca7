"""High-precision references for the Mittag-Leffler function and the fractional relaxor.

Nothing here imports :mod:`labrig`. Three independent evaluations of ``E_a(-T^a)``:

- :func:`ml_series`: the defining power series ``sum_k (-x)^k / Gamma(a k + b)`` summed in mpmath
  with the working precision raised to absorb the cancellation (the terms peak near
  ``exp(x^(1/a))``, so about ``x^(1/a) / ln 10`` digits are lost);
- :func:`ml_integral`: the Gorenflo-Mainardi representation (branch-cut integral plus, for
  ``1 < a < 2``, the residues of the poles ``exp(+-j pi/a)``), integrated by mpmath's
  tanh-sinh quadrature in ``v = ln r``, where the kernel is the smooth
  ``sin(a pi) / (2 pi (cosh(a v) + cos(a pi)))``;
- :func:`step_talbot`: Talbot inversion of ``G(s)/s`` (mpmath.invertlaplace), fine for ``a <= 1``.

The relaxor ``G(s) = 1/(1 + (tau s)^a)`` has step response ``1 - E_a(-(t/tau)^a)`` and ramp
response ``R = int_0^t step``. Times are in units of ``tau`` (``T = t / tau``) unless noted.
"""

from __future__ import annotations

from functools import lru_cache

import mpmath as mp

#: below this T = t/tau the power series is used (<= ~10 extra digits), above it the integral
SERIES_T_MAX = 20.0


def _series_dps(x: mp.mpf, a: float, extra: int) -> int:
    t_eff = float(x) ** (1.0 / a) if x > 0 else 0.0
    return int(30 + extra + t_eff / 2.302585 + 2 * mp.log10(1 + t_eff))


def ml_series(x, a, b=1, extra: int = 10) -> mp.mpf:
    """``E_{a,b}(-x)`` for ``x >= 0`` by the power series at adaptive precision."""
    x = mp.mpf(x)
    dps = _series_dps(x, float(a), extra)
    with mp.workdps(dps):
        a_, b_ = mp.mpf(a), mp.mpf(b)
        tol = mp.mpf(10) ** (-(dps - 5))
        total = mp.mpf(0)
        term_x = mp.mpf(1)  # (-x)^k
        k = 0
        peak = 0
        while True:
            term = term_x * mp.rgamma(a_ * k + b_)
            total += term
            peak = max(peak, abs(term))
            # stop once the terms decrease and are negligible against the largest one
            if k > 5 and abs(term) < tol * max(1, abs(total)) and abs(term) < peak * tol:
                break
            term_x *= -x
            k += 1
            if k > 10_000_000:  # pragma: no cover - a guard, never reached for our inputs
                raise RuntimeError("series did not converge")
        return +total


def _kernel(v, a):
    """Branch-cut density of ``E_a(-T^a)`` in ``v = ln r``.

    ``K(r) r = sin(a pi) / (2 pi (cosh(a v) + cos(a pi)))`` with ``r = e^v``.
    """
    return mp.sin(a * mp.pi) / (2 * mp.pi * (mp.cosh(a * v) + mp.cos(a * mp.pi)))


def _breaks(T, a, upper):
    """Quadrature break points in ``v = ln r``: around ``v = -ln T`` where ``exp(-T e^v)`` cuts
    the integrand off, and around ``v = 0`` where the kernel peaks (sharply for ``a`` near 1)."""
    lt = mp.log(T)
    pts = {-lt - 3, -lt, -lt + 2, -lt + 4, mp.mpf(-2), mp.mpf(0), mp.mpf(2)}
    if abs(a - 1) < 0.2:
        pts |= {mp.mpf(p) for p in (-0.3, -0.1, -0.03, 0.03, 0.1, 0.3)}
    if upper is not None:
        pts = {p for p in pts if p < upper}
        return [mp.ninf, *sorted(pts), upper]
    return [mp.ninf, *sorted(pts), mp.inf]


def _pole_E(T, a):
    """Residue part ``(2/a) Re exp(p T)``, ``p = exp(j pi / a)``, of ``E_a(-T^a)`` (``a > 1``)."""
    if a <= 1:
        return mp.mpf(0)
    p = mp.expjpi(1 / mp.mpf(a))
    return 2 / mp.mpf(a) * mp.re(mp.exp(p * T))


def ml_integral(T, a, dps: int = 10) -> mp.mpf:
    """``E_a(-T^a)`` for ``T > 0``, ``0 < a < 2``, ``a != 1``, by the integral representation."""
    with mp.workdps(dps + 10):
        T, a_ = mp.mpf(T), mp.mpf(a)
        upper = mp.log(120 / T)  # beyond: exp(-T e^v) < e^-120

        def f(v):
            return _kernel(v, a_) * mp.exp(-T * mp.exp(v))

        val = mp.quad(f, _breaks(T, a_, upper), maxdegree=10)
        return +(val + _pole_E(T, a_))


def step_talbot(T, a, dps: int = 30) -> mp.mpf:
    """Unit-step response at ``T`` by Talbot inversion of ``1 / (s (1 + s^a))`` (``a <= 1``)."""
    with mp.workdps(dps):
        a_ = mp.mpf(a)
        return +mp.invertlaplace(lambda s: 1 / (s * (1 + s**a_)), mp.mpf(T), method="talbot")


def ml_neg(T, a) -> mp.mpf:
    """``E_a(-T^a)``: exact for ``a = 1``, series for small ``T``, integral representation above."""
    T = mp.mpf(T)
    if T == 0:
        return mp.mpf(1)
    if a == 1:
        return mp.exp(-T)
    if T <= SERIES_T_MAX:
        return ml_series(T**a, a)
    return ml_integral(T, a)


def ramp_series(T, a) -> mp.mpf:
    """Ramp response ``R(T) = T^(a+1) E_{a,a+2}(-T^a)`` (tau = 1) by the power series."""
    T = mp.mpf(T)
    with mp.workdps(40):
        a_ = mp.mpf(a)  # a + 2 in mpf: the float sum would be off by ~1e-16
        return T ** (a_ + 1) * ml_series(T**a_, a_, a_ + 2)


def ramp_integral(T, a, dps: int = 10) -> mp.mpf:
    """``R(T) = T - int K(r)(1 - e^{-rT})/r dr - [a>1] (2/a) Re((e^{pT} - 1)/p)`` (tau = 1)."""
    with mp.workdps(dps + 10):
        T, a_ = mp.mpf(T), mp.mpf(a)

        def f(v):
            if v > 2000:  # the integrand is below e^-2000 there; tanh-sinh probes huge v
                return mp.mpf(0)
            return _kernel(v, a_) * (-mp.expm1(-T * mp.exp(v))) * mp.exp(-v)

        # beyond v = 8 + 70/(1 + a) the integrand is below e^-78 and falls like e^-(1+a)v
        br = _breaks(T, a_, None)
        br[-1] = max(br[-2] + 1, 8 + 70 / (1 + a_))
        val = mp.quad(f, br, maxdegree=10)
        pole = mp.mpf(0)
        if a_ > 1:
            p = mp.expjpi(1 / a_)
            pole = 2 / a_ * mp.re(mp.expm1(p * T) / p)
        return +(T - val - pole)


def ramp_ref(T, a) -> mp.mpf:
    """Unit-ramp response ``int_0^T (1 - E_a(-u^a)) du`` (tau = 1)."""
    T = mp.mpf(T)
    if T <= 0:
        return mp.mpf(0)
    if a == 1:
        return T + mp.expm1(-T)
    if T <= SERIES_T_MAX:
        return ramp_series(T, a)
    return ramp_integral(T, a)


@lru_cache(maxsize=100_000)
def relaxor_step_ref(t_s: float, tau_s: float, lam: float) -> float:
    """Step response ``1 - E_lam(-(t/tau)^lam)`` of ``1/(1 + (tau s)^lam)`` at ``t_s`` (s)."""
    if t_s <= 0:
        return 0.0
    with mp.workdps(30):
        T = mp.mpf(t_s) / mp.mpf(tau_s)
        return float(1 - ml_neg(T, lam))


def step_mean_integral(T, h, a, dps: int = 10) -> mp.mpf:
    """Mean of the unit-step response over ``[T, T + h]`` (tau = 1), by the integral representation.

    ``1 - int K(r) e^{-rT} (1 - e^{-rh})/(rh) dr - [a>1] (2/a) Re(e^{pT} (e^{ph} - 1)/(ph))``:
    no cancellation between ramp values, so it stays accurate for ``h << T``.
    """
    with mp.workdps(dps + 10):
        T, h, a_ = mp.mpf(T), mp.mpf(h), mp.mpf(a)
        upper = mp.log(120 / T) if T > 0 else None

        def f(v):
            if v > 2000:
                return mp.mpf(0)
            x = h * mp.exp(v)
            return _kernel(v, a_) * mp.exp(-T * mp.exp(v)) * (-mp.expm1(-x) / x)

        val = mp.quad(f, _breaks(T + h, a_, upper), maxdegree=10)
        pole = mp.mpf(0)
        if a_ > 1:
            p = mp.expjpi(1 / a_)
            pole = 2 / a_ * mp.re(mp.exp(p * T) * mp.expm1(p * h) / (p * h))
        return +(1 - val - pole)


@lru_cache(maxsize=100_000)
def relaxor_linear_step_ref(n: int, dt_s: float, tau_s: float, lam: float) -> float:
    """Response at ``t = n dt`` to the input ramping from 0 at ``-dt`` to 1 at 0, then 1.

    That input is ``(ramp(t + dt) - ramp(t)) / dt``, so the response is
    ``(r(t + dt) - r(t)) / dt`` with ``r`` the ramp response (``r(t) = tau R(t/tau)``): the mean
    of the step response over ``[t, t + dt]``.
    """
    if n < 0:
        return 0.0
    with mp.workdps(45):
        tau = mp.mpf(tau_s)
        h = mp.mpf(dt_s) / tau
        T0 = n * h
        if lam == 1 or T0 + h <= SERIES_T_MAX:
            # ramp differences; the series carries >= 40 digits, so the cancellation is harmless
            return float((ramp_ref(T0 + h, lam) - ramp_ref(T0, lam)) / h)
        return float(step_mean_integral(T0, h, lam))


def relaxor_G(f_hz, tau_s, lam) -> complex:
    """``G(j 2 pi f) = 1/(1 + (j 2 pi f tau)^lam)`` in mpmath (principal branch)."""
    with mp.workdps(30):
        s = 2j * mp.pi * mp.mpf(f_hz)
        return complex(1 / (1 + (mp.mpf(tau_s) * s) ** mp.mpf(lam)))
