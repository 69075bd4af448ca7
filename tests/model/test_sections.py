"""Sampled second-order sections (labrig.model.sections) against scipy.signal's own sampling and
filter, against the continuous equation, and without importing scipy.signal.

References: ``scipy.signal.cont2discrete(..., method="foh")`` with ``lfilter`` at rest
(``lfilter_zi``), 1e-9 of the record's range (lfilter's transfer-function form itself is off
the continuous solution by up to 1e-10 for a slow section sampled fast); ``solve_ivp``
(DOP853, rtol 1e-13) of ``tau^2 y'' + 2 zeta tau y' + y = u`` with ``u`` linear between
samples, where the section must be within 1e-12 of the range. Without numba the recursion
is scipy's ``lfilter`` on the section's transfer function (its import only then).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy import integrate

from labrig.model import accel, sections
from labrig.model.effects import library
from labrig.model.effects.base import Context
from labrig.model.sections import foh_section, run_section


def record(n: int, rate: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 30.0 + np.cumsum(rng.normal(size=n)) + 50 * np.sin(2 * np.pi * 5 * np.arange(n) / rate)


def scipy_reference(num, den, rate, x):
    from scipy import signal  # here, not for every worker's collection

    bd, ad, _ = signal.cont2discrete((num, den), 1.0 / rate, method="foh")
    b = np.atleast_1d(np.squeeze(bd)) / ad[0]
    a = np.asarray(ad, float) / ad[0]
    return signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])[0]


@pytest.mark.parametrize("rate", [500.0, 10_000.0, 100_000.0])
@pytest.mark.parametrize("fc", [16.0, 150.0, 1600.0])
@pytest.mark.parametrize("zeta", [0.2, 0.7, 1.0, 1.0 + 1e-6, 5.0])
def test_a_low_pass_is_scipys_foh_section_at_rest(rate, fc, zeta):
    tau = 1.0 / (2 * np.pi * fc)
    x = record(2000, rate)
    den = [tau * tau, 2 * zeta * tau, 1.0]
    got = run_section(foh_section([1.0], den, rate), x)
    want = scipy_reference([1.0], den, rate, x)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.ptp(x))


@pytest.mark.parametrize("q", [0.3, 1.0])
def test_a_section_with_a_zero_is_scipys(q):
    rate, tau, zeta = 10_000.0, 1.0 / (2 * np.pi * 800.0), 0.05
    x = record(3000, rate, seed=1)
    num, den = [2 * q * zeta * tau, 1.0], [tau * tau, 2 * zeta * tau, 1.0]
    got = run_section(foh_section(num, den, rate), x)
    np.testing.assert_allclose(got, scipy_reference(num, den, rate, x), atol=1e-9 * np.ptp(x))


@pytest.mark.parametrize(("rate", "fc", "zeta"), [(100_000.0, 16.0, 0.7), (100_000.0, 16.0, 1.0)])
def test_a_slow_section_sampled_fast_is_the_continuous_solution(rate, fc, zeta):
    tau = 1.0 / (2 * np.pi * fc)
    n = 1500
    x = record(n, rate, seed=2)
    t = np.arange(n) / rate

    def rhs(tt, s):
        return [s[1], (np.interp(tt, t, x) - s[0] - 2 * zeta * tau * s[1]) / (tau * tau)]

    sol = integrate.solve_ivp(rhs, (0.0, t[-1]), [x[0], 0.0], t_eval=t, method="DOP853",
                              rtol=1e-13, atol=1e-12 * np.ptp(x), max_step=1.0 / rate)  # fmt: skip
    got = run_section(foh_section([1.0], [tau * tau, 2 * zeta * tau, 1.0], rate), x)
    np.testing.assert_allclose(got, sol.y[0], rtol=0, atol=1e-12 * np.ptp(x))


def test_the_compiled_recursion_is_lfilter_and_columns_are_records(monkeypatch):
    assert accel.kernels() is not None
    rate, tau = 2000.0, 1.0 / (2 * np.pi * 90.0)
    sec = foh_section([1.0], [tau * tau, 0.3 * tau, 1.0], rate)
    x = record(4000, rate, seed=3)
    compiled = run_section(sec, x)
    with monkeypatch.context() as m:
        m.setattr(sections, "kernels", lambda: None)  # as without numba: scipy's lfilter
        fallback = run_section(sec, x)
    assert not np.array_equal(fallback, x)
    np.testing.assert_allclose(compiled, fallback, rtol=0, atol=1e-12 * np.ptp(x))
    both = run_section(sec, np.stack([x, -2.0 * x], axis=1))
    np.testing.assert_array_equal(both[:, 0], run_section(sec, x))
    np.testing.assert_array_equal(both[:, 1], run_section(sec, -2.0 * x))


@pytest.mark.parametrize("tau", [1e-30, 1e-43, 1e-100])
def test_a_section_settled_within_a_sample_passes_the_input_through(tau):
    """Poles decaying by e^(1e12) or more per sample (below that the matrix exponential is
    computed; it overflowed to NaN near 1e-43 s at 100 Hz)."""
    x = record(500, 100.0, seed=5)
    got = run_section(foh_section([1.0], [tau * tau, 2 * 0.7 * tau, 1.0], 100.0), x)
    np.testing.assert_allclose(got, x, rtol=0, atol=1e-12 * np.ptp(x))


def test_the_state_is_of_the_inputs_size_whatever_the_section():
    for tau in (1e-6, 1e-3, 0.02):
        sec = foh_section([1.0], [tau * tau, 2 * 0.7 * tau, 1.0], 10_000.0)
        assert 0.01 < np.max(np.abs(sec.rest_state(1.0))) < 10.0


def test_a_constant_input_stays_where_it_is():
    tau = 1e-3
    sec = foh_section([1.0], [tau * tau, 2 * 0.4 * tau, 1.0], 1000.0)
    np.testing.assert_allclose(run_section(sec, np.full(500, 73.0)), 73.0, rtol=1e-12)
    assert run_section(sec, np.array([])).size == 0


@pytest.mark.parametrize(
    ("num", "den"),
    [([1.0, 2.0, 3.0], [1.0, 1.0, 1.0]), ([1.0], [1.0, 1.0]), ([1.0], [0.0, 1.0, 1.0]),
     ([1.0], [1.0, 1.0, 0.0]), ([1.0], [1.0, 1.0, -1.0])],
)  # fmt: skip
def test_what_is_not_a_second_order_section_is_refused(num, den):
    with pytest.raises(ValueError, match="second-order section"):
        foh_section(num, den, 1000.0)


def test_the_library_filters_import_no_scipy_signal():
    """The low-pass, the resonance and the amplifier's fixed corner, in a fresh process."""
    code = """
import sys
import numpy as np
from labrig.model.effects import library
from labrig.model.effects.base import Context
x = np.linspace(0.0, 100.0, 400)
ctx = Context(2000.0, x, {})
p = {"sensor_lowpass": {"tau_s": 1e-3, "zeta": 0.7},
     "mechanical_resonance": {"tau_r_s": 2e-4, "zeta": 0.05, "internal": 0.5},
     "amplifier_bandwidth": {"tau_amp_s": 3e-4, "rise": 0.0}}
for name, q in p.items():
    assert np.all(np.isfinite(library()[name].apply(x, ctx, q)))
print("scipy.signal" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_the_amplifiers_fixed_corner_is_lfilter_at_rest():
    from scipy import signal  # here, not for every worker's collection

    from labrig.model.effects.amplifier_bandwidth import first_order_lowpass

    rate = 10_000.0
    x = record(3000, rate, seed=4)
    for tau in (2e-5, 1e-3, 5e-3):
        b, a = first_order_lowpass(tau, rate)
        want = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])[0]
        got = library()["amplifier_bandwidth"].apply(
            x, Context(rate, x, {}), {"tau_amp_s": tau, "rise": 0.0}
        )
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.ptp(x))
