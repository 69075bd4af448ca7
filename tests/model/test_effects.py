"""The effect library (labrig.model.effects): null values, forms, bounds; the frozen-reversal
tangent of the diagnosis engine."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.model.effects import (
    EFFECT_NAMES,
    AmplifierCurrentLimit,
    Context,
    Creep,
    MainsPickup,
    OffsetDrift,
    SensorLowpass,
    ThermalDrift,
    TimeDelay,
    library,
    measured_voltage,
    slew_limit,
)

FS = 1000.0


def _ctx(v, **kw):
    return Context(FS, np.asarray(v, float), {"e": slice(0, len(v))}, **kw)


def _sine(f=10.0, a=100.0, n=3000):
    t = np.arange(n) / FS
    return 0.5 * a * (1 - np.cos(2 * np.pi * f * t))


def test_required_names_and_metadata():
    for name in (
        "thermal_drift",
        "amplifier_current_limit",
        "sensor_lowpass",
        "mains_pickup",
        "offset_drift",
        "creep",
    ):
        assert name in EFFECT_NAMES
    lib = library(temperature=True, amplifier_voltage=True)
    for e in lib.values():
        assert e.where in ("voltage", "operator", "output", "nuisance")
        assert e.physics and e.signature and e.__doc__
        for q in e.params:
            assert q.lo <= q.null <= q.hi or q.log
            assert q.lo <= q.init <= q.hi


@pytest.mark.parametrize("temperature", [True, False])
def test_output_and_voltage_effects_vanish_at_null(temperature):
    v = _sine()
    T = 23 + np.linspace(0, 5, v.size)
    ctx = _ctx(v, amplifier_voltage=v.copy(), temperature=T)
    x = 9.0 * v + 3.0
    for e in library(temperature=temperature, amplifier_voltage=False).values():
        if e.where == "nuisance" or not e.params:
            continue
        if e.where == "operator":  # an added strain term: zero at the null
            np.testing.assert_array_equal(e.apply(v, ctx, e.null), np.zeros(v.size))
            continue
        y = e.apply(v if e.where == "voltage" else x, ctx, e.null)
        np.testing.assert_allclose(y, v if e.where == "voltage" else x, atol=1e-12)


def test_sensor_lowpass_gain_and_phase():
    e = SensorLowpass()
    fc = 100.0
    tau = 1 / (2 * np.pi * fc)
    for f, zeta in ((fc, 1 / np.sqrt(2)), (20.0, 0.7)):
        t = np.arange(20000) / FS
        x = np.sin(2 * np.pi * f * t)
        y = e.apply(x, _ctx(x), {"tau_s": tau, "zeta": zeta})[-5000:]
        c = 2 / y.size * np.sum(y * np.exp(-2j * np.pi * f * t[-5000:]))
        c0 = 2 / y.size * np.sum(x[-5000:] * np.exp(-2j * np.pi * f * t[-5000:]))
        h = 1 / (1 - (f / fc) ** 2 + 2j * zeta * f / fc)
        # exact for the input linear between samples: the sampled sine's interpolation has
        # the first-order-hold gain sinc^2(f / fs) at f
        foh = np.sinc(f / FS) ** 2
        assert c / c0 == pytest.approx(h * foh, rel=2e-3)
    # DC gain 1, starts in steady state
    np.testing.assert_allclose(
        e.apply(np.full(100, 5.0), _ctx(np.ones(100)), {"tau_s": tau, "zeta": 0.7}), 5.0
    )
    assert e.physical({"tau_s": tau, "zeta": 0.7})["fc_hz"] == pytest.approx(fc)


def test_time_delay_integer_and_fractional():
    e = TimeDelay()
    x = np.arange(10.0)
    np.testing.assert_allclose(
        e.apply(x, _ctx(x), {"delay_s": 2e-3}), [0, 0, 0, 1, 2, 3, 4, 5, 6, 7]
    )
    np.testing.assert_allclose(e.apply(x, _ctx(x), {"delay_s": 0.5e-3})[1:], x[1:] - 0.5)


def test_slew_limit():
    v = _sine(40.0, 100.0, 500)
    top = 3e3  # V/s
    y = slew_limit(v, top, FS)
    assert np.max(np.abs(np.diff(y, prepend=0.0))) <= top / FS + 1e-12
    assert np.ptp(y) < np.ptp(v)
    assert slew_limit(v, 1e9, FS) is v
    e = AmplifierCurrentLimit(amplifier_voltage=False)
    assert e.physical({"inv_slew_ms_per_V": 0.5})["slew_V_per_ms"] == pytest.approx(2.0)


def test_measured_voltage_ignores_monitor_noise():
    rng = np.random.default_rng(0)
    v = _sine(10.0, 100.0, 2000)
    noisy = v + 0.01 * rng.standard_normal(v.size)
    np.testing.assert_array_equal(measured_voltage(_ctx(v, amplifier_voltage=noisy)), v)
    limited = slew_limit(v, 2e3, FS) + 0.01 * rng.standard_normal(v.size)
    m = measured_voltage(_ctx(v, amplifier_voltage=limited))
    big = np.abs(limited - v) > 1.0
    np.testing.assert_array_equal(m[big], limited[big])


@pytest.mark.parametrize("t0", [0.002, 0.05])
def test_creep_is_logarithmic_after_a_step(t0):
    e = Creep()
    n = 60000
    x = np.ones(n)
    y = e.apply(x, _ctx(np.zeros(n)), {"c_per_decade": 0.02, "t0_s": t0})
    # one decade later the strain has grown by c (for t >> t0), the same for every decade
    i1, i5, i10, i50 = (round(tt * FS) for tt in (1.0, 5.0, 10.0, 50.0))
    assert y[i10] - y[i1] == pytest.approx(0.02, rel=0.03)
    assert y[i50] - y[i5] == pytest.approx(0.02, rel=0.01)
    # linear in the strain change: a step back down at 10 s recovers, leaving the creep of a
    # 10 s pulse, which fades: at 50 s, c log10(50 / 40) for t >> t0
    down = np.where(np.arange(n) < i10, 1.0, 0.0)
    z = e.apply(down, _ctx(np.zeros(n)), {"c_per_decade": 0.02, "t0_s": t0})
    assert z[i50] == pytest.approx(0.02 * np.log10(50.0 / 40.0), rel=0.01)
    assert np.all(np.diff(z[i10 + 1 :]) < 0)


def test_creep_over_too_few_decades_is_a_caveat():
    """Two decades of log creep between t0 and the data's span, or a caveat (one slow mode
    would do as well)."""
    e = Creep()
    assert e.caveats({"c_per_decade": 0.04, "t0_s": 0.002}, 20.0) == []  # 4 decades
    (said,) = e.caveats({"c_per_decade": 0.04, "t0_s": 0.3}, 20.0)  # 1.8 decades
    assert "1.8 decades" in said and "viscoelastic_creep" in said
    assert e.caveats({"c_per_decade": 0.0, "t0_s": 0.3}, 20.0) == []  # no creep, no caveat
    (said,) = e.caveats({"c_per_decade": 0.04, "t0_s": 5.0}, 3.0)  # t0 beyond the data
    assert "less than a decade" in said


def test_thermal_drift_with_and_without_temperature():
    v = _sine(40.0, 100.0, 4000)
    T = 23 + np.linspace(0, 4, v.size)
    x = np.full(v.size, 100.0)
    e = ThermalDrift(temperature=True)
    y = e.apply(x, _ctx(v, temperature=T), {"k_per_K": 0.002})
    assert y[-1] == pytest.approx(100 * (1 + 0.002 * 4))
    e2 = ThermalDrift(temperature=False)
    y2 = e2.apply(x, _ctx(v), {"k_rel": 0.05, "tau_th_s": 1.0})
    assert y2[0] == pytest.approx(100.0)
    assert y2[-1] == pytest.approx(105.0, rel=2e-3)  # steady state of the hottest entry
    assert np.all(np.diff(y2) >= -1e-12)


def test_nuisance_columns():
    t = np.arange(1000) / FS
    C = MainsPickup(50.0).columns(t, FS)
    assert C.shape == (1000, 6)
    assert OffsetDrift().columns(t, FS).shape == (1000, 2)
    assert MainsPickup(60.0).columns(t, 100.0).shape[1] == 0  # above Nyquist: nothing


def test_viscoelastic_creep_step_response_is_one_kelvin_voigt_element():
    """Independent reference: a unit step through ``(1 - c) + c / (1 + tau s)`` relaxes as
    ``1 - c exp(-t / tau)`` (continuous time); the sampled lag reaches sample ``n`` at
    ``t = (n + 1) / rate`` (its state is updated with ``x[n]`` before it is read)."""
    from labrig.model.effects import ViscoelasticCreep

    eff = library()["viscoelastic_creep"]
    assert isinstance(eff, ViscoelasticCreep) and eff.where == "output"
    c, tau = 0.08, 0.25
    x = np.ones(3000)
    y = eff.apply(x, _ctx(x), {"c": c, "tau_s": tau})
    t = (np.arange(x.size) + 1) / FS
    assert np.max(np.abs(y - (1 - c * np.exp(-t / tau)))) < 1e-12
    # DC gain 1 and linearity; the null leaves the strain alone
    s = _sine(2.0, 100.0, 5000)
    assert np.allclose(eff.apply(3 * s, _ctx(s), {"c": c, "tau_s": tau}),
                       3 * eff.apply(s, _ctx(s), {"c": c, "tau_s": tau}))  # fmt: skip
    assert np.array_equal(eff.apply(s, _ctx(s), {"c": 0.0, "tau_s": tau}), s)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize(("c", "tau_s"), [(0.5, 30.0), (-0.3, 30.0), (-0.3, 3.0)])
def test_viscoelastic_creep_keeps_its_digits_for_a_slow_lag(
    c: float, tau_s: float, engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The slowest lag the fit allows (tau 30 s) at 10 kHz leaves ``1 - A = 3.3e-6``: a unit
    step over 10 s (1e5 samples) against the closed form ``1 - c exp(-t/tau)`` within 5e-13
    (the same filter's ``lfilter(b, a)`` form is off by up to 2e-11 here: its numerator
    ``1 - c A - (1 - c) A`` is a difference of numbers near 1), on either engine."""
    import labrig.model.modal as modal
    from labrig.model.accel import kernels

    if engine == "compiled" and kernels() is None:
        pytest.skip("numba is not installed")
    monkeypatch.setattr(modal, "stream_engine", lambda: engine)
    rate, n = 1e4, 100_000
    x = np.ones(n)
    ctx = Context(rate, x, {"e": slice(0, n)})
    y = library()["viscoelastic_creep"].apply(x, ctx, {"c": c, "tau_s": tau_s})
    t = (np.arange(n) + 1) / rate
    assert np.max(np.abs(y - (1 - c * np.exp(-t / tau_s)))) < 5e-13


def test_kelvin_voigt_filter_inverse_is_stable_and_exact():
    from scipy import signal

    from labrig.model.effects import kelvin_voigt_filter

    for c in (-0.2, 0.05, 0.3, 0.9):
        b, a = kelvin_voigt_filter(c, 0.1, FS)
        assert np.all(np.abs(np.roots(b)) < 1.0)  # the inverse's pole
        x = np.random.default_rng(1).standard_normal(2000).cumsum()
        back = signal.lfilter(a, b, signal.lfilter(b, a, x))
        assert np.max(np.abs(back - x)) < 1e-9 * np.max(np.abs(x))


def test_field_saturation_is_odd_monotone_and_loses_s_at_full_scale():
    """The library's field saturation ``V (1 - s (V/V_ref)^2)``: odd about 0 V (a bipolar drive
    loses gain at both ends), the small-signal gain kept, the slope at full scale
    ``1 - 3 s`` (checked by a finite difference), monotone for the largest allowed ``s``."""
    eff = library(v_ref=150.0)["field_saturation"]
    assert "field_saturation" in EFFECT_NAMES
    v = np.linspace(-150.0, 150.0, 3001)
    ctx = _ctx(v)
    y = eff.apply(v, ctx, {"s": 0.05})
    np.testing.assert_allclose(y, -y[::-1], atol=1e-12)  # odd
    assert y[-1] == pytest.approx(150.0 * 0.95, rel=1e-12)  # 5 % less at full scale
    slope_end = (y[-1] - y[-2]) / (v[-1] - v[-2])
    slope_mid = (y[1501] - y[1499]) / (v[1501] - v[1499])
    assert slope_mid == pytest.approx(1.0, abs=1e-6)
    assert slope_end == pytest.approx(1 - 3 * 0.05, abs=2e-3)
    top = eff.params[0].hi
    assert np.all(np.diff(eff.apply(v, ctx, {"s": top})) > 0)
    np.testing.assert_array_equal(eff.apply(v, ctx, {"s": 0.0}), v)


def test_thermal_drift_compares_entries_against_one_campaign_reference():
    """Unchained entries held at different temperatures (an oven series: each entry isothermal)
    show a gain difference only against a common reference: every sequence of a campaign gets
    the first record's first temperature (labrig.analysis.simulate.build_sequences)."""
    from labrig.analysis.records import Record
    from labrig.analysis.simulate import build_sequences

    v = _sine(1.0, 100.0, 2000)
    recs = [
        Record("cool", FS, None, v, 10 * v, {"temperature": np.full(v.size, 25.0)}),
        Record("hot", FS, None, v, 10 * v, {"temperature": np.full(v.size, 45.0)}),
    ]
    seqs = build_sequences(recs, chain=False)
    assert [s.context.temperature_ref for s in seqs] == [25.0, 25.0]
    eff = library(temperature=True)["thermal_drift"]
    x = 10 * v
    cool, hot = (eff.apply(x, s.context, {"k_per_K": 0.005}) for s in seqs)
    np.testing.assert_allclose(cool, x)
    np.testing.assert_allclose(hot, x * (1 + 0.005 * 20.0))


def _creep_reference(x, t0, c):
    """``x + c (k * dx)`` by direct convolution (numpy), ``k = log10(1 + t / t0)``."""
    k = np.log10(1.0 + (np.arange(x.size) / FS) / t0)
    return x + c * np.convolve(np.diff(x, prepend=0.0), k)[: x.size]


def test_creep_columns_and_derivatives_match_a_direct_convolution_and_differences():
    """The creep's strain, tangent columns and parameter derivatives (FFT convolutions, the
    last strain's steps kept on the context) against a direct convolution and central
    differences; a strain changed in place after a call is transformed anew."""
    e = Creep()
    rng = np.random.default_rng(3)
    n = 2000
    ctx = _ctx(np.zeros(n))
    x = np.cumsum(rng.standard_normal(n))
    p = {"c_per_decade": 0.03, "t0_s": 0.01}
    y = e.apply(x, ctx, p)
    np.testing.assert_allclose(y, _creep_reference(x, 0.01, 0.03), rtol=0, atol=1e-10)
    cols = rng.standard_normal((n, 3))
    tc = e.tangent_columns(x, cols, ctx, p)
    for i in range(3):
        ref = _creep_reference(cols[:, i], 0.01, 0.03)
        np.testing.assert_allclose(tc[:, i], ref, rtol=0, atol=1e-10)
    d = e.parameter_derivatives(x, ctx, p)
    h = 1e-6
    dc = (_creep_reference(x, 0.01, 0.03 + h) - _creep_reference(x, 0.01, 0.03 - h)) / (2 * h)
    np.testing.assert_allclose(d["c_per_decade"], dc, rtol=1e-6, atol=1e-8)
    ht = 1e-7
    dt0 = (_creep_reference(x, 0.01 + ht, 0.03) - _creep_reference(x, 0.01 - ht, 0.03)) / (2 * ht)
    np.testing.assert_allclose(d["t0_s"], dt0, rtol=1e-5, atol=1e-6 * np.max(np.abs(dt0)))
    # the same array changed in place: not the kept steps
    x[n // 2 :] += 5.0
    d2 = e.parameter_derivatives(x, ctx, p)
    np.testing.assert_allclose(d2["c_per_decade"], (_creep_reference(x, 0.01, 0.03) - x) / 0.03,
                               rtol=0, atol=1e-9)  # fmt: skip
    assert not np.allclose(d2["c_per_decade"], d["c_per_decade"])
