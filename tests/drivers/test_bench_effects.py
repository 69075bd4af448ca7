"""The virtual bench's actuator effects (field saturation, a viscoelastic mode, a cubic term),
measured on an ideal bench whose truth is a plain linear actuator ``S = alpha0 u`` (the hybrid
plant with its hysteresis, Bouc-Wen part and Eq. 11 off), so what is measured is the effect."""

from __future__ import annotations

import math

import numpy as np
import pytest
from labrig.drivers.sim.effects import (
    DEFAULT_SATURATION_V,
    EFFECT_NAMES,
    CubicTerm,
    Effect,
    FieldSaturation,
    Retardation,
    ViscoelasticMode,
)
from pydantic import TypeAdapter, ValidationError
from scipy.optimize import curve_fit

from helpers import ALPHA0, linear_bench, strain

pytestmark = pytest.mark.timeout(60)


def triangle(peak_V: float, seconds: float, rate_hz: float) -> np.ndarray:
    """0 -> +peak -> -peak -> 0, slow and straight."""
    n = round(seconds * rate_hz / 4)
    up = np.linspace(0.0, peak_V, n + 1)
    return np.concatenate([up, up[::-1][1:], -up[1:], -up[::-1][1:]])


# --- field saturation -------------------------------------------------------------------------


def test_field_saturation_loses_five_percent_of_the_gain_at_150_V():
    """On a slow 150 V triangle: strain per volt at +-150 V is 5 % below the small-signal
    strain per volt (measured near 0 V), within 1 % of the stated 5 %; odd about 0 V."""
    v = triangle(150.0, 8.0, 1000.0)
    s = strain(linear_bench([{"name": "field_saturation"}]), v)
    small = np.abs(v) <= 5.0
    g0 = np.polyfit(v[small], s[small], 1)[0]  # the small-signal gain (ue/V)
    assert g0 == pytest.approx(ALPHA0, rel=1e-3)
    top, bottom = np.argmax(v), np.argmin(v)
    loss_top = 1 - s[top] / (g0 * v[top])
    loss_bottom = 1 - s[bottom] / (g0 * v[bottom])
    assert loss_top == pytest.approx(0.05, rel=0.01)
    assert loss_bottom == pytest.approx(loss_top, rel=1e-6)  # odd about 0 V
    # the local slope falls too: less strain per volt near both ends than near 0 V
    ends = (np.abs(v) > 140) & (np.arange(v.size) < top)
    assert np.polyfit(v[ends], s[ends], 1)[0] < 0.9 * g0


def test_field_saturation_is_not_a_polynomial_of_the_strain():
    """The deficit at 150 V is not 8 times the one at 75 V (a cubic softening's would be), nor
    the deficit at 75 V 8 times the one at 37.5 V: tanh differs from a cubic at high field."""
    v = np.array([0.0, 37.5, 75.0, 150.0])
    s = strain(linear_bench([{"name": "field_saturation", "saturation_V": 150.0}]), v)
    deficit = ALPHA0 * v[1:] - s[1:]
    assert deficit[2] / deficit[1] < 0.9 * 8  # 150 V vs 75 V: tanh saturates faster than x^3
    x = v[1:] / 150.0
    assert s[1:] == pytest.approx(ALPHA0 * 150.0 * np.tanh(x), rel=1e-9)


def test_the_default_saturation_voltage_gives_the_stated_loss():
    assert DEFAULT_SATURATION_V * math.tanh(150 / DEFAULT_SATURATION_V) / 150 == pytest.approx(
        0.95, abs=1e-4
    )
    assert FieldSaturation(name="field_saturation").saturation_V == DEFAULT_SATURATION_V


# --- viscoelastic mode ------------------------------------------------------------------------


def step_response(effect: dict, rate_hz: float = 1000.0, seconds: float = 3.0):
    bench = linear_bench([effect], rate_hz)
    v = np.full(round(seconds * rate_hz), 100.0)
    t = (np.arange(v.size) + 0.5) / rate_hz  # the drive of interval n is its mean over it
    return t, strain(bench, v) / (ALPHA0 * 100.0)


def test_viscoelastic_mode_step_response_fraction_and_time_constant():
    """A 100 V step: the strain jumps to (1 - c) of its final value and creeps up the rest
    with time constant tau; fitted (curve_fit) c within 1 % and tau within 2 % of 6 %, 0.3 s."""
    t, y = step_response({"name": "viscoelastic_mode"})
    (c, tau, final), _ = curve_fit(
        lambda t, c, tau, final: final * (1 - c * np.exp(-t / tau)), t, y, p0=(0.1, 0.1, 1.0)
    )
    assert c == pytest.approx(0.06, rel=0.01)
    assert tau == pytest.approx(0.3, rel=0.02)
    assert final == pytest.approx(1.0, rel=1e-4)
    assert y[0] == pytest.approx(0.94, abs=1e-3)  # the elastic part, at once
    # after one time constant, 1 - c/e of the final strain
    assert np.interp(0.3, t, y) == pytest.approx(1 - 0.06 / math.e, abs=2e-4)


def test_two_viscoelastic_modes_add():
    t, y = step_response(
        {
            "name": "viscoelastic_mode",
            "fraction": 0.04,
            "tau_s": 0.1,
            "second_fraction": 0.03,
            "second_tau_s": 1.0,
        },
        seconds=8.0,
    )
    late = t > 0.8  # the fast mode is gone (e^-8): only the slow one is left
    slope, _ = np.polyfit(t[late], np.log(1 - y[late]), 1)
    assert -1 / slope == pytest.approx(1.0, rel=0.02)
    assert 1 - y[0] == pytest.approx(0.07, abs=1e-3)


def test_retardation_does_not_depend_on_the_block_size():
    cfg = ViscoelasticMode(name="viscoelastic_mode")
    v = np.sin(np.arange(3000) / 50.0) * 80
    whole = Retardation(cfg, 1000.0).process(v)
    r = Retardation(cfg, 1000.0)
    parts = np.concatenate([r.process(b) for b in np.array_split(v, 7)])
    assert np.max(np.abs(whole - parts)) < 1e-12


def test_the_viscoelastic_fractions_must_leave_an_elastic_part():
    with pytest.raises(ValidationError, match="below 1"):
        ViscoelasticMode(name="viscoelastic_mode", fraction=0.6, second_fraction=0.4)


# --- cubic term -------------------------------------------------------------------------------


def test_cubic_term_is_positive_odd_and_follows_the_held_voltage():
    """``+c3 (v/V_ref)^3``: at +V_ref the strain is c3 above the linear truth, at -V_ref c3
    below (the gain rises with field on both sides), from the voltage held before the sample."""
    cfg = {"name": "cubic_term", "c3_ue": 20.0, "v_ref_V": 100.0}
    v = np.array([0.0, 100.0, 100.0, -100.0, -100.0, 50.0, 50.0])
    extra = strain(linear_bench([cfg]), v) - ALPHA0 * v
    # sample n carries the voltage of interval n - 1 (the bench starts at 0 V)
    assert extra == pytest.approx([0.0, 0.0, 20.0, 20.0, -20.0, -20.0, 2.5], abs=1e-9)
    assert CubicTerm(name="cubic_term").c3_ue > 0  # hardening by default


# --- rig files --------------------------------------------------------------------------------


def test_every_effect_name_is_accepted_in_a_rig_file():
    adapter = TypeAdapter(Effect)
    assert [adapter.validate_python({"name": n}).name for n in EFFECT_NAMES] == list(EFFECT_NAMES)
    for bad in ({"name": "field_saturation", "saturation_V": -1.0}, {"name": "cubic_terms"}):
        with pytest.raises(ValidationError):
            adapter.validate_python(bad)


def test_no_effect_no_change():
    """The actuator effects off, the bench is the linear truth itself."""
    v = triangle(150.0, 2.0, 1000.0)
    s = strain(linear_bench([]), v)
    assert np.max(np.abs(s - ALPHA0 * v)) < 1e-9 * ALPHA0 * 150
