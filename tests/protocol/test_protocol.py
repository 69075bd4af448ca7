"""Protocol files: expansion into concrete steps, waveform formulas, preflight numbers."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from labrig.core.errors import InputFileError
from labrig.protocol import preflight as pf
from labrig.protocol.check import check_protocol, format_plan, load_plan
from labrig.protocol.waveforms import envelope, unipolar_sine
from labrig.rig.drive_load import DriveLoad
from labrig.rig.limits import RigLimits

ROOT = Path(__file__).resolve().parents[2]
EXP = ROOT / "experiments"
SWEEP_NAMES = [f"sine_{a}V_{f}Hz" for a in (50, 100) for f in (1, 5, 10, 20, 40)]


def write(tmp_path: Path, text: str, name: str = "p.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def proto(steps: str, head: str = "name: t\nrate_hz: 1000\n") -> str:
    return head + "steps:\n" + steps


# --- the paper's experiments ------------------------------------------------------------------


def test_sweep_yaml_expands_to_the_paper_sweep():
    plan = check_protocol(EXP / "sweep.yaml")
    assert [s.name for s in plan.steps] == SWEEP_NAMES
    assert [(s.amplitude_V, s.frequency_hz) for s in plan.steps] == [
        (a, f) for a in (50, 100) for f in (1, 5, 10, 20, 40)
    ]
    for s in plan.steps:
        assert s.kind == "sine"
        cycles = s.definition["cycles"]
        assert cycles >= 5 and cycles == int(cycles)
        assert s.duration_s >= 4 - 1e-9
        # whole cycles: duration = cycles / f, no edge ramps needed
        assert s.duration_s == pytest.approx(cycles / s.frequency_hz)
        assert s.definition["edge_ramps"] == 0
    assert plan.steps[4].definition["cycles"] == 160  # 40 Hz for 4 s: steady state
    assert 30 <= plan.recorded_duration_s <= 120
    assert plan.steps[-1].rest_after_s == 0
    assert all(s.rest_after_s == 3 for s in plan.steps[:-1])


def test_envelope_yaml_is_the_vanishing_envelope():
    plan = check_protocol(EXP / "envelope.yaml")
    (s,) = plan.steps
    assert s.name == "vanishing_100V_1Hz" and s.kind == "vanishing"
    assert s.frequency_hz == 1 and s.amplitude_V == 100
    d = s.definition
    assert d["decay_s"] == 5 and d["envelope_end_s"] == pytest.approx(5.5) and d["hold_s"] > 0
    v = s.samples()
    t = s.times()
    assert v[0] == 0 and v[-1] == 0
    assert np.all(v[t >= 5.5] == pytest.approx(0, abs=1e-9))
    peaks = [v[(t >= k) & (t < k + 1)].max() for k in range(5)]
    assert peaks[0] == pytest.approx(100) and all(a > b for a, b in itertools.pairwise(peaks))


def test_paper_yaml_is_sweep_plus_envelope():
    paper = check_protocol(EXP / "paper.yaml")
    sweep = load_plan(EXP / "sweep.yaml")
    env = load_plan(EXP / "envelope.yaml")
    assert len(paper.steps) == 11
    assert [s.name for s in paper.steps] == [*SWEEP_NAMES, "vanishing_100V_1Hz"]
    for a, b in zip(paper.steps, sweep.steps + env.steps, strict=True):
        assert a.definition | {"source_step": 0} == b.definition | {"source_step": 0}
        np.testing.assert_array_equal(a.samples(), b.samples())


def test_format_plan_lists_every_entry():
    plan = check_protocol(EXP / "paper.yaml")
    console = Console(width=160, record=True)
    console.print(format_plan(plan))
    out = console.export_text()
    for name in [*SWEEP_NAMES, "vanishing_100V_1Hz"]:
        assert name in out
    assert "peak A" in out and "0.128" in out  # 100 V at 40 Hz
    json.dumps(plan.to_dict())  # JSON-able


# --- waveform formulas ------------------------------------------------------------------------


@pytest.mark.parametrize("a,f,rate", [(100, 1, 1000), (50, 40, 1000), (80, 3, 997)])
def test_sine_matches_its_definition(tmp_path, a, f, rate):
    p = write(
        tmp_path,
        f"name: t\nrate_hz: {rate}\nsteps:\n  - kind: sine\n    amplitude_V: {a}\n"
        f"    frequency_hz: {f}\n    cycles: 3\n",
    )
    (s,) = check_protocol(p).steps
    v, t = s.samples(), s.times()
    assert v[0] == 0.0 and v[-1] == 0.0
    inner = slice(1, -1)
    np.testing.assert_allclose(v[inner], a / 2 * (1 - np.cos(2 * np.pi * f * t[inner])), atol=1e-9)
    # peak A at t = 1/(2f), period 1/f
    assert unipolar_sine(np.array([1 / (2 * f)]), a, f)[0] == pytest.approx(a)
    w = s.waveform
    u = np.linspace(0.1, 1.7, 7) * rate / f
    np.testing.assert_allclose(w.at_index(u), w.at_index(u + rate / f), atol=1e-9)
    assert v.max() == pytest.approx(a, rel=1e-2) and v.max() <= a and v.min() >= 0
    assert s.duration_s == pytest.approx(3 / f, abs=1 / rate)


def test_envelope_shapes():
    t = np.linspace(0, 5, 11)
    lin = envelope(t, 5.0, "linear")
    np.testing.assert_allclose(lin, 1 - t / 5)
    tau = 5 / 2
    ex = envelope(t, 5.0, "exponential")
    ref = (np.exp(-t / tau) - np.exp(-5 / tau)) / (1 - np.exp(-5 / tau))
    np.testing.assert_allclose(ex, ref, rtol=1e-12, atol=1e-15)
    assert ex[0] == pytest.approx(1) and ex[-1] == 0
    # extreme time constants stay finite and bounded
    for tau_s in (1e-6, 1e6):
        e = envelope(t, 5.0, "exponential", tau_s)
        assert np.all(np.isfinite(e)) and e[0] == pytest.approx(1) and e[-1] == 0
        assert np.all(np.diff(e) <= 1e-15)


def test_every_kind_starts_and_ends_at_zero_with_edge_ramps(tmp_path):
    (tmp_path / "w.csv").write_text("v\n5\n10\n20\n")
    p = write(
        tmp_path,
        proto(
            "  - {kind: sine, amplitude_V: 40, frequency_hz: 2, duration_s: 0.6}\n"
            "  - {kind: vanishing, amplitude_V: 40, frequency_hz: 2, decay_s: 1, shape: linear}\n"
            "  - {kind: hold, voltage_V: 50, duration_s: 0.5}\n"
            "  - {kind: hold, voltage_V: -10, duration_s: 0.5}\n"
            "  - {kind: ramp, from_V: 20, to_V: 80, duration_s: 1}\n"
            "  - {kind: csv, path: w.csv}\n",
            "name: t\nrate_hz: 1000\nedge_slew_V_per_s: 500\n",
        ),
    )
    plan = check_protocol(p)
    for s in plan.steps:
        v = s.samples()
        assert v[0] == 0.0 and v[-1] == 0.0, s.name
        assert len(v) == s.n_samples
    hold = plan.step("hold_50V_0p5s")
    v = hold.samples()
    # 50 V at 500 V/s: 0.1 s = 100 samples each way
    assert hold.n_samples == 100 + 500 + 100 + 1
    assert v[100] == pytest.approx(50) and v[600] == pytest.approx(50)
    np.testing.assert_allclose(np.diff(v[:101]), 0.5)
    sine = plan.step("sine_40V_2Hz")  # 0.6 s = 1.2 cycles: ends high, edge ramp down
    assert sine.definition["edge_ramps"] == 1
    ramp = plan.step("ramp_20V_to_80V")
    assert ramp.definition["edge_ramps"] == 2
    assert plan.step("vanishing_40V_2Hz").definition["edge_ramps"] == 0


def test_blockwise_samples_equal_whole(tmp_path):
    plan = load_plan(EXP / "paper.yaml")
    s = plan.steps[-1]
    whole = s.samples()
    parts = np.concatenate([s.samples(i, i + 777) for i in range(0, s.n_samples, 777)])
    np.testing.assert_array_equal(whole, parts)
    np.testing.assert_array_equal(s.times()[:5], np.arange(5) / 1000)


# --- names, repeats, rests, sweeps ------------------------------------------------------------


def test_names_repeats_and_rests(tmp_path):
    p = write(
        tmp_path,
        proto(
            "  - {kind: sine, amplitude_V: 50, frequency_hz: 1, cycles: 1, repeat: 3}\n"
            "  - {kind: sine, amplitude_V: 50, frequency_hz: 1, cycles: 1, rest_s: 7}\n"
            "  - {kind: hold, voltage_V: 0, duration_s: 1, name: creep}\n"
            "  - {kind: sweep, name: low, amplitudes_V: [10, 20], frequencies_hz: [1, 2.5],\n"
            "     cycles: 1, order: by_frequency, repeat: 2}\n"
            "  - {kind: ramp, from_V: -5, to_V: 5, duration_s: 1}\n",
            "name: t\nrate_hz: 1000\nrest_s: 2\n",
        ),
    )
    plan = check_protocol(p)
    names = [s.name for s in plan.steps]
    sweep = ["low_10V_1Hz", "low_20V_1Hz", "low_10V_2p5Hz", "low_20V_2p5Hz"]
    assert names == [
        "sine_50V_1Hz",
        "sine_50V_1Hz_2",
        "sine_50V_1Hz_3",
        "sine_50V_1Hz_4",
        "creep",
        *sweep,
        *[n + "_2" for n in sweep],
        "ramp_m5V_to_5V",
    ]
    assert len(set(names)) == len(names)
    rests = [s.rest_after_s for s in plan.steps]
    assert rests[:5] == [2, 2, 2, 7, 2] and rests[-1] == 0
    assert [s.repeat_index for s in plan.steps[:3]] == [1, 2, 3]
    assert plan.total_duration_s == pytest.approx(plan.recorded_duration_s + sum(rests))


def test_sweep_min_duration_and_duration(tmp_path):
    p = write(
        tmp_path,
        proto(
            "  - {kind: sweep, amplitudes_V: [10], frequencies_hz: [1, 7, 30], cycles: 2,\n"
            "     min_duration_s: 1.5}\n"
            "  - {kind: sweep, amplitudes_V: [10], frequencies_hz: [2], duration_s: 1.25}\n"
        ),
    )
    plan = check_protocol(p)
    assert [s.definition["cycles"] for s in plan.steps[:3]] == [2, 11, 45]
    last = plan.steps[3]
    assert last.definition["duration_s"] == pytest.approx(1.25)
    assert last.definition["edge_ramps"] == 1  # 2.5 cycles end at the peak


# --- CSV steps --------------------------------------------------------------------------------


def test_csv_timebases(tmp_path):
    (tmp_path / "t.csv").write_text("# ramp\ntime_s,volts\n0,0\n0.5,10\n1.0,0\n")
    (tmp_path / "r.dat").write_text("1 0\n2 4\n3 8\n4 0\n")
    (tmp_path / "n.csv").write_text("0\n1\n2\n1\n0\n")
    p = write(
        tmp_path,
        proto(
            "  - {kind: csv, path: t.csv, time_column: time_s, column: volts}\n"
            "  - {kind: csv, path: r.dat, column: 1, rate_hz: 10, name: dat}\n"
            "  - {kind: csv, path: n.csv, scale: 2.5}\n",
            "name: t\nrate_hz: 100\n",
        ),
    )
    plan = check_protocol(p)
    a, b, c = plan.steps
    assert a.name == "csv_t" and a.n_samples == 101 and a.definition["resampled"]
    np.testing.assert_allclose(a.samples()[[0, 25, 50, 75, 100]], [0, 5, 10, 5, 0])
    assert b.n_samples == 31 and b.samples()[10] == pytest.approx(4)
    assert b.samples()[5] == pytest.approx(2)
    np.testing.assert_allclose(c.samples(), [0, 2.5, 5, 2.5, 0])
    assert not c.definition["resampled"]


# --- preflight numbers ------------------------------------------------------------------------


def _independent_fmax(amplitude_V: float, lim: RigLimits) -> float:
    """Highest unipolar-sine frequency at ``amplitude_V``, straight from the RigLimits fields.

    V = A/2 (1 - cos 2 pi f t): max dV/dt = pi A f, cycle mean |dV/dt| = 2 A f.
    """
    c_eff = lim.capacitance_F * lim.large_signal_factor
    f_peak = lim.i_peak_A / (c_eff * math.pi * amplitude_V)
    f_avg = lim.i_avg_A / (c_eff * 2 * amplitude_V)
    return min(f_peak, f_avg)


def test_current_limit_frequency_at_100V(tmp_path):
    lim = RigLimits()
    fmax = _independent_fmax(100, lim)
    assert fmax == pytest.approx(56.17, abs=0.01)  # "about 55 Hz" in the paper
    assert pf.max_sine_frequency_hz(100, lim) == pytest.approx(fmax)

    def plan_at(f):
        return write(
            tmp_path,
            proto(
                f"  - {{kind: sine, amplitude_V: 100, frequency_hz: {f!r}, cycles: 20}}\n",
                "name: t\nrate_hz: 5000\n",
            ),
            f"p{f}.yaml",
        )

    ok = check_protocol(plan_at(round(fmax * 0.995, 3)))
    assert ok.checks[0].peak_current_A == pytest.approx(0.995 * lim.i_peak_A, rel=2e-3)
    with pytest.raises(InputFileError) as e:
        check_protocol(plan_at(round(fmax * 1.005, 3)))
    msg = str(e.value)
    # the highest frequency offered is rounded down (56.17 -> 56.1), and it passes; the value
    # rounded to the nearest (56.2) would not
    assert "max frequency at 100 V is 56.1 Hz" in msg
    check_protocol(plan_at(56.1))
    with pytest.raises(InputFileError):
        check_protocol(plan_at(56.2))
    assert e.value.issues[0].line == 4 and e.value.issues[0].field == "steps[0].frequency_hz"


def test_peak_and_mean_current_of_a_sine_match_the_formulas(tmp_path):
    lim = RigLimits()
    c_eff = lim.capacitance_F * lim.large_signal_factor
    p = write(tmp_path, proto("  - {kind: sine, amplitude_V: 100, frequency_hz: 40, cycles: 8}\n"))
    (chk,) = check_protocol(p).checks
    assert chk.peak_current_A == pytest.approx(math.pi * c_eff * 100 * 40, rel=1e-3)
    assert chk.mean_current_A == pytest.approx(2 * c_eff * 100 * 40, rel=2e-3)
    assert chk.v_min_V == pytest.approx(0) and chk.v_max_V == pytest.approx(100, rel=1e-6)


def test_average_limit_binds_on_a_weaker_amplifier(tmp_path):
    lim = RigLimits(i_avg_A=0.05)
    fmax = _independent_fmax(100, lim)
    assert fmax == pytest.approx(0.05 / (2 * 6e-6 * 1.7 * 100))
    p = write(tmp_path, proto("  - {kind: sine, amplitude_V: 100, frequency_hz: 30, cycles: 9}\n"))
    with pytest.raises(InputFileError) as e:
        check_protocol(p, lim)
    (issue,) = e.value.issues
    assert "on average over a cycle" in issue.message and f"{fmax:.1f} Hz" in issue.message


def test_other_rig_limits_refuse_the_sweep():
    lim = RigLimits(v_max_V=60)
    with pytest.raises(InputFileError) as e:
        check_protocol(EXP / "sweep.yaml", lim)
    assert {i.field for i in e.value.issues} == {"steps[0].amplitudes_V[1]"}
    assert all(i.line == 18 for i in e.value.issues)  # the amplitudes_V line of sweep.yaml


def test_a_drive_load_is_compared_with_the_limits_at_their_tolerances():
    """The one comparison of a measured drive with the rig (preflight and controller): the
    voltage range with 1 nV to spare, the currents with 1 ppm; a current that is not a number
    is over the limit."""
    lim = RigLimits()  # -20..100 V, 0.18 A peak, 0.12 A average

    def load(v_min=0.0, v_max=50.0, peak=0.1, mean=0.05):
        return DriveLoad(v_min, v_max, peak, 0.0, mean, 0.0, 1.0, 1.0)

    assert load().beyond_range(lim) is None
    assert load(v_max=100.0 + 5e-10).beyond_range(lim) is None
    assert load(v_max=100.0 + 2e-9).beyond_range(lim) == (True, 100.0 + 2e-9)
    assert load(v_min=-20.1).beyond_range(lim) == (False, -20.1)
    assert load(v_min=-30.0, v_max=120.0).beyond_range(lim) == (True, 120.0)  # the top first
    assert not load(peak=0.18 * (1 + 5e-7)).over_peak(lim)
    assert load(peak=0.18 * (1 + 2e-6)).over_peak(lim) and load(peak=math.nan).over_peak(lim)
    assert not load(mean=0.12).over_mean(lim)
    assert load(mean=0.121).over_mean(lim) and load(mean=math.inf).over_mean(lim)


def test_preflight_records_each_entry_with_its_name_and_duration():
    plan = check_protocol(EXP / "paper.yaml")
    assert plan.checks is not None
    assert [c.name for c in plan.checks] == [s.name for s in plan.steps]
    assert [c.duration_s for c in plan.checks] == [s.duration_s for s in plan.steps]
    assert all(isinstance(c, DriveLoad) for c in plan.checks)


def test_chunked_scan_equals_single_pass():
    plan = load_plan(EXP / "envelope.yaml")
    step = plan.steps[0]
    whole = pf.measure(step, RigLimits())
    chunked = pf.measure(step, RigLimits(), chunk=997)
    assert chunked.peak_current_A == pytest.approx(whole.peak_current_A, rel=1e-12)
    assert chunked.mean_current_A == pytest.approx(whole.mean_current_A, rel=1e-9)
    assert chunked.v_max_V == whole.v_max_V and chunked.v_min_V == whole.v_min_V


def test_preflight_collects_every_problem(tmp_path):
    p = write(
        tmp_path,
        proto(
            "  - {kind: sine, amplitude_V: 150, frequency_hz: 1, cycles: 1}\n"
            "  - {kind: hold, voltage_V: -30, duration_s: 1}\n",
        ),
    )
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    assert e.value.exit_code == 2
    assert {i.field for i in e.value.issues} == {"steps[0].amplitude_V", "steps[1].voltage_V"}
    # a rate outside the DAQ's range is reported alone (the samples at it mean nothing)
    with pytest.raises(InputFileError) as e:
        check_protocol(p, RigLimits(rate_max_hz=500))
    assert [i.field for i in e.value.issues] == ["rate_hz"]
