"""Mittag-Leffler kernel of the relaxors against independent high-precision references.

The references (tests/reference/mittag_leffler_ref.py) are checked first against closed forms
and against each other (power series at raised precision, Gorenflo-Mainardi integral, Talbot
inversion); then labrig's ``mittag_leffler``, ``relaxor_ramp`` and the pole pair are compared
with them.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from labrig.model.mittag_leffler import (
    mittag_leffler,
    pole_pair,
    relaxor_ramp,
    relaxor_step,
    relaxor_step_pole_part,
)

from reference.mittag_leffler_ref import (
    ml_integral,
    ml_series,
    ramp_integral,
    ramp_series,
    step_mean_integral,
    step_talbot,
)

LAMS = (0.15, 0.5, 0.99, 1.35, 1.8)

# -- the references against closed forms ------------------------------------------------------


@pytest.mark.parametrize("x", [1e-3, 0.4, 2.0, 7.5, 25.0, 60.0])
def test_reference_series_closed_forms(x: float) -> None:
    # E_1(-x) = exp(-x), E_2(-x^2) = cos(x), E_1/2(-x) = exp(x^2) erfc(x). The series is summed at
    # raised precision, so it must match to ~1e-20 relative even where the terms reach e^x;
    # 1e-18 leaves margin and is far below the 1e-9 the relaxor tests need. (E_1/2(-x) costs
    # x^2/2.3 extra digits, so it is checked up to x = 7.5 here and beyond by the integral.)
    with mp.workdps(30):
        assert abs(ml_series(x, 1) - mp.exp(-x)) <= 1e-18 * mp.exp(-x)
        assert abs(ml_series(mp.mpf(x) ** 2, 2) - mp.cos(x)) <= 1e-18
        if x <= 7.5:
            half = mp.exp(mp.mpf(x) ** 2) * mp.erfc(x)
            assert abs(ml_series(x, 0.5) / half - 1) <= 1e-18


@pytest.mark.parametrize("x", [0.3, 3.0, 40.0, 1e4])
def test_reference_integral_closed_form_half(x: float) -> None:
    # the integral representation at lam = 1/2 against exp(x^2) erfc(x), E_{1/2}(-x) with x = T^1/2
    with mp.workdps(30):
        T = mp.mpf(x) ** 2
        assert abs(ml_integral(T, 0.5) / (mp.exp(T) * mp.erfc(x)) - 1) <= 1e-15


@pytest.mark.parametrize("lam", LAMS)
@pytest.mark.parametrize("T", [0.3, 3.0, 15.0])
def test_reference_methods_agree(lam: float, T: float) -> None:
    # three independent evaluations of E_lam(-T^lam): power series, branch-cut integral (+ poles),
    # and, for lam <= 1, Talbot inversion; each is good to ~1e-20, so 1e-15 is a safe bound
    s = ml_series(mp.mpf(T) ** lam, lam)
    i = ml_integral(T, lam)
    assert abs(s - i) <= 1e-15
    if lam <= 1:
        assert abs((1 - step_talbot(T, lam)) - s) <= 1e-15


@pytest.mark.parametrize("lam", [0.15, 0.5, 0.99])
@pytest.mark.parametrize("T", [1e3, 6.5e6])
def test_reference_integral_vs_talbot_large_t(lam: float, T: float) -> None:
    # long times (slow relaxor at 1e3 s): the integral against Talbot inversion (fine for lam <= 1)
    assert abs((1 - step_talbot(T, lam)) - ml_integral(T, lam)) <= 1e-15


@pytest.mark.parametrize("lam", [1.35, 1.8])
@pytest.mark.parametrize("T", [60.0, 150.0])
def test_reference_integral_vs_series_past_the_poles(lam: float, T: float) -> None:
    # for lam > 1 Talbot misses the complex pole pair; check the integral + residues against the
    # series (here at ~60-100 digits) where the pole part is still visible
    assert abs(ml_series(mp.mpf(T) ** lam, lam) - ml_integral(T, lam)) <= 1e-15


@pytest.mark.parametrize(
    "lam", [pytest.param(lam, marks=[] if lam in (0.5, 1.35) else pytest.mark.slow) for lam in LAMS]
)
def test_reference_ramp(lam: float) -> None:
    # ramp R(T) = int_0^T step: series E_{lam,lam+2} form, integral form, and direct quadrature of
    # the (reference) step response must agree; relative 1e-14 (each is good to ~1e-20)
    T = 4.0
    rs = ramp_series(T, lam)
    ri = ramp_integral(T, lam)
    with mp.workdps(25):
        rq = mp.quad(lambda u: 1 - ml_series(u**lam, lam), [0, 0.1, 1, T])
    assert abs(rs - ri) <= 1e-14 * abs(rs)
    assert abs(rs - rq) <= 1e-14 * abs(rs)
    # interval mean of the step response from the integral form vs ramp differences
    h = 0.25
    with mp.workdps(40):
        diff = (ramp_series(T + h, lam) - rs) / h
    assert abs(step_mean_integral(T, h, lam) - diff) <= 1e-14


# -- labrig's kernel against the references ---------------------------------------------------


@pytest.mark.parametrize("lam", LAMS)
def test_mittag_leffler_function(lam: float) -> None:
    # Garrappa's algorithm is documented at ~1e-15 for real negative arguments; allow 1e-13
    # absolute on values bounded by ~1 (and far below the 1e-9 budget of the relaxor tests).
    # One point a decade, 1e-4 to 1e3 (both branches of the references); the relaxor's step
    # response (1 - E) is checked against mpmath at 10 times per order, to 1e-9, in
    # test_relaxor.py
    T = np.logspace(-4, 3, 8)
    x = T**lam
    got = mittag_leffler(-x, lam, 1.0)
    want = np.array([float(ml_series(float(xx), lam)) for xx in x[T <= 20]])
    want = np.concatenate([want, [float(ml_integral(float(tt), lam)) for tt in T[T > 20]]])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


@pytest.mark.parametrize("lam", LAMS)
@pytest.mark.parametrize("beta_shift", [0.0, 2.0])
def test_mittag_leffler_two_parameter(lam: float, beta_shift: float) -> None:
    # E_{lam,beta} for beta = lam (impulse response) and lam + 2 (ramp response), against the
    # series; values are O(1) or smaller, tolerance 1e-13 absolute as above
    beta = lam + beta_shift
    x = np.array([1e-3, 0.1, 1.0, 3.0, 10.0]) ** lam
    got = mittag_leffler(-x, lam, beta)
    want = np.array([float(ml_series(float(xx), lam, beta)) for xx in x])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


@pytest.mark.parametrize("lam", LAMS)
def test_relaxor_ramp(lam: float) -> None:
    # ramp response (drives the linear-hold kernel) vs the reference, relative 1e-12: the values
    # grow like t, so the error budget scales with them
    tau = 2e-3
    t = tau * np.logspace(-3, 4, 8)
    got = relaxor_ramp(t, tau, lam)
    want = np.array(
        [
            float(
                tau
                * (ramp_series(tt / tau, lam) if tt / tau <= 20 else ramp_integral(tt / tau, lam))
            )
            for tt in t
        ]
    )
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    assert np.all(relaxor_ramp(np.array([-1.0, 0.0]), tau, lam) == 0.0)


def test_step_is_zero_before_zero() -> None:
    # causal: nothing before the step (t <= 0); the value just after is ~ (t/tau)^lam / Gamma(1+lam)
    assert np.all(relaxor_step(np.array([-1.0, -1e-9, 0.0]), 1.0, 0.5) == 0.0)
    small = relaxor_step(np.array([1e-12]), 1.0, 0.5)[0]
    assert small == pytest.approx(1e-6 / float(mp.gamma(1.5)), rel=1e-5)


@pytest.mark.parametrize("lam", [1.1, 1.35, 1.8])
def test_pole_pair_and_its_share(lam: float) -> None:
    tau = 2e-3
    p = pole_pair(tau, lam)
    assert p is not None and p.imag > 0
    with mp.workdps(30):
        sp = mp.mpc(p.real, p.imag)
        den = lambda s: 1 + (tau * s) ** lam  # noqa: E731
        # p is a zero of 1 + (tau s)^lam on the principal branch, in the left half plane
        assert abs(den(sp)) <= 1e-12
        assert p.real < 0
        # residue of G(s)/s at p, from a numerical derivative of the denominator
        res = 1 / (sp * mp.diff(den, sp))
    t = np.array([1e-4, 1e-3, 5e-3, 2e-2])
    want = np.array([float(2 * mp.re(res * mp.exp(sp * tt))) for tt in t])
    np.testing.assert_allclose(relaxor_step_pole_part(t, tau, lam), want, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("lam", [0.15, 0.5, 1.0])
def test_no_pole_pair_for_lam_at_most_one(lam: float) -> None:
    assert pole_pair(1.0, lam) is None
    assert np.all(relaxor_step_pole_part(np.array([0.5, 2.0]), 1.0, lam) == 0.0)
