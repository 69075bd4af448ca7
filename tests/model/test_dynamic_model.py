"""Dynamic model ``S = alpha0 V* + H[V*]``, ``V* = G_t G_d V`` ().

Checks the paper's qualitative results with Table 1 (strain shift, loop size), the agreement of
the fast and exact realisations, block streaming, the wiring against an independent composition,
and the parameter presets and validation.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from labrig.model import (
    PAPER_CONTROL,
    PAPER_TABLE1,
    PAPER_TEXT,
    PRESETS,
    DynamicHysteresisModel,
    ModelParams,
    Relaxor,
)

from reference.hysteresis_ref import hysteresis_ref

RATE = 1e3


def _unipolar_1hz(seconds: float, rate: float = RATE) -> np.ndarray:
    t = np.arange(round(seconds * rate)) / rate
    return 50 * (1 - np.cos(2 * np.pi * t))  # 0-100 V, starting at 0 V


@pytest.fixture(scope="module")
def table1_run() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v = _unipolar_1hz(4.0)
    model = DynamicHysteresisModel(PAPER_TABLE1)
    return v, model.predict(v, RATE, method="fast"), model.predict(v, RATE, method="exact")


def test_strain_shift_at_zero_voltage(table1_run) -> None:
    # the paper's Fig. 10b: after the first cycle the strain at 0 V is positive (the transient
    # relaxor's slow response keeps V* above the drive), and it grows over the following cycles
    # as the long memory accumulates (G_t's step response is monotone for lam_t < 1)
    v, s, _ = table1_run
    at_zero = s[[1000, 2000, 3000]]  # t = 1, 2, 3 s, where V = 0
    assert np.all(v[[1000, 2000, 3000]] == pytest.approx(0.0, abs=1e-9))
    assert np.all(at_zero > 1.0)  # ue, well above rounding
    assert np.all(np.diff(at_zero) > 0)


def test_peak_strain_in_the_seeds_range(table1_run) -> None:
    # seed: 0-100 V loops of about 900-1300 ue on the P-888.51
    _, s, _ = table1_run
    for cycle in range(4):
        peak = s[cycle * 1000 : (cycle + 1) * 1000].max()
        assert 900.0 <= peak <= 1300.0
    assert s.min() >= -1e-9  # unipolar drive from rest: no negative strain


def test_fast_matches_exact(table1_run) -> None:
    # the relaxors' fast realisation is within 1e-5 of full scale (100 V -> 1e-3 V) of the exact
    # one; the operator's slope is at most alpha0 + gamma = 16.7 ue/V, so 0.02 ue bounds the strain
    _, fast, exact = table1_run
    assert np.max(np.abs(fast - exact)) <= 0.02


@pytest.mark.parametrize("params", [PAPER_TEXT, PAPER_CONTROL], ids=["text", "control"])
def test_fast_matches_exact_other_presets(params: ModelParams) -> None:
    v = _unipolar_1hz(2.0)
    model = DynamicHysteresisModel(params)
    fast = model.predict(v, RATE, method="fast")
    exact = model.predict(v, RATE, method="exact")
    assert np.max(np.abs(fast - exact)) <= 0.02


def test_matches_independent_composition() -> None:
    # spec Eq. 5-7: V* = G_d G_t V (G_t with the record's zoh, G_d with the linear hold since its
    # input is G_t's continuous output), then the quasi-static operator, here integrated by the
    # independent quadrature reference; 1e-9 of the strain scale
    v = _unipolar_1hz(0.6)
    p = PAPER_TABLE1
    vt = Relaxor(p.tau_t_s, p.lam_t).filter(v, RATE, method="exact", hold="zoh")
    vstar = Relaxor(p.tau_d_s, p.lam_d).filter(vt, RATE, method="exact", hold="linear")
    alpha0, gamma, vc = p.alpha0_ue_per_V, p.gamma_ue_per_V, p.vc_V
    want = hysteresis_ref(vstar, alpha0, lambda x: gamma * (1 - np.exp(-x / vc)))
    got = DynamicHysteresisModel(p).predict(v, RATE, method="exact")
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_strain_keeps_decreasing_after_the_voltage_vanishes() -> None:
    # section 4 (vanishing envelope): 1 Hz carrier fading to 0 over 5 s, then 0 V held; the
    # strain keeps decreasing while the voltage is zero (long memory), and stays positive
    t = np.arange(int(8 * RATE)) / RATE
    v = 50 * np.clip(1 - t / 5, 0, None) * (1 - np.cos(2 * np.pi * t))
    s = DynamicHysteresisModel(PAPER_TABLE1).predict(v, RATE)
    hold = s[int(5.1 * RATE) :]  # after G_d's ~50 ms transient
    assert np.all(np.diff(hold) < 0)
    assert hold[-1] > 0
    assert hold[0] - hold[-1] > 1.0  # ue: a visible drift, not rounding


@pytest.mark.parametrize("seed", range(5))
def test_stream_in_random_blocks_equals_predict(seed: int) -> None:
    v = _unipolar_1hz(3.0) + np.random.default_rng(100 + seed).normal(0, 2, 3000)
    model = DynamicHysteresisModel(PAPER_TABLE1)
    whole = model.predict(v, RATE, method="fast")
    rng = np.random.default_rng(seed)
    cuts = np.sort(rng.integers(0, v.size + 1, size=rng.integers(1, 60)))  # repeats: empty blocks
    if seed == 0:
        cuts = np.r_[cuts, np.arange(1, 40)]  # and a run of one-sample blocks
        cuts.sort()
    stream = model.stream(RATE)
    parts = [stream.process(b) for b in np.split(v, cuts)]
    # the same recursion regrouped: rounding only; 1e-9 ue
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=0, atol=1e-9)
    stream.reset()
    np.testing.assert_allclose(stream.process(v[:500]), whole[:500], rtol=0, atol=1e-9)


# -- parameters ---------------------------------------------------------------------------------


def test_preset_table1() -> None:
    p = PAPER_TABLE1
    assert (p.alpha0_ue_per_V, p.gamma_ue_per_V, p.vc_V) == (8.9, 7.8, 65.0)
    assert p.shape == "exponential"
    assert (p.lam_t, p.tau_t_s, p.lam_d, p.tau_d_s) == (0.15, 15.5e-5, 1.35, 2e-3)


def test_preset_text() -> None:
    # Table 1 with tau_t = 15.5e-6 s (tau_t^lam_t = 0.19 s^0.15 as the paper's text says)
    p = PAPER_TEXT
    assert p.tau_t_s == 15.5e-6
    assert p.tau_t_s**p.lam_t == pytest.approx(0.19, abs=0.005)
    same = {k: v for k, v in PAPER_TABLE1.model_dump().items() if k != "tau_t_s"}
    assert {k: v for k, v in p.model_dump().items() if k != "tau_t_s"} == same


def test_preset_control() -> None:
    # section 4: lam_t, tau_t, tau_d changed to 0.2, 32e-5 s, 2.2e-3 s (tau_t^lam_t = 0.2)
    p = PAPER_CONTROL
    assert (p.lam_t, p.tau_t_s, p.tau_d_s) == (0.2, 32e-5, 2.2e-3)
    assert p.tau_t_s**p.lam_t == pytest.approx(0.2, abs=0.005)
    changed = {"lam_t", "tau_t_s", "tau_d_s"}
    same = {k: v for k, v in PAPER_TABLE1.model_dump().items() if k not in changed}
    assert {k: v for k, v in p.model_dump().items() if k not in changed} == same


def test_presets_registry() -> None:
    assert PRESETS["PAPER_TABLE1"] == PAPER_TABLE1
    assert PRESETS["PAPER_TEXT"] == PAPER_TEXT
    assert PRESETS["PAPER_CONTROL"] == PAPER_CONTROL


def _kwargs(**over) -> dict:
    d = PAPER_TABLE1.model_dump()
    d.update(over)
    return d


@pytest.mark.parametrize("key", ["lam_t", "lam_d"])
@pytest.mark.parametrize("value", [0.0, -0.1, 2.0, 2.5])
def test_params_reject_order_outside_open_interval(key: str, value: float) -> None:
    with pytest.raises(ValidationError):
        ModelParams(**_kwargs(**{key: value}))


@pytest.mark.parametrize("key", ["tau_t_s", "tau_d_s"])
@pytest.mark.parametrize("value", [-1e-3, 0.0])
def test_params_reject_non_positive_time_constant(key: str, value: float) -> None:
    with pytest.raises(ValidationError):
        ModelParams(**_kwargs(**{key: value}))


def test_params_reject_extra_keys_and_are_frozen() -> None:
    with pytest.raises(ValidationError):
        ModelParams(**_kwargs(tau_x_s=1.0))
    with pytest.raises(ValidationError):
        ModelParams(**_kwargs(shape="cubic"))
    ModelParams(**_kwargs(lam_t=1.99, lam_d=0.01))  # inside the interval: accepted
    with pytest.raises(ValidationError):
        PAPER_TABLE1.lam_t = 0.3  # type: ignore[misc]
