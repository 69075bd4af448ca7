"""Compensation control: the inverse model, the per-sample controller, limits and metrics."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from labrig.control import (
    CompensationController,
    DirectController,
    InfeasibleCommandError,
    check_drive,
    command_metrics,
    compensated_drive,
    compute_drive,
    direct_drive,
    final_strain_ue,
    hysteresis_width_pct,
    load_params,
    model_tracking_error,
    outside_zeros,
    tracking_nrmse_pct,
    zero_command_strain_ue,
)
from labrig.control.inversion import relaxor_inverse
from labrig.control.static_inverse import StaticInverseStepper
from labrig.model import PAPER_CONTROL, DynamicHysteresisModel, QuasiStaticHysteresis
from labrig.model.relaxor import sampled_kernel
from labrig.rig.limits import RigLimits

ROOT = Path(__file__).resolve().parents[2]
FITTED = load_params(ROOT / "experiments" / "hybrid-params.json")
RATE = 1000.0


def strain_sine(amplitude_ue: float, f_hz: float, cycles: float, rate: float = RATE):
    n = round(cycles * rate / f_hz) + 1
    t = np.arange(n) / rate
    return 0.5 * amplitude_ue * (1.0 - np.cos(2 * np.pi * f_hz * t))


def vanishing(amplitude_ue: float = 800.0, f_hz: float = 2.0, rate: float = RATE):
    t = np.arange(round(4.0 * rate) + 1) / rate
    env = np.where(t < 0.25, 1.0, np.exp(-(t - 0.25) / 0.8))
    return env * 0.5 * amplitude_ue * (1.0 - np.cos(2 * np.pi * f_hz * t))


# -- the offline inverse ---------------------------------------------------------------------


@pytest.mark.parametrize("params", [FITTED, PAPER_CONTROL], ids=["fitted", "paper_control"])
@pytest.mark.parametrize("f_hz", [1.0, 10.0, 40.0])
def test_compensated_drive_inverts_the_model(params, f_hz):
    s = strain_sine(1000.0, f_hz, max(3, 2 * f_hz))
    v = compensated_drive(s, params, RATE)
    model = DynamicHysteresisModel(params)
    for method, tol in (("exact", 1e-6), ("fast", 1e-6)):
        err = model.predict(v, RATE, method=method) - s
        # a start-up transient of a few samples (the anti-causal zero of G_d), then exact
        assert np.max(np.abs(err[100:])) < tol * 1000.0
        assert np.max(np.abs(err)) < 3e-3 * 1000.0
        # (where there is a visible transient at all: below 1e-9 of the span it is rounding)
        assert np.argmax(np.abs(err)) <= 3 or np.max(np.abs(err)) < 1e-9 * 1000.0


def test_model_tracking_error_and_minor_loops():
    s = vanishing()
    err = model_tracking_error(s, FITTED, RATE)
    assert np.max(np.abs(err[50:])) < 1e-4  # ue
    # reversals inside the command (minor loops) are inverted exactly too
    # (after a smooth start: a reversal inside the start-up transient would keep its error in
    # the hysteresis memory, see the module docstring)
    rng = np.random.default_rng(3)
    rise = 200.0 * (1 - np.cos(np.pi * np.arange(200) / 200)) / 2
    walk = np.abs(rise[-1] + np.cumsum(rng.normal(0.0, 4.0, 3000)))
    walk = np.concatenate((rise, walk))  # a rough command with many reversals
    err = model_tracking_error(walk, FITTED, RATE, method="exact")
    assert np.max(np.abs(err[100:])) < 1e-6 * np.ptp(walk)


def test_outside_zeros_of_the_sampled_relaxors():
    # G_d (lam > 1) under the linear hold: one negative real zero outside the unit circle,
    # equal to the zero of the exact kernel
    (z,) = outside_zeros(PAPER_CONTROL.tau_d_s, PAPER_CONTROL.lam_d, RATE, "linear")
    assert z.imag == 0 and -2.0 < z.real < -1.0
    k = sampled_kernel(PAPER_CONTROL.tau_d_s, PAPER_CONTROL.lam_d, 1 / RATE, 400, "linear")
    assert abs(np.sum(k * z.real ** -np.arange(400.0))) < 1e-9
    # G_t (lam < 1, zero-order hold shifted by its delay) and G_d with lam < 1: none
    assert outside_zeros(FITTED.tau_t_s, FITTED.lam_t, RATE, "zoh") == []
    assert outside_zeros(2e-3, 0.8, RATE, "linear") == []


def stepped(st: StaticInverseStepper, s: np.ndarray) -> tuple[np.ndarray, int]:
    """The stepper's voltages along ``s`` and the most turning points it remembered at once."""
    got, depth = [], 0
    for x in s:
        got.append(st.step(x))
        depth = max(depth, len(st.stack))
    return np.array(got), depth


def test_static_inverse_stepper_matches_invert():
    op = QuasiStaticHysteresis(
        FITTED.alpha0_ue_per_V, FITTED.gamma_ue_per_V, FITTED.vc_V, FITTED.shape
    )
    rng = np.random.default_rng(0)
    s = np.concatenate(([0.0, 0.0], np.cumsum(rng.normal(0.0, 20.0, 2000))))
    s[100:110] = s[99]  # flat stretch: not a reversal
    got, depth = stepped(StaticInverseStepper(op), s)
    assert np.max(np.abs(got - op.invert(s))) < 1e-9
    # and for a shape without a closed form here (a numerical inverse at each sample): the
    # walk's first 700 samples, with the flat stretch, both signs and as deep a memory
    opg = QuasiStaticHysteresis(11.0, 3.0, 40.0, "gaussian")
    short = s[:700]
    got, depth_short = stepped(StaticInverseStepper(opg), short)
    assert depth_short == depth and short.min() < 0 < short.max()
    assert np.max(np.abs(got - opg.invert(short))) < 1e-9


# -- per sample --------------------------------------------------------------------------------


@pytest.mark.parametrize("params", [FITTED, PAPER_CONTROL], ids=["fitted", "paper_control"])
def test_per_sample_controller_agrees_with_offline(params):
    for s in (strain_sine(1000.0, 40.0, 40), vanishing()):
        v_off = compensated_drive(s, params, RATE)
        ctl = CompensationController(params, RATE)
        # PAPER_CONTROL's G_d (lam_d 1.35) has an outside zero at 1 kHz: look-ahead needed
        assert ctl.preview >= (2 if params is PAPER_CONTROL else 1)
        v_ps = ctl.run(s)
        assert np.max(np.abs(v_ps - v_off)) < 1e-5  # V (drives of ~90 V)


def test_per_sample_controller_real_time_usage_and_reset():
    s = strain_sine(600.0, 10.0, 5)
    ctl = CompensationController(FITTED, RATE)
    with pytest.raises(RuntimeError):
        ctl.step(0.0)  # not primed
    ctl.reset()
    n, p = s.size, ctl.preview
    ctl.prime(s[:p])
    v = [ctl.step(s[min(k + p, n - 1)]) for k in range(n)]
    assert np.allclose(v, ctl.run(s), atol=1e-12)


def test_controllers_clip_to_the_rig_range():
    lim = RigLimits(v_min_V=-1.0, v_max_V=50.0)
    s = strain_sine(1000.0, 5.0, 3)
    ctl = CompensationController(FITTED, RATE, limits=lim)
    v = ctl.run(s)
    assert v.min() >= -1.0 and v.max() <= 50.0 and ctl.n_clipped > 0
    d = DirectController(FITTED, RATE, limits=lim)
    v = d.run(s)
    assert v.max() == 50.0 and d.n_clipped > 0


def test_direct_control_is_the_linear_inverse():
    s = strain_sine(1000.0, 5.0, 2)
    v = direct_drive(s, FITTED)
    mid = 0.5 * (s + np.append(s[1:], s[-1]))
    assert np.allclose(v, mid / FITTED.alpha0_ue_per_V)
    assert np.allclose(DirectController(FITTED, RATE).run(s), v)
    assert np.allclose(compute_drive(s, FITTED, RATE, "direct"), v)


# -- limits ------------------------------------------------------------------------------------


def test_infeasible_commands_raise_clear_value_errors():
    lim = RigLimits()
    big = strain_sine(2000.0, 1.0, 2)  # needs ~170 V
    with pytest.raises(InfeasibleCommandError) as e:
        compute_drive(big, FITTED, RATE, "compensated", limits=lim, frequency_hz=1.0)
    assert isinstance(e.value, ValueError) and e.value.kind == "voltage"
    assert "the rig allows -20 to 100 V" in str(e.value)
    fast = strain_sine(1000.0, 80.0, 20)  # 85 V at 80 Hz: over the current limit
    with pytest.raises(InfeasibleCommandError) as e:
        compute_drive(fast, FITTED, RATE, "direct", limits=lim, frequency_hz=80.0)
    assert e.value.kind == "peak_current" and "A peak" in str(e.value)
    # clipping instead of raising for the range (the current is still checked)
    v = compute_drive(big, FITTED, RATE, limits=lim, frequency_hz=1.0, on_infeasible="clip")
    assert v.max() == 100.0
    # the drift-cancelling negative voltages are within the range and allowed
    ok = compute_drive(strain_sine(1000.0, 40.0, 40), FITTED, RATE, limits=lim, frequency_hz=40)
    assert -20.0 < ok.min() < -0.1
    chk = check_drive(ok, RATE, lim, 40.0)
    assert 0 < chk.peak_current_A < lim.i_peak_A and chk.window_s == pytest.approx(1 / 40)


def test_load_params(tmp_path):
    p = load_params(ROOT / "experiments" / "hybrid-params.json")
    assert p.shape == "exponential" and 0 < p.lam_t < 1 < p.lam_d < 2
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(PAPER_CONTROL.model_dump()))
    assert load_params(bare) == PAPER_CONTROL
    bad = tmp_path / "bad.json"
    bad.write_text('{"params": {"alpha0_ue_per_V": -1}}')
    with pytest.raises(ValueError, match="invalid model parameters"):
        load_params(bad)
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_params(bad)


# -- metrics -----------------------------------------------------------------------------------


def test_metrics_on_known_signals():
    f, rate = 2.0, 1000.0
    c = strain_sine(1000.0, f, 3)
    assert tracking_nrmse_pct(c, c) == 0.0
    assert hysteresis_width_pct(c, c, rate, f) == pytest.approx(0.0, abs=1e-9)
    assert zero_command_strain_ue(c, c + 7.0, rate, f) == pytest.approx(7.0)
    assert tracking_nrmse_pct(c, c + 10.0) == pytest.approx(1.0)
    # a lag of phi: S = A/2 (1 - cos(wt - phi)); the branches differ by A sin(phi) at mid-span
    t = np.arange(c.size) / rate
    phi = 0.1
    m = 500.0 * (1 - np.cos(2 * np.pi * f * t - phi))
    w = hysteresis_width_pct(c, m, rate, f)
    assert w == pytest.approx(100 * math.sin(phi), rel=2e-3)
    out = command_metrics(c, m, rate, f)
    assert set(out) >= {"tracking_nrmse_pct", "hysteresis_width_pct", "zero_command_strain_ue"}
    assert out["hysteresis_width_pct"] == pytest.approx(abs(w))
    mean, se = final_strain_ue(np.r_[np.zeros(100), np.full(1000, 3.0)], rate, 0.5)
    assert mean == 3.0 and se == 0.0
    out = command_metrics(c, m, rate, None, periodic=False)
    assert out["hysteresis_width_pct"] is None and out["zero_command_strain_ue"] is None


def test_relaxor_inverse_is_exact_up_to_the_last_sample():
    """The kernel equation holds at every sample but the first (the start-up defect), also at
    the end of a command that does not return to 0 (its continuation at the last value)."""
    n = np.arange(400)
    y = 0.2 * n + 5 * np.sin(n / 7.0)
    for tau, lam, hold in ((2.2e-3, 1.35, "linear"), (FITTED.tau_t_s, FITTED.lam_t, "zoh")):
        v, _ = relaxor_inverse(y, tau, lam, RATE, hold)
        k = sampled_kernel(tau, lam, 1 / RATE, y.size + 1, hold)
        if hold == "zoh":  # V[n] reaches y[n+1]
            r = np.convolve(k[1:], v)[: v.size] - y[1:]
        else:
            r = np.convolve(k, v)[: y.size] - y
            r = r[1:]
        assert np.max(np.abs(r)) < 1e-9
    s = np.concatenate((strain_sine(600.0, 5.0, 1.5), np.full(50, 600.0)))  # ends high
    v_off = compensated_drive(s, FITTED, RATE)
    v_ps = CompensationController(FITTED, RATE).run(s)
    assert np.max(np.abs(v_ps - v_off)) < 1e-5


# -- the creep fitted with the model (labrig fit --effect viscoelastic_creep) ------------------


def test_control_model_with_creep_inverts_model_and_creep():
    """The drive of a ControlModel makes ``KV[model(V)]`` follow the command; the creep stage is
    checked against its continuous-time step response, not against its own inverse."""
    from scipy import signal

    from labrig.control import ControlModel

    c, tau = 0.1, 0.27
    cm = ControlModel(FITTED, (c, tau))
    s = strain_sine(1000.0, 5.0, 10)
    v = compensated_drive(s, cm, RATE)
    y = DynamicHysteresisModel(FITTED).predict(v, RATE)
    a_lag = math.exp(-1.0 / (RATE * tau))  # the sampled lag 1/(1 + tau s), step-invariant
    lag = signal.lfilter([1 - a_lag], [1.0, -a_lag], y)
    y_kv = (1 - c) * y + c * lag
    assert np.max(np.abs(y_kv - s)[100:]) < 1e-4  # ue, on a 1000 ue command
    # without the creep stage the same model misses the command by about c of its changes
    y_plain = DynamicHysteresisModel(FITTED).predict(compensated_drive(s, FITTED, RATE), RATE)
    assert np.max(np.abs((1 - c) * y_plain + c * signal.lfilter([1 - a_lag], [1, -a_lag],
                                                                y_plain) - s)) > 10  # fmt: skip
    # per sample = offline, for sines and a vanishing command
    for cmd in (s, vanishing()):
        assert np.max(np.abs(CompensationController(cm, RATE).run(cmd)
                             - compensated_drive(cmd, cm, RATE))) < 1e-5  # fmt: skip
    # direct control ignores the creep: V = S / alpha0
    assert np.array_equal(direct_drive(s, cm), direct_drive(s, FITTED))


def test_load_control_model(tmp_path):
    from labrig.control import load_control_model

    doc = json.loads((ROOT / "experiments" / "hybrid-params.json").read_text())
    cm = load_control_model(ROOT / "experiments" / "hybrid-params.json")
    assert cm.params == load_params(ROOT / "experiments" / "hybrid-params.json")
    fx = {e["effect"]: e["params"] for e in doc["effects"]}
    assert set(fx) == {"viscoelastic_creep", "remanence"}
    assert cm.creep == (fx["viscoelastic_creep"]["c"], fx["viscoelastic_creep"]["tau_s"])
    r = fx["remanence"]
    assert cm.remanence == pytest.approx(
        (r["A_ue_per_V"], r["beta_per_V"], r["gamma_ratio"] * r["beta_per_V"]), rel=1e-15
    )
    f = tmp_path / "p.json"
    f.write_text(json.dumps({**doc, "effects": []}))
    assert load_control_model(f).creep is None and load_control_model(f).remanence is None
    f.write_text(json.dumps({**doc, "effects": [{"effect": "sensor_lowpass", "params": {}}]}))
    with pytest.raises(ValueError, match="cannot invert the effect 'sensor_lowpass'"):
        load_control_model(f)
    bad = {"effect": "viscoelastic_creep", "params": {"c": 1.5, "tau_s": 0.2}}
    f.write_text(json.dumps({**doc, "effects": [bad]}))
    with pytest.raises(ValueError, match="-1 < c < 1"):
        load_control_model(f)


def test_every_effect_the_registry_calls_invertible_reaches_its_own_control_field(tmp_path):
    """The registry marks which effects the controller inverts; each must land in a field of
    ``ControlModel`` of its own (an effect marked invertible that the controller ignored would
    be dropped from the drive without a word)."""
    import dataclasses

    from labrig.control import INVERTIBLE_EFFECTS, ControlModel, load_control_model

    doc = json.loads((ROOT / "experiments" / "hybrid-params.json").read_text())
    fitted = {e["effect"]: e for e in doc["effects"]}
    effect_fields = [f.name for f in dataclasses.fields(ControlModel) if f.name != "params"]
    reached = []
    for name in INVERTIBLE_EFFECTS:
        assert name in fitted, f"{name}: no fitted example in hybrid-params.json"
        f = tmp_path / f"{name}.json"
        f.write_text(json.dumps({**doc, "effects": [fitted[name]]}))
        cm = load_control_model(f)
        (field,) = [k for k in effect_fields if getattr(cm, k) is not None]
        reached.append(field)
    assert sorted(reached) == sorted(effect_fields)
