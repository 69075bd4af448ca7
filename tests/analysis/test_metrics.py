"""Metrics against closed forms: NRMSE of known signals, ellipse loop area, strain shift, width."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.metrics import (
    compare,
    drive_frequency_hz,
    estimate_frequency_hz,
    hysteresis_width,
    is_periodic,
    last_period,
    loop_area,
    max_error,
    mean_nrmse_pct,
    nrmse_pct,
    second_half_nrmse_pct,
    strain_at_zero_voltage,
)
from labrig.analysis.records import Record

RATE = 1000.0


def _t(n: int) -> np.ndarray:
    return np.arange(n) / RATE


def test_nrmse_of_an_offset_and_of_a_scaled_sine() -> None:
    t = _t(2000)
    m = 50.0 * np.sin(2 * np.pi * 2 * t)  # span 100 (sampled at the peaks)
    span = m.max() - m.min()
    # constant error c: RMS = c
    assert nrmse_pct(m, m + 3.0) == pytest.approx(100 * 3.0 / span, rel=1e-12)
    # scaled sine: error 0.1 m, RMS of a full-period sine = amplitude / sqrt 2
    assert nrmse_pct(m, 0.9 * m) == pytest.approx(100 * 5.0 / np.sqrt(2) / span, rel=1e-9)
    assert nrmse_pct(m, m) == 0.0
    assert max_error(m, m + np.where(t > 1, 7.0, -2.0)) == pytest.approx(7.0, rel=1e-12)
    assert mean_nrmse_pct({"a": 1.0, "b": 3.0}) == 2.0
    assert mean_nrmse_pct([1.0, 2.0, 6.0]) == 3.0
    with pytest.raises(ValueError):
        nrmse_pct(np.ones(5), np.zeros(5))
    with pytest.raises(ValueError):
        nrmse_pct(np.ones(5), np.zeros(4))


def test_second_half_score_is_in_percent_of_the_whole_entrys_span() -> None:
    """A vanishing entry: a 0-1000 ue swing, then a quiet tail (a 5 ue span). A constant 2 ue
    error on the tail is 0.2 % of the entry's span (it was scored 40 %, against the tail's own
    span); on a steady sine the two normalisers agree."""
    t = _t(4000)
    m = np.where(t < 2.0, 500.0 * (1 - np.cos(2 * np.pi * t)), 5.0 * (t - 2.0) / 2.0)
    assert np.ptp(m) == pytest.approx(1000.0, rel=1e-6) and np.ptp(m[2000:]) < 5.0
    assert second_half_nrmse_pct(m, m + 2.0) == pytest.approx(100 * 2.0 / np.ptp(m), rel=1e-12)
    assert nrmse_pct(m[2000:], m[2000:] + 2.0) > 40.0
    sine = 50.0 * np.sin(2 * np.pi * 2 * t)
    assert second_half_nrmse_pct(sine, 0.9 * sine) == pytest.approx(
        nrmse_pct(sine[2000:], 0.9 * sine[2000:]), rel=1e-9
    )


@pytest.mark.parametrize("phi_deg", [5.0, 30.0, 90.0, -20.0])
def test_loop_area_of_an_ellipse(phi_deg: float) -> None:
    a, b, f = 40.0, 300.0, 2.0
    phi = np.deg2rad(phi_deg)
    t = _t(2000)  # 4 periods of 500 samples
    v = a * np.cos(2 * np.pi * f * t)
    s = b * np.cos(2 * np.pi * f * t - phi)  # strain lagging the voltage: positive area
    expected = np.pi * a * b * np.sin(phi)
    # polygon of 500 vertices: relative error ~ (2 pi / 500)^2 / 6
    assert loop_area(v, s, RATE, f) == pytest.approx(expected, rel=1e-4)
    # frequency estimated from the voltage gives the same period
    assert loop_area(v, s, RATE) == pytest.approx(expected, rel=1e-4)
    # width at equal voltage: at V = 0 the branches are b sin(phi) and -b sin(phi)
    assert hysteresis_width(v, s, RATE, f) == pytest.approx(2 * b * np.sin(phi), rel=1e-3)


def test_loop_area_uses_only_the_last_period() -> None:
    t = _t(3000)
    v = 50 * (1 - np.cos(2 * np.pi * t))  # 3 periods of a unipolar 1 Hz sine
    grow = np.where(t < 2.0, 0.0, 1.0)  # the loop opens only in the last period
    s = 10 * v - grow * 100 * np.sin(2 * np.pi * t)
    # V - 50 = 50 cos(wt - 180 deg), S_hyst = -100 sin(wt) = 100 cos(wt - 270 deg): the strain
    # lags by 90 deg -> ellipse area pi 50 100
    assert loop_area(v, s, RATE, 1.0) == pytest.approx(np.pi * 50 * 100, rel=1e-4)
    assert last_period(3000, RATE, 1.0) == slice(2000, 3000)


def test_strain_at_zero_voltage_unipolar_and_bipolar() -> None:
    t = _t(3000)
    v = 50 * (1 - np.cos(2 * np.pi * t))  # touches 0 V once per period
    shift = 40.0 - 10.0 * t  # drifting strain shift
    s = 12.0 * v + shift
    # last period: 0 V at t = 2.0 s (the window start)
    assert strain_at_zero_voltage(v, s, RATE, 1.0) == pytest.approx(20.0, abs=0.1)
    # bipolar: two crossings, the mean of the strain there (linear interpolation is exact here)
    vb = 30 * np.sin(2 * np.pi * t + 0.3)
    sb = 5.0 * vb + 17.0 + 8.0 * np.cos(2 * np.pi * t + 0.3)  # +8 rising, -8 falling at 0 V
    assert strain_at_zero_voltage(vb, sb, RATE, 1.0) == pytest.approx(17.0, abs=1e-3)


def test_frequency_estimate_and_periodicity() -> None:
    t = _t(5000)
    v = 50 * (1 - np.cos(2 * np.pi * 7.0 * t))
    assert estimate_frequency_hz(v, RATE) == pytest.approx(7.0, rel=2e-3)
    assert is_periodic(v, RATE, 7.0)
    env = np.clip(1 - t / 3, 0, None) * v  # vanishing envelope then 0 V: not periodic
    assert not is_periodic(env, RATE, 7.0)
    assert estimate_frequency_hz(np.zeros(100), RATE) is None
    rec = Record.from_arrays("x", RATE, v, v, frequency_hz=7.0)
    assert drive_frequency_hz(rec) == 7.0
    rec2 = Record.from_arrays("y", RATE, v, v)
    assert drive_frequency_hz(rec2) == pytest.approx(7.0, rel=2e-3)


def test_compare_gives_every_metric() -> None:
    t = _t(3000)
    v = 50 * (1 - np.cos(2 * np.pi * t))
    meas = 10 * v - 30 * np.sin(2 * np.pi * t)  # lagging by 90 deg (see above)
    pred = 10 * v - 20 * np.sin(2 * np.pi * t)
    rec = Record.from_arrays("sine", RATE, v, meas, frequency_hz=1.0)
    out = compare(rec, pred)
    assert out["nrmse_pct"] == pytest.approx(nrmse_pct(meas, pred))
    assert out["max_error_ue"] == pytest.approx(10.0, rel=1e-6)
    assert out["loop_area_Vue"] == pytest.approx(np.pi * 50 * 30, rel=1e-4)
    assert out["loop_area_error_pct"] == pytest.approx(-100 / 3, rel=1e-3)
    assert out["strain_shift_error_ue"] == pytest.approx(0.0, abs=0.5)
    assert out["hysteresis_width_ue"] == pytest.approx(60.0, rel=1e-3)
    # a record that is not periodic has no loop metrics
    env = Record.from_arrays("env", RATE, np.clip(1 - t / 2, 0, None) * v, meas)
    out = compare(env, pred)
    assert out["loop_area_Vue"] is None and out["nrmse_pct"] > 0
