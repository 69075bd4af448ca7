"""Records that begin at a held voltage (a biased drive, a capture that starts on a hold): the
model starts with the relaxors settled there and the operator brought there from rest at 0 V.

The independent reference is the model's own convention for a run: simulate the actuator from
rest at 0 V, ramped slowly to the held voltage and held long enough for the relaxors to settle,
then the record; its tail must equal the held-start prediction of the record alone."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.fit import predict_record
from labrig.analysis.records import Record
from labrig.model import DynamicHysteresisModel, ModelParams

RATE = 1000.0
#: relaxors that settle within the hold (a small lam_t would settle algebraically slowly) and
#: approach it monotonically (orders below 1: an overshoot would leave a minor loop in the
#: operator, which the held state, brought there monotonically, does not have)
FAST = ModelParams(
    alpha0_ue_per_V=8.9,
    gamma_ue_per_V=7.8,
    vc_V=65.0,
    lam_t=0.9,
    tau_t_s=1e-5,
    lam_d=0.7,
    tau_d_s=1e-6,
)


def _biased_record(v0: float, amp: float, f: float, seconds: float) -> np.ndarray:
    t = np.arange(round(seconds * RATE)) / RATE
    return v0 + amp * np.sin(2 * np.pi * f * t) * np.minimum(t / 1.0, 1.0)


@pytest.mark.parametrize("v0", [-60.0, 45.0])
def test_held_start_equals_a_long_hold_from_rest(v0: float) -> None:
    rec = _biased_record(v0, 20.0, 5.0, 3.0)
    ramp = v0 * 0.5 * (1 - np.cos(np.pi * np.arange(2000) / 2000))  # 2 s raised cosine
    hold = np.full(round(20 * RATE), v0)
    model = DynamicHysteresisModel(FAST)
    long = model.predict(np.concatenate([ramp, hold, rec]), RATE)[-rec.size :]
    held = model.predict(rec, RATE, rest_V=v0)
    # the relaxors' memory of the ramp after 20 s of hold: (tau / 20 s)^lam / Gamma(1 - lam) of
    # 60 V, about 2e-3 ue through the operator's slope
    np.testing.assert_allclose(held, long, atol=5e-3)
    # without the held start, the step from 0 V to v0 at t = 0 leaves a large transient
    from_zero = model.predict(rec, RATE)
    assert np.max(np.abs(from_zero - long)) > 1.0


def test_rest_voltage_of_a_record() -> None:
    held = Record.from_arrays("held", RATE, _biased_record(-90.0, 30.0, 20.0, 2.0), np.zeros(2000))
    assert held.rest_V == -90.0  # the envelope grows from zero: the record begins on a hold
    moving = 1.8 + 1.8 * np.sin(2 * np.pi * np.arange(2000) / 200)  # a sine started mid-swing
    assert Record.from_arrays("moving", 200.0, moving, np.zeros(2000)).rest_V == 0.0
    zero = Record.from_arrays(
        "zero", RATE, 50 * (1 - np.cos(np.arange(2000) / 100)), np.zeros(2000)
    )
    assert zero.rest_V == 0.0
    stated = Record.from_arrays("stated", 200.0, moving, np.zeros(2000), rest_V=1.8)
    assert stated.rest_V == 1.8  # the source says where the actuator rested


def test_fit_prediction_uses_the_held_start() -> None:
    v = _biased_record(-60.0, 20.0, 5.0, 3.0)
    rec = Record.from_arrays("r", RATE, v, np.zeros(v.size), hold="zoh")
    direct = DynamicHysteresisModel(FAST).predict(v, RATE, rest_V=-60.0)
    np.testing.assert_array_equal(predict_record(FAST, rec), direct)
