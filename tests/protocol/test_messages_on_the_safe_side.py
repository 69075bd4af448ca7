"""What a refusal offers is on the safe side of the limit it names: a value just past a limit
never prints as the limit, a remedy is one the rig can take, and the total length names the
rests when they make it (labrig.protocol.preflight, labrig.protocol.expand)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from labrig.core.errors import InputFileError
from labrig.protocol.check import check_protocol

SINE = "  - {{kind: sine, amplitude_V: 1, frequency_hz: {f!r}, cycles: 2}}\n"


def refusal(tmp_path: Path, text: str) -> InputFileError:
    p = tmp_path / "p.yaml"
    p.write_text(text)
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    return e.value


def passes(tmp_path: Path, text: str) -> None:
    p = tmp_path / "ok.yaml"
    p.write_text(text)
    check_protocol(p)


@pytest.mark.parametrize(("rate", "shown"), [(9.999999999999998, "9.999999999999998"),
                                             (100000.00000001, "100000.00000001")])  # fmt: skip
def test_a_rate_just_outside_the_daqs_range_does_not_print_as_its_edge(tmp_path, rate, shown):
    e = refusal(tmp_path, f"name: r\nrate_hz: {rate!r}\nsteps:\n" + SINE.format(f=0.2))
    assert f"rate_hz {shown} is outside the rig's DAQ range 10 to 100000 Hz" in str(e)
    passes(tmp_path, "name: r\nrate_hz: 10.0\nsteps:\n" + SINE.format(f=0.2))


def test_too_few_samples_per_cycle_at_the_highest_rate_offers_a_lower_frequency(tmp_path):
    e = refusal(tmp_path, "name: r\nrate_hz: 100000\nsteps:\n" + SINE.format(f=5000.000001))
    msg = str(e)
    assert "5000.000001 Hz sampled at rate_hz 100000 gives 19.999999996 samples per cycle" in msg
    assert "lower frequency_hz to <= 5000 (the rig's DAQ runs at most 100000 Hz)" in msg
    assert "raise rate_hz" not in msg
    passes(tmp_path, "name: r\nrate_hz: 100000\nsteps:\n" + SINE.format(f=5000.0))


def test_below_the_highest_rate_both_remedies_are_offered_and_work(tmp_path):
    e = refusal(tmp_path, "name: r\nrate_hz: 1000\nsteps:\n" + SINE.format(f=60.0))
    assert "16.67 samples per cycle" in str(e)
    assert "raise rate_hz to >= 1200 or lower frequency_hz to <= 50" in str(e)
    passes(tmp_path, "name: r\nrate_hz: 1200\nsteps:\n" + SINE.format(f=60.0))
    passes(tmp_path, "name: r\nrate_hz: 1000\nsteps:\n" + SINE.format(f=50.0))


def test_a_protocol_too_long_by_its_rests_names_rest_s(tmp_path):
    hold = "  - {kind: hold, voltage_V: 5, duration_s: 0.1}\n"
    e = refusal(tmp_path, "name: r\nrate_hz: 500\nrest_s: 604800\nsteps:\n" + hold * 2)
    (issue,) = e.issues
    assert (issue.line, issue.field) == (3, "rest_s")
    assert "lasts 168.0001 h (0.0 h of entries, 168.0 h of rests); at most 168 h" in issue.message
    passes(tmp_path, "name: r\nrate_hz: 500\nrest_s: 604799\nsteps:\n" + hold * 2)


def test_an_absurd_voltage_is_blamed_not_the_edge_slew(tmp_path):
    """A hold at 1e300 V cannot be sampled (its edge ramp from 0 V would be endless): the key
    to fix is voltage_V, and no saturated sample count (2**62) is printed."""
    e = refusal(
        tmp_path,
        "name: r\nrate_hz: 500\nsteps:\n  - {kind: hold, voltage_V: 1.0e+300, duration_s: 0.1}\n",
    )
    (issue,) = e.issues
    assert (issue.line, issue.field) == (4, "steps[0].voltage_V")
    assert "would have more samples than the 50000000 allowed" in issue.message
    assert "edge ramp from 0 V to 1e+300 V" in issue.message and str(2**62) not in str(e)


@pytest.mark.parametrize(("volts", "blamed"), [(1e6, "edge_slew_V_per_s"),
                                               (1.000001e6, "steps[0].voltage_V")])  # fmt: skip
def test_a_slow_edge_to_a_sane_voltage_is_blamed_on_the_slew(tmp_path, volts, blamed):
    """At and below 1e6 V the slew rate is what to change; just above it, the voltage."""
    e = refusal(
        tmp_path,
        "name: r\nrate_hz: 500\nedge_slew_V_per_s: 0.001\nsteps:\n"
        f"  - {{kind: hold, voltage_V: {volts!r}, duration_s: 0.1}}\n",
    )
    assert e.issues[0].field == blamed, str(e)
    assert "samples, more than the 50000000 allowed in one entry (its edge ramp" in str(e)


@pytest.mark.parametrize("rate", [1000.0, 1130.0, 5000.0, 10000.0])
@pytest.mark.parametrize("kind", ["sine", "offset_sine", "triangle"])
def test_the_current_limits_do_not_depend_on_the_sample_rate(tmp_path, kind: str, rate: float):
    """A drive 0.1 % under its highest frequency passes and 0.1 % over it is refused at every
    sample rate. The reference is i = C_eff dV/dt on the continuous waveform: a unipolar sine of
    amplitude A peaks at pi C A f and averages 2 C A f over a cycle, a sine around a bias 2 pi C
    A f and 4 C A f, a triangle (swing 2 A, slope 4 A f) 4 C A f for both (the built-in rig's
    C_eff, i_peak_A, i_avg_A). On a grid of 20-80 points a cycle the corners of the triangle
    and the crests of the sine fall between points and read up to 2.5 % low."""
    from labrig.rig.limits import RigLimits

    lim = RigLimits()
    c, a = lim.effective_capacitance_F, 60.0
    peak_per_hz, mean_per_hz = {
        "sine": (math.pi * c * a, 2 * c * a),
        "offset_sine": (2 * math.pi * c * a, 4 * c * a),
        "triangle": (4 * c * a, 4 * c * a),
    }[kind]
    f_max = min(lim.i_peak_A / peak_per_hz, lim.i_avg_A / mean_per_hz)
    bias = "" if kind == "sine" else ", offset_V: 40"
    for f, ok in ((f_max * 0.999, True), (f_max * 1.001, False)):
        if rate / f < 20:
            continue  # too few samples a cycle: refused for that, not for the current
        text = (f"name: r\nrate_hz: {rate!r}\nsteps:\n  - {{kind: {kind}, amplitude_V: {a}"
                f"{bias}, frequency_hz: {f!r}, cycles: 20}}\n")  # fmt: skip
        if ok:
            passes(tmp_path, text)
        else:
            msg = str(refusal(tmp_path, text))
            assert "on average" in msg or "peak" in msg, msg


@pytest.mark.parametrize(
    "step",
    [
        # half and three quarters of a triangle cycle over the cycle's limit: their window's
        # mean is what the grid measures (0.071 and 0.102 A), not the cycle's 0.13 A
        "{kind: triangle, amplitude_V: 50, offset_V: 50, start: low, frequency_hz: 65, "
        "cycles: 0.5}",
        "{kind: triangle, amplitude_V: 50, offset_V: 50, start: low, frequency_hz: 65, "
        "cycles: 0.75}",
    ],
)
def test_less_than_a_cycle_is_judged_by_what_it_draws(tmp_path, step: str):
    passes(tmp_path, f"name: r\nrate_hz: 10000\nsteps:\n  - {step}\n")


def test_a_vanishing_offset_sine_is_judged_by_what_it_draws(tmp_path):
    """Over its constant-amplitude limit, but vanishing: its measured mean stays under the
    average limit (0.095 A against 0.12 A on a rig of 0.30 A peak), so it passes; the same
    sine at constant amplitude is refused."""
    from labrig.rig.limits import RigLimits

    lim = RigLimits(i_peak_A=0.30)
    body = ("name: r\nrate_hz: 10000\nsteps:\n  - {kind: offset_sine, offset_V: 50, "
            "amplitude_V: 50, frequency_hz: 62, cycles: 2, envelope: %s}\n")  # fmt: skip
    p = tmp_path / "p.yaml"
    p.write_text(body % "vanishing")
    check_protocol(p, lim)
    p.write_text(body % "constant")
    with pytest.raises(InputFileError, match="on average"):
        check_protocol(p, lim)
