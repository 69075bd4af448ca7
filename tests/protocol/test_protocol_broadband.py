"""The ``triangle``, ``prbs`` and ``multisine`` steps: schema errors at their field, waveforms
against independent references (scipy's sawtooth, the m-sequence's autocorrelation and shift
property, the FFT's lines), and the preflight just inside and just outside each limit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from labrig.core.errors import InputFileError
from labrig.protocol import preflight as pf
from labrig.protocol.broadband import prbs_bits, triangle_wave
from labrig.protocol.check import check_protocol, load_plan
from labrig.rig.limits import RigLimits

from helpers import invoke as run_cli

#: the bipolar rig's limits (experiments/rigs/bipolar.yaml): C_eff = 1.5 uF
BIPOLAR = RigLimits(
    v_min_V=-150.0, v_max_V=150.0, capacitance_F=1e-6, large_signal_factor=1.5, i_peak_A=0.18
)
C_EFF = 1.5e-6


def write(tmp_path: Path, kind: str, rate_hz: float = 2000.0, **keys) -> Path:
    """A one-step protocol: the step at line 4, its keys one per line from line 5 in order."""
    body = "".join(f"    {k}: {v}\n" for k, v in keys.items() if v is not None)
    p = tmp_path / "p.yaml"
    p.write_text(f"name: t\nrate_hz: {rate_hz:g}\nsteps:\n  - kind: {kind}\n{body}")
    return p


def refused(path: Path, limits: RigLimits | None = BIPOLAR) -> list:
    with pytest.raises(InputFileError) as e:
        check_protocol(path, limits)
    assert e.value.exit_code == 2
    return e.value.issues


def only_step(path: Path, limits: RigLimits = BIPOLAR):
    (step,) = check_protocol(path, limits).steps
    return step


PRBS = {
    "amplitude_V": 60,
    "offset_V": 0,
    "clock_hz": 200,
    "order": 6,
    "seed": 1,
    "transition_s": 0.002,
    "periods": 1,
}


# --- schema -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "keys", "field", "message"),
    [
        ("prbs", {**PRBS, "seed": 64}, "steps[0].seed", "between 1 and 2**order - 1 = 63"),
        ("prbs", {**PRBS, "seed": 0}, "steps[0].seed", "greater than or equal to 1"),
        ("prbs", {**PRBS, "transition_s": 0.0026}, "steps[0].transition_s", "half a chip"),
        ("prbs", {**PRBS, "transition_s": None}, "steps[0].transition_s", "required"),
        ("prbs", {**PRBS, "order": 2}, "steps[0].order", "greater than or equal to 3"),
        ("prbs", {**PRBS, "duration_s": 1}, "steps[0]", "exactly one of periods or duration_s"),
        (
            "multisine",
            {"frequencies_hz": "[1, 2, 1]", "amplitude_V": 10, "duration_s": 1},
            "steps[0].frequencies_hz",
            "must not repeat",
        ),
        (
            "multisine",
            {"frequencies_hz": "[]", "amplitude_V": 10, "duration_s": 1},
            "steps[0].frequencies_hz",
            "at least 1",
        ),
        (
            "triangle",
            {"amplitude_V": 10, "frequency_hz": 1, "cycles": 1, "start": "high"},
            "steps[0].start",
            "'bias' or 'low'",
        ),
        (
            "triangle",
            {"amplitude_V": -10, "frequency_hz": 1, "cycles": 1},
            "steps[0].amplitude_V",
            "greater than 0",
        ),
    ],
)
def test_schema_errors_name_the_field(tmp_path, kind, keys, field, message):
    (issue,) = refused(write(tmp_path, kind, **keys))
    assert issue.field == field
    assert message in issue.message


def test_transition_at_exactly_half_a_chip_is_accepted(tmp_path):
    step = only_step(write(tmp_path, "prbs", **{**PRBS, "transition_s": 0.0025}))
    assert step.definition["transition_s"] == 0.0025


def test_check_command_exits_2_naming_the_field(tmp_path):
    path = write(tmp_path, "prbs", **{**PRBS, "seed": 64})
    res = run_cli("check", path)
    assert res.exit_code == 2
    assert "steps[0].seed" in res.output and ":9:" in res.output.replace(" ", "")
    assert "Traceback" not in res.output


def test_transition_shorter_than_a_sample_is_refused(tmp_path):
    # 0.4 ms at 2 kHz is 0.8 of a sample interval; at 2.5 kHz it is exactly one
    (issue,) = refused(write(tmp_path, "prbs", **{**PRBS, "transition_s": 0.0004}))
    assert issue.field == "steps[0].transition_s" and "0.0005" in issue.message
    keys = {**PRBS, "transition_s": 0.0004, "amplitude_V": 10}
    assert only_step(write(tmp_path, "prbs", 2500.0, **keys))


# --- waveforms against independent references -------------------------------------------------


@pytest.mark.parametrize(
    ("start", "offset", "phase"), [("bias", 0.0, np.pi / 2), ("low", 40.0, 0.0)]
)
def test_triangle_matches_scipy_sawtooth(tmp_path, start, offset, phase):
    """scipy.signal.sawtooth(x, width=0.5) rises from -1 at x = 0 to +1 at pi: a triangle that
    starts at the bias rising is its phase pi/2, one starting low is phase 0."""
    from scipy import signal  # here, not for every worker's collection

    a, f, rate = 40.0, 4.0, 2000.0  # whole cycles in whole samples: no edge ramps
    step = only_step(
        write(
            tmp_path,
            "triangle",
            rate,
            amplitude_V=a,
            offset_V=offset,
            frequency_hz=f,
            start=start,
            cycles=2,
        )
    )
    t = step.times()
    want = offset + a * signal.sawtooth(2 * np.pi * f * t + phase, width=0.5)
    assert step.definition["edge_ramps"] == 0  # starts and ends at 0 V: no edge ramp
    np.testing.assert_allclose(step.samples(), want, atol=1e-9)
    # and the closed form 2/pi arcsin(sin x) for the one in phase with sin
    x = np.linspace(-3, 3, 1001)
    np.testing.assert_allclose(
        triangle_wave(x), 2 / np.pi * np.arcsin(np.sin(2 * np.pi * x)), atol=1e-12
    )


@pytest.mark.parametrize("order", [5, 9])
def test_prbs_bits_are_a_maximal_length_sequence(order):
    """An m-sequence of period N = 2^n - 1 has 2^(n-1) ones per period, a two-valued circular
    autocorrelation (N at lag 0, -1 elsewhere), and every other start state gives a circular
    shift of it."""
    n = 2**order - 1
    b = prbs_bits(order, 1, 2 * n)
    np.testing.assert_array_equal(b[:n], b[n:])
    assert int(b[:n].sum()) == 2 ** (order - 1)
    s = 2.0 * b[:n] - 1.0
    acf = np.real(np.fft.ifft(np.abs(np.fft.fft(s)) ** 2))
    np.testing.assert_allclose(acf, np.r_[n, -np.ones(n - 1)], atol=1e-9)
    other = prbs_bits(order, 13, n)
    assert not np.array_equal(other, b[:n])
    assert any(np.array_equal(np.roll(b[:n], -k), other) for k in range(n))


def test_prbs_levels_and_slew_limited_edges(tmp_path):
    rate, clock, tr, a, v0 = 20000.0, 200.0, 0.002, 60.0, 10.0
    keys = {**PRBS, "offset_V": v0, "transition_s": tr}
    step = only_step(write(tmp_path, "prbs", rate, **keys))
    d = step.definition
    assert (d["low_V"], d["high_V"], d["chips"]) == (v0 - a, v0 + a, 63)
    bits = prbs_bits(6, 1, 63)
    start, n = piece(step, "prbs")
    assert n == round(63 / clock * rate)
    v = step.samples()
    # the middle of each chip (after its transition) sits on the bit's level
    mids = start + np.round((np.arange(63) + 0.75) / clock * rate).astype(int)
    np.testing.assert_allclose(v[mids], v0 + a * (2.0 * bits - 1.0), atol=1e-9)
    # every level change is a straight ramp of 2A / transition_s; nothing is steeper
    slope = np.abs(np.diff(v[start:])) * rate
    assert slope.max() == pytest.approx(2 * a / tr, rel=1e-9)
    assert d["transitions"] == int(np.count_nonzero(np.diff(bits)))


def test_multisine_lines_phases_and_peak(tmp_path):
    """Over whole periods (1 s for integer frequencies) the FFT shows equal lines at the listed
    frequencies only, with Schroeder's phases, and the peak of |V - V0| is the amplitude."""
    rate, a, v0 = 1000.0, 50.0, 20.0
    freqs = [3, 1, 7, 12, 25]  # any order: sorted for the phases
    step = only_step(
        write(
            tmp_path,
            "multisine",
            rate,
            frequencies_hz=str(freqs),
            amplitude_V=a,
            offset_V=v0,
            duration_s=2,
        )
    )
    v = step.samples()
    d = step.definition
    i0, n = piece(step, "multisine")
    assert n == 2000
    seg = v[i0 : i0 + n] - v0
    spec = np.fft.rfft(seg) / (seg.size / 2)
    k = np.arange(spec.size) * rate / seg.size
    lines = np.isin(np.round(k, 9), freqs)
    amps = np.abs(spec[lines])
    np.testing.assert_allclose(amps, amps[0], rtol=1e-9)
    assert np.max(np.abs(spec[~lines][1:])) < 1e-9 * amps[0]
    kk = np.arange(1, 6)
    want = -np.pi * kk * (kk - 1) / 5
    got = np.angle(spec[lines])
    np.testing.assert_allclose(np.angle(np.exp(1j * (got - want))), 0, atol=1e-9)
    assert np.max(np.abs(seg)) <= a + 1e-9
    assert np.max(np.abs(seg)) >= a * 0.999
    assert amps[0] == pytest.approx(d["line_amplitude_V"], rel=1e-9)
    # Schroeder's phases lower the crest factor below the zero-phase sum's sqrt(2 K) = 3.16
    assert d["crest_factor"] < 0.85 * math.sqrt(2 * 5)


def piece(step, kind: str) -> tuple[int, int]:
    """First sample and sample intervals of the step's piece of ``kind`` (not an edge ramp)."""
    (seg,) = [g for g in step.waveform.segments if g.kind == kind]
    return step.waveform.segment_start(seg), seg.n


# --- preflight just inside and just outside ----------------------------------------------------


def test_biased_drive_minus_100_to_plus_73(tmp_path):
    keys = {"amplitude_V": 86.5, "offset_V": -13.5, "frequency_hz": 5, "cycles": 2}
    step = only_step(write(tmp_path, "triangle", **keys))
    assert min(step.samples()) == pytest.approx(-100) and max(step.samples()) == pytest.approx(73)
    (issue,) = refused(write(tmp_path, "triangle", **keys), RigLimits())
    assert issue.field == "steps[0].amplitude_V" and "amplitude_V <= 6.5" in issue.message
    (issue,) = refused(write(tmp_path, "triangle", **{**keys, "offset_V": -30}), RigLimits())
    assert issue.field == "steps[0].offset_V"


@pytest.mark.parametrize("i_avg", [0.12, 0.5])
def test_triangle_frequency_limit(tmp_path, i_avg):
    """A triangle draws 4 C_eff A f throughout: the highest frequency is min(i_peak, i_avg) /
    (4 C_eff A); 0.5 % below passes, 0.5 % above is refused at frequency_hz."""
    lim = BIPOLAR.model_copy(update={"i_avg_A": i_avg})
    a = 100.0
    f_max = min(0.18, i_avg) / (4 * C_EFF * a)
    assert pf.max_triangle_frequency_hz(a, lim) == pytest.approx(f_max, rel=1e-12)
    rate = 100_000.0  # >= 300 samples per cycle: the corners barely lower the cycle mean
    ok = write(tmp_path, "triangle", rate, amplitude_V=a, frequency_hz=0.995 * f_max, cycles=4)
    assert only_step(ok, lim)
    bad = write(tmp_path, "triangle", rate, amplitude_V=a, frequency_hz=1.005 * f_max, cycles=4)
    issues = refused(bad, lim)
    assert {i.field for i in issues} == {"steps[0].frequency_hz"}
    assert f"max frequency at 100 V is {f_max:.1f} Hz" in issues[0].message


def test_triangle_samples_per_cycle(tmp_path):
    assert only_step(write(tmp_path, "triangle", 200.0, amplitude_V=5, frequency_hz=10, cycles=2))
    (issue,) = refused(
        write(tmp_path, "triangle", 200.0, amplitude_V=5, frequency_hz=10.1, cycles=2)
    )
    assert issue.field == "steps[0].frequency_hz" and "samples per cycle" in issue.message


def test_prbs_edge_slew_limit(tmp_path):
    """Each level change of 2A in transition_s draws 2 C_eff A / transition_s: the shortest
    edge is 2 C_eff A / i_peak (1 ms for 60 V on the bipolar rig)."""
    t_min = 2 * C_EFF * 60 / 0.18
    assert t_min == pytest.approx(1e-3)
    rate = 50000.0
    assert only_step(write(tmp_path, "prbs", rate, **{**PRBS, "transition_s": 1.005 * t_min}))
    (issue,) = refused(write(tmp_path, "prbs", rate, **{**PRBS, "transition_s": 0.995 * t_min}))
    assert issue.field == "steps[0].transition_s"
    assert "use transition_s >= 0.001" in issue.message


def test_prbs_mean_current_is_blamed_on_the_clock(tmp_path):
    lim = BIPOLAR.model_copy(update={"i_avg_A": 0.005})
    issues = refused(write(tmp_path, "prbs", 20000.0, **PRBS), lim)
    assert [i.field for i in issues] == ["steps[0].clock_hz"]
    # each change carries 2 C_eff A = 180 uC; the busiest second of the sequence draws that
    # times its changes: far above 5 mA
    assert "lower clock_hz or amplitude_V" in issues[0].message


def test_multisine_suggested_amplitude_is_just_right(tmp_path):
    """The peak current scales with the amplitude: the amplitude the message suggests passes,
    1 % more is refused again."""
    keys = {"frequencies_hz": "[5, 40, 90]", "offset_V": 0, "duration_s": 1}
    lim = BIPOLAR.model_copy(update={"i_peak_A": 0.03, "i_avg_A": 1.0})
    (issue,) = refused(write(tmp_path, "multisine", 4000.0, amplitude_V=100, **keys), lim)
    assert issue.field == "steps[0].amplitude_V"
    suggested = float(issue.message.split("amplitude_V <= ")[1].split(" ")[0])
    assert only_step(write(tmp_path, "multisine", 4000.0, amplitude_V=suggested, **keys), lim)
    refused(write(tmp_path, "multisine", 4000.0, amplitude_V=suggested * 1.01, **keys), lim)


def test_multisine_samples_per_cycle_of_the_highest_line(tmp_path):
    keys = {"amplitude_V": 5, "duration_s": 1}
    assert only_step(write(tmp_path, "multisine", 2000.0, frequencies_hz="[1, 100]", **keys))
    (issue,) = refused(write(tmp_path, "multisine", 2000.0, frequencies_hz="[1, 101]", **keys))
    assert issue.field == "steps[0].frequencies_hz" and "101 Hz" in issue.message


def test_names_and_titles(tmp_path):
    p = tmp_path / "p.yaml"
    p.write_text(
        "name: t\nrate_hz: 2000\nsteps:\n"
        "  - {kind: triangle, amplitude_V: 50, offset_V: 50, start: low, frequency_hz: 2, "
        "cycles: 1}\n"
        "  - {kind: prbs, amplitude_V: 60, clock_hz: 200, order: 6, seed: 5, "
        "transition_s: 0.002, periods: 1}\n"
        "  - {kind: multisine, frequencies_hz: [1, 2.5], amplitude_V: 9, duration_s: 2}\n"
    )
    plan = load_plan(p)
    assert [s.name for s in plan.steps] == [
        "triangle_50V_50V_2Hz",
        "prbs_0V_60V_200Hz_o6_s5",
        "multisine_0V_9V_2f_1to2p5Hz",
    ]
    assert "LFSR order 6, seed 5" in plan.steps[1].title
    assert "Schroeder" in plan.steps[2].title
    assert math.isclose(plan.steps[0].duration_s, 0.5)


def test_a_multisine_too_large_to_synthesise_is_refused_before_any_work(tmp_path, monkeypatch):
    """Lines x samples past the bound: refused at once (exit 2, the duration blamed, the
    longest duration that passes offered), not computed for minutes; one sample under the
    bound passes (checked with the bound lowered, so that the passing case is cheap)."""
    import time

    from labrig.core.errors import InputFileError
    from labrig.protocol import broadband
    from labrig.protocol.check import check_protocol

    lines = [0.5 + 4 * k for k in range(100)]
    rate = 100_000

    def protocol(n_samples: int) -> Path:
        p = tmp_path / f"m{n_samples}.yaml"
        p.write_text(f"name: m\nrate_hz: {rate}\nsteps:\n  - kind: multisine\n    offset_V: 10\n"
                     f"    amplitude_V: 1\n    frequencies_hz: {lines}\n"
                     f"    duration_s: {n_samples / rate!r}\n")  # fmt: skip
        return p

    t0 = time.process_time()
    with pytest.raises(InputFileError) as e:
        check_protocol(protocol(40 * rate))  # 40 s at 100 kHz: minutes of work before
    assert time.process_time() - t0 < 5.0  # refused before the work, not after it
    msg = str(e.value)
    assert "duration_s" in msg and "line-samples" in msg and "fewer lines" in msg
    monkeypatch.setattr(broadband, "MAX_MULTISINE_LINE_SAMPLES", 100 * 20_000)
    with pytest.raises(InputFileError, match="line-samples"):
        check_protocol(protocol(20_001))
    check_protocol(protocol(20_000))
