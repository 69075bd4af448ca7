"""The virtual bench's structural truths (``amplifier_output_rc``, ``depoling``,
``viscous_slip``, ``stack_resonance``, ``gauge_warmup``) against independent references: an
ODE solver, a quadrature, the steady lag of a ramp, the analytic frequency response of a
mass-spring-damper, and the warm-up exponential; and on the bench, by name, on a linear truth
``S = alpha0 u`` (the hybrid plant with its hysteresis off) so what is measured is the effect."""

from __future__ import annotations

import math

import numpy as np
import pytest
from labrig.drivers.sim.bench import BenchConfig
from labrig.drivers.sim.effects import EFFECT_NAMES
from labrig.drivers.sim.structural import (
    STRUCTURAL_BENCH_EFFECTS,
    AmplifierOutputRC,
    Depoling,
    OutputRC,
    Resonance,
    StackResonance,
    ViscousSlip,
    ViscousSlipElements,
    depoled_drive,
)
from pydantic import ValidationError
from scipy.integrate import quad, solve_ivp

from helpers import linear_bench, strain

pytestmark = pytest.mark.timeout(60)


def test_the_names_are_bench_effects():
    for name in STRUCTURAL_BENCH_EFFECTS:
        assert name in EFFECT_NAMES
    with pytest.raises(ValidationError):
        BenchConfig.model_validate({"effects": [{"name": "depoling", "coercive_V": -1.0}]})
    with pytest.raises(ValidationError):
        BenchConfig.model_validate(
            {"effects": [{"name": "viscous_slip", "r_min_V": 5.0, "r_max_V": 1.0}]}
        )


@pytest.mark.parametrize(
    "effect",
    [
        {"name": "amplifier_output_rc", "output_resistance_ohm": 1e-9},
        {"name": "depoling", "coercive_V": 1e9},
        {"name": "viscous_slip", "gain_ue_per_V": 0.0},
        {"name": "stack_resonance", "mass_kg": 1e-9},
        {"name": "gauge_warmup", "zero_ue": 0.0, "span_fraction": 0.0},
    ],
)
def test_each_vanishes_at_zero_strength(effect):
    """At a negligible strength each leaves the linear truth's record as it is; the same effect
    at its default strength changes it (so the comparison can fail)."""
    rng = np.random.default_rng(1)
    v = np.cumsum(rng.normal(0, 3.0, 3000))
    v = np.clip(v - v.mean(), -140, 140)
    plain = strain(linear_bench([]), v)
    weak = strain(linear_bench([effect]), v)
    np.testing.assert_allclose(weak, plain, atol=1e-6 * np.ptp(plain))
    default = strain(linear_bench([{"name": effect["name"]}]), v)
    assert np.max(np.abs(default - plain)) > 1e-4 * np.ptp(plain)


# --- amplifier_output_rc ----------------------------------------------------------------------


def test_output_rc_follows_its_ode():
    """The stack voltage of ``R C(x) dx/dt = v - x`` with ``C = C0 (1 + rise |x| / V_ref)``,
    ``v`` held over each sample: solve_ivp (rtol 1e-10) against the bench's interval means, for a
    100 V 100 Hz sine at 20 kHz (tau 0.25..0.4 ms); agreement within 0.5 % of the amplitude
    (the bench holds C over each 50 us interval: an error of order dt/tau rise |dx|/V_ref)."""
    rate, r, c0, rise = 20000.0, 250.0, 1e-6, 0.7
    cfg = AmplifierOutputRC(
        name="amplifier_output_rc", output_resistance_ohm=r, capacitance_F=c0, capacitance_rise=rise
    )
    n = 400
    v = 100.0 * np.sin(2 * np.pi * 100.0 * np.arange(n) / rate)
    got = OutputRC(cfg, 5e-6, rate).process(v)  # capacitance_F given: the bench's C is not used

    def rhs(_t, x, vk):
        return [(vk - x[0]) / (r * c0 * (1 + rise * abs(x[0]) / 100.0))]

    sub, x, want = 8, 0.0, np.empty(n)
    for k in range(n):  # one interval at a time: v is constant over it
        t_eval = (np.arange(sub) + 0.5) / (rate * sub)
        sol = solve_ivp(
            rhs,
            (0, 1 / rate),
            [x],
            args=(v[k],),
            t_eval=t_eval,
            rtol=1e-10,
            atol=1e-10,
            dense_output=True,
        )
        want[k] = sol.y[0].mean()  # the interval's mean (midpoint rule on 8 points)
        x = float(sol.sol(1 / rate)[0])
    assert np.max(np.abs(got - want)) < 0.005 * 100.0
    # and the lag is real: at 100 Hz the stack voltage trails the command by ~ omega tau
    assert np.max(np.abs(got - v)) > 0.05 * 100.0


def test_output_rc_corner_falls_with_drive():
    """The capacitance rises with |v|: a 100 V step settles slower than a 1 V step (scaled)."""
    cfg = AmplifierOutputRC(
        name="amplifier_output_rc", output_resistance_ohm=250.0, capacitance_F=1e-6
    )
    rate = 200000.0
    small = OutputRC(cfg, 1e-6, rate).process(np.full(200, 1.0))
    large = OutputRC(cfg, 1e-6, rate).process(np.full(200, 100.0)) / 100.0
    tau0 = 250e-6
    i = round(tau0 * rate)  # one small-signal time constant in
    assert small[i] == pytest.approx(1 - math.exp(-1), abs=0.01)
    assert large[i] < small[i] - 0.05


# --- depoling ---------------------------------------------------------------------------------


@pytest.mark.parametrize("v", [-200.0, -100.0, -3.0, 0.0, 50.0])
def test_depoled_drive_is_the_integral_of_d33(v):
    cfg = Depoling(name="depoling", coercive_V=250.0)
    ref, _ = quad(lambda w: 1.0 / (1.0 + (w / 250.0) ** 2) if w < 0 else 1.0, 0.0, v)
    assert float(depoled_drive(np.array([v]), cfg)[0]) == pytest.approx(ref, rel=1e-10, abs=1e-12)


def test_depoling_takes_strain_off_the_negative_side_only():
    v = np.concatenate([np.linspace(0, 100, 101), np.linspace(100, -100, 201)])
    s = strain(linear_bench([{"name": "depoling"}]), v)
    plain = strain(linear_bench([]), v)
    pos, neg = v > 0, v < -50
    np.testing.assert_allclose(s[pos], plain[pos], rtol=1e-9)
    assert np.all(s[neg] > plain[neg])  # less negative strain: d33 lower under negative field
    # at -100 V: 250 atan(0.4) = 95.1 V of drive, 4.9 % less
    at = np.argmin(v)
    assert s[at] / plain[at] == pytest.approx(250 * math.atan(0.4) / 100, rel=1e-3)


# --- viscous_slip -----------------------------------------------------------------------------


@pytest.mark.parametrize("slope", [10.0, 20000.0])
def test_viscous_slip_lag_on_a_ramp(slope):
    """On a long ramp of slope s each element settles at the lag ``r_i + tau s`` (the steady
    state of ``de/dt = s - (e - r)/tau``): the term is ``-g mean(r_i + tau s)``."""
    cfg = ViscousSlip(name="viscous_slip")
    rate = 100000.0
    n = 4000
    v = slope * np.arange(n) / rate
    term = ViscousSlipElements(cfg, rate).process(v)
    want = -cfg.gain_ue_per_V * (np.mean(cfg.thresholds_V()) + cfg.tau_s * slope)
    if slope * n / rate > 60:  # the lag has built up
        assert term[-1] == pytest.approx(want, rel=2e-3)
    else:  # slow: within the thresholds, only the smallest elements have slipped
        assert abs(term[-1]) <= abs(want) + 1e-9


def test_viscous_slip_hysteresis_widens_with_rate():
    """The loop of the term against v on a triangle of 100 V: its width at the middle grows
    with the rate (rate-dependent), where a plain Maxwell-slip's would not."""
    cfg = ViscousSlip(name="viscous_slip")
    rate = 20000.0

    def width(f: float) -> float:
        t = np.arange(round(3 * rate / f)) / rate
        v = 50 + 50 * (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * f * t - np.pi / 2))
        term = ViscousSlipElements(cfg, rate).process(v)
        last = t >= 2 / f
        up = last & (np.gradient(v) > 0) & (np.abs(v - 50) < 1)
        down = last & (np.gradient(v) < 0) & (np.abs(v - 50) < 1)
        return float(term[down].mean() - term[up].mean())

    slow, fast = width(0.5), width(40.0)
    assert slow == pytest.approx(2 * 1.0 * np.mean(cfg.thresholds_V()), rel=0.02)
    # at 40 Hz (slope 8 kV/s, tau s = 16 V) the lag has not settled for the wide elements by
    # mid-stroke; the loop is still half as wide again
    assert fast > 1.5 * slow


# --- stack_resonance --------------------------------------------------------------------------


def test_resonance_frequency_response():
    """Steady-state gain of the mass on the stack's spring and damper against
    ``|H| = sqrt(1 + (2 zeta r)^2) / sqrt((1 - r^2)^2 + (2 zeta r)^2)``, r = f / f_n, below, at
    and above resonance (the damper on the relative motion: ``H = (c s + k)/(m s^2 + c s +
    k)``)."""
    cfg = StackResonance(name="stack_resonance")
    assert cfg.resonance_hz == pytest.approx(math.sqrt(20e6 / 8.0) / (2 * math.pi))
    rate = 20000.0
    for r in (0.3, 1.0, 2.0):
        f = r * cfg.resonance_hz
        t = np.arange(round(2.0 * rate)) / rate
        y = Resonance(cfg, rate).process(np.sin(2 * np.pi * f * t))
        tail = t >= 1.0  # 1 s: 80 time constants of the decay (1 / (zeta w_n) = 12.6 ms)
        gain = math.sqrt(2 * np.mean(y[tail] ** 2))
        zr = 2 * cfg.damping_ratio * r
        want = math.sqrt(1 + zr * zr) / math.sqrt((1 - r * r) ** 2 + zr * zr)
        # 5e-3: the first-order hold takes the sine as piecewise linear (40 samples a cycle)
        assert gain == pytest.approx(want, rel=5e-3), r


# --- gauge_warmup -----------------------------------------------------------------------------


def test_gauge_warmup_zero_follows_the_exponential():
    bench = linear_bench([{"name": "gauge_warmup", "zero_ue": 30.0, "tau_s": 20.0}], 100.0)
    t0 = bench.time_s
    s = strain(bench, np.zeros(6000))
    t = t0 + np.arange(6000) / 100.0
    np.testing.assert_allclose(s, 30.0 * (1 - np.exp(-t / 20.0)), atol=1e-9)


def test_gauge_warmup_span():
    bench = linear_bench(
        [{"name": "gauge_warmup", "zero_ue": 0.0, "span_fraction": 0.02, "tau_s": 1.0}], 100.0
    )
    plain = strain(linear_bench([], 100.0), np.full(1000, 50.0))
    s = strain(bench, np.full(1000, 50.0))
    t = np.arange(1000) / 100.0
    np.testing.assert_allclose(s, plain * (1 + 0.02 * (1 - np.exp(-t))), rtol=1e-9)
