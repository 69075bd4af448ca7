"""The ``offset_sine`` step: schema errors at their line, the waveform against its physics, the
preflight's limits (range, currents, ramps) and the plan's table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from labrig.core.errors import InputFileError
from labrig.protocol import preflight as pf
from labrig.protocol.check import check_protocol, format_plan, load_plan
from labrig.rig.limits import RigLimits

#: the bipolar rig's limits (experiments/rigs/bipolar.yaml)
BIPOLAR = RigLimits(
    v_min_V=-150.0, v_max_V=150.0, capacitance_F=1e-6, large_signal_factor=1.5, i_peak_A=0.18
)


def write(tmp_path: Path, steps: str, rate_hz: float = 2000.0) -> Path:
    p = tmp_path / "p.yaml"
    p.write_text(f"name: t\nrate_hz: {rate_hz:g}\nsteps:\n{steps}")
    return p


def offset_sine(**keys) -> str:
    """A one-step protocol body: the offset sine with ``keys``, one per line: the step at line
    4, offset_V 5, amplitude_V 6, frequency_hz 7, cycles 8, further keys from line 9 on."""
    base = {"offset_V": -90, "amplitude_V": 60, "frequency_hz": 20, "cycles": 10}
    base.update(keys)
    lines = "".join(f"    {k}: {v}\n" for k, v in base.items() if v is not None)
    return "  - kind: offset_sine\n" + lines


def refused(path: Path, limits: RigLimits | None = None) -> list:
    with pytest.raises(InputFileError) as e:
        check_protocol(path, limits)
    assert e.value.exit_code == 2
    return e.value.issues


def the_step(tmp_path: Path, limits: RigLimits = BIPOLAR, rate_hz: float = 2000.0, **keys):
    (step,) = check_protocol(write(tmp_path, offset_sine(**keys), rate_hz), limits).steps
    return step


# --- schema -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("keys", "line", "field", "message"),
    [
        ({"offset_V": None}, 4, "steps[0].offset_V", "required"),
        ({"duration_s": 2}, 4, "steps[0]", "exactly one of cycles or duration_s"),
        ({"envelope": "rising"}, 9, "steps[0].envelope", "growing"),
        ({"ramp_s": -0.5}, 9, "steps[0].ramp_s", "greater than or equal to 0"),
        ({"settle_s": '"1"'}, 9, "steps[0].settle_s", "without quotes"),
        ({"amplitude_V": 0}, 6, "steps[0].amplitude_V", "greater than 0"),
        ({"bias_V": 3}, 9, "steps[0].bias_V", "unknown key"),
    ],
)
def test_schema_errors_name_line_and_field(tmp_path, keys, line, field, message):
    issues = refused(write(tmp_path, offset_sine(**keys)), BIPOLAR)
    hits = [i for i in issues if i.line == line and i.field == field and message in i.message]
    assert hits, [str(i) for i in issues]


def test_a_ramp_shorter_than_one_sample_is_refused_at_ramp_s(tmp_path):
    (issue,) = refused(write(tmp_path, offset_sine(ramp_s=0.0001)), BIPOLAR)
    assert (issue.line, issue.field) == (9, "steps[0].ramp_s")
    assert "shorter than one sample" in issue.message and "0.0005 s" in issue.message


# --- the waveform -----------------------------------------------------------------------------


def test_ramp_settle_sine_and_ramp_back_are_recorded_in_order(tmp_path):
    rate = 2000.0
    s = the_step(tmp_path, rate_hz=rate, envelope="growing", ramp_s=0.5, settle_s=1.0)
    v, t = s.samples(), s.times()
    assert s.name == "offset_sine_m90V_60V_20Hz_growing" and s.kind == "offset_sine"
    assert s.n_samples == round((0.5 + 1.0 + 10 / 20 + 0.5) * rate) + 1
    assert v[0] == 0.0 and v[-1] == 0.0
    # the ramp: 0 V to the bias, monotonic, half-way at half time, flat at both ends
    ramp = v[t <= 0.5]
    assert np.all(np.diff(ramp) <= 0) and ramp[-1] == pytest.approx(-90, abs=1e-12)
    assert np.interp(0.25, t, v) == pytest.approx(-45, abs=1e-9)
    slope = np.diff(v) * rate
    assert abs(slope[0]) < 0.01 * np.max(np.abs(slope[: round(0.5 * rate)]))
    # the settle: exactly the bias
    assert np.all(v[(t >= 0.5) & (t <= 1.5)] == -90.0)
    # the ramp back: from the bias to 0 V, monotonic, recorded in the entry
    back = v[t >= 2.0]
    assert back[0] == pytest.approx(-90, abs=1e-9) and np.all(np.diff(back) >= 0)
    assert back.size == round(0.5 * rate) + 1
    d = s.definition
    assert (d["sine_start_s"], d["sine_end_s"]) == (1.5, 2.0)
    assert (d["offset_V"], d["amplitude_V"], d["envelope"]) == (-90, 60, "growing")


@pytest.mark.parametrize("envelope", ["constant", "growing", "vanishing"])
def test_the_envelope_shape_at_the_sines_crests(tmp_path, envelope):
    """At the crests of the carrier (a quarter into each cycle, ``sin = 1``) the excursion
    from the bias is the envelope times A: constant A, growing ``A (k + 1/4)/N`` (from zero),
    vanishing its mirror (to zero); half a cycle later the troughs mirror the crests; and each
    cycle of the constant envelope averages to the bias."""
    rate, f, n_cycles, a, bias = 4000.0, 10.0, 8, 60.0, 20.0
    s = the_step(tmp_path, rate_hz=rate, offset_V=bias, amplitude_V=a, frequency_hz=f,
                 cycles=n_cycles, envelope=envelope, ramp_s=0.2, settle_s=0.3)  # fmt: skip
    v = s.samples()
    start = round(0.5 * rate)  # ramp + settle
    per_cycle = round(rate / f)
    k = np.arange(n_cycles)
    crests = v[start + (k * per_cycle + per_cycle // 4)] - bias
    troughs = v[start + (k * per_cycle + 3 * per_cycle // 4)] - bias
    share = {
        "constant": np.ones(n_cycles),
        "growing": (k + 0.25) / n_cycles,
        "vanishing": 1 - (k + 0.25) / n_cycles,
    }[envelope]
    assert crests == pytest.approx(a * share, abs=1e-9)
    trough_share = (
        share + (0.5 / n_cycles) * {"constant": 0, "growing": 1, "vanishing": -1}[envelope]
    )
    assert troughs == pytest.approx(-a * trough_share, abs=1e-9)
    if envelope == "constant":
        means = [np.mean(v[start + j * per_cycle : start + (j + 1) * per_cycle]) for j in k]
        assert means == pytest.approx([bias] * n_cycles, abs=1e-9)
    end = v[start + n_cycles * per_cycle]
    assert end == pytest.approx(bias, abs=1e-9)  # whole cycles end at the bias


def test_a_constant_bipolar_sine_has_the_amplitude_in_its_spectrum(tmp_path):
    """The FFT of the sine part of ``offset_sine`` with offset 0: amplitude A at f only."""
    rate, f, a = 1000.0, 10.0, 150.0
    s = the_step(tmp_path, rate_hz=rate, offset_V=0, amplitude_V=a, frequency_hz=f, cycles=20,
                 ramp_s=0, settle_s=0.2)  # fmt: skip
    v = s.samples()[round(0.2 * rate) : round(2.2 * rate)]
    spec = np.abs(np.fft.rfft(v)) * 2 / v.size
    freqs = np.fft.rfftfreq(v.size, 1 / rate)
    assert spec[np.argmin(np.abs(freqs - f))] == pytest.approx(a, rel=1e-9)
    others = np.delete(spec, np.argmin(np.abs(freqs - f)))
    assert np.max(others) < 1e-9 * a
    assert s.samples()[: round(0.2 * rate) + 1].max() == 0.0  # the settle at 0 V
    assert s.definition["edge_ramps"] == 0  # whole cycles from and to 0 V: nothing to join


def test_continuous_everywhere_and_edge_ramps_without_raised_cosine_ramps(tmp_path):
    """No jump larger than the steepest slope allows, at any joint; with ramp_s 0 the
    protocol's straight edge ramps (1000 V/s) reach the bias."""
    rate = 2000.0
    for ramp_s in (0.5, 0):
        s = the_step(tmp_path, rate_hz=rate, duration_s=0.4125, cycles=None, ramp_s=ramp_s)
        v = s.samples()
        steepest = max(2 * math.pi * 20 * 60, 1000.0, math.pi * 90 / (2 * 0.5))
        assert np.max(np.abs(np.diff(v))) <= steepest / rate * 1.01
        assert v[0] == 0.0 and v[-1] == 0.0
    assert s.definition["edge_ramps"] == 2
    assert np.diff(v)[:5] * rate == pytest.approx([-1000.0] * 5)  # the straight edge ramp


# --- preflight --------------------------------------------------------------------------------


def test_peak_and_mean_current_match_the_bipolar_sine_formulas(tmp_path):
    """A sine of amplitude A at f about any bias: i_peak = 2 pi C A f, cycle mean 4 C A f."""
    a, f = 150.0, 100.0
    s = the_step(tmp_path, rate_hz=5000.0, offset_V=0, amplitude_V=a, frequency_hz=f,
                 cycles=20, ramp_s=0, settle_s=0)  # fmt: skip
    chk = pf.measure(s, BIPOLAR)
    c = 1.5e-6
    assert chk.peak_current_A == pytest.approx(2 * math.pi * c * a * f, rel=2e-3)
    assert chk.mean_current_A == pytest.approx(4 * c * a * f, rel=2e-3)
    assert (chk.v_min_V, chk.v_max_V) == (pytest.approx(-a, rel=1e-6), pytest.approx(a, rel=1e-6))


def test_an_offset_beyond_the_range_is_refused_at_offset_v(tmp_path):
    issues = refused(write(tmp_path, offset_sine(offset_V=-160, amplitude_V=5)), BIPOLAR)
    hit = [i for i in issues if i.field == "steps[0].offset_V"]
    assert hit and hit[0].line == 5
    assert "-160 V" in hit[0].message and "-150 to 150 V" in hit[0].message


def test_an_amplitude_beyond_the_range_names_the_room_around_the_bias(tmp_path):
    (issue,) = refused(write(tmp_path, offset_sine(amplitude_V=70)), BIPOLAR)
    assert (issue.line, issue.field) == (6, "steps[0].amplitude_V")
    assert "use amplitude_V <= 60" in issue.message
    assert the_step(tmp_path, amplitude_V=60).definition["amplitude_V"] == 60  # the room fits


def test_a_too_fast_sine_is_refused_at_frequency_hz_with_the_highest_frequency(tmp_path):
    a = 150.0
    c = 1.5e-6
    f_max = min(0.18 / (2 * math.pi * c * a), 0.12 / (4 * c * a))  # 127.3 Hz
    p = write(tmp_path, offset_sine(offset_V=0, amplitude_V=a, frequency_hz=200, cycles=100,
                                    ramp_s=0), rate_hz=10000)  # fmt: skip
    issues = refused(p, BIPOLAR)
    at_f = [i for i in issues if i.field == "steps[0].frequency_hz"]
    assert at_f and all(i.line == 7 for i in at_f)
    offered = math.floor(f_max * 10) / 10  # rounded down: the value offered passes
    assert any(f"max frequency at 150 V is {offered:.1f} Hz" in i.message for i in at_f)
    assert any("peak" in i.message for i in at_f) and any("average" in i.message for i in at_f)
    below = write(tmp_path, offset_sine(offset_V=0, amplitude_V=a, frequency_hz=math.floor(f_max),
                                        cycles=100, ramp_s=0), rate_hz=10000)  # fmt: skip
    check_protocol(below, BIPOLAR)


def test_too_few_samples_per_cycle_are_refused(tmp_path):
    issues = refused(write(tmp_path, offset_sine(frequency_hz=150), rate_hz=2000), BIPOLAR)
    assert any(
        i.field == "steps[0].frequency_hz" and "samples per cycle" in i.message for i in issues
    )


def test_a_too_steep_ramp_is_refused_at_ramp_s_and_the_advice_passes(tmp_path):
    issues = refused(write(tmp_path, offset_sine(ramp_s=0.0006), rate_hz=10000), BIPOLAR)
    (issue,) = [i for i in issues if "peak" in i.message]
    assert (issue.line, issue.field) == (9, "steps[0].ramp_s")
    advice = float(issue.message.split("ramp_s >= ")[1])
    # a raised cosine over D peaks at pi |dV| / (2 D): D >= pi 90 C / (2 i_peak)
    assert advice == pytest.approx(math.pi * 90 * 1.5e-6 / (2 * 0.18), rel=0.02)
    check_protocol(write(tmp_path, offset_sine(ramp_s=advice), rate_hz=10000), BIPOLAR)


def test_the_built_in_rig_refuses_the_biased_drive_and_the_bipolar_rig_takes_it():
    root = Path(__file__).resolve().parents[2] / "experiments"
    issues = refused(root / "biased-envelope.yaml", RigLimits())
    assert {f"steps[{k}].offset_V" for k in range(3)} <= {i.field for i in issues}
    plan = check_protocol(root / "biased-envelope.yaml", BIPOLAR)
    assert [s.name for s in plan.steps] == [
        f"offset_sine_m90V_60V_{f}Hz_growing" for f in (20, 40, 100)
    ]


def test_the_plan_table_shows_offset_and_amplitude(tmp_path):
    plan = check_protocol(write(tmp_path, offset_sine()), BIPOLAR)
    console = Console(width=200, record=True)
    console.print(format_plan(plan))
    text = console.export_text()
    assert "offset_sine_m90V_60V_20Hz_constant" in text and "-90+-60" in text
    assert "constant sine -90 V +- 60 V, 20 Hz, 10 cycles" in plan.steps[0].title
    assert load_plan(write(tmp_path, offset_sine(name="biased"))).steps[0].name == "biased"
