"""The preflight's shortcut over repeating drives measures what the full scan does.

Where an entry's drive repeats (a sine, a sweep's sines, an offset sine of constant envelope, a
triangle, a hold), :func:`labrig.protocol.preflight.measure` scans its edges and enough points
at each end of the repeating piece, and leaves out the middle
(:func:`labrig.rig.drive_load.repeat_skip`). Its record must be the full scan's
(``measure(..., full=True)``): the peak and window-mean currents to a relative 1e-9, the voltage
range to 1e-9 of the amplitude (the shortcut allows itself ``REPEAT_RTOL`` = 1e-10; the rest is
the full scan's own rounding of late times, under 1e-9 on entries of up to a few million fine
points as here), and so the same refusals. A drive 0.1 % over a limit is refused and 0.1 % under
passes at every rate with the shortcut in use.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from labrig.core.errors import InputFileError
from labrig.protocol.expand import build_plan
from labrig.protocol.plan import Plan, PlannedStep
from labrig.protocol.preflight import (
    OVERSAMPLE,
    continuous_load,
    measure,
    preflight_checks,
    repeat_skips,
)
from labrig.protocol.schema import Protocol
from labrig.rig.drive_load import (
    RANGE_TOL_V,
    REPEAT_RTOL,
    DriveLoad,
    averaging_window_s,
    repeat_span,
    window_points,
)
from labrig.rig.limits import RigLimits

#: wide limits: the figures are compared, nothing is refused
WIDE = RigLimits(v_min_V=-500.0, v_max_V=500.0, i_peak_A=100.0, i_avg_A=100.0)
#: the most fine-grid points an entry compared with the full scan may have (about 0.1 s each)
MOST_POINTS = 2_000_000
CASES = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def plan_of(rate_hz: float, *steps: dict, edge_slew: float = 1000.0) -> Plan:
    """The plan of a protocol with ``steps`` at ``rate_hz`` (no file)."""
    protocol = Protocol.model_validate(
        {"name": "p", "rate_hz": rate_hz, "edge_slew_V_per_s": edge_slew, "steps": list(steps)}
    )
    return build_plan(protocol)


def entry(rate_hz: float, step: dict, edge_slew: float = 1000.0) -> PlannedStep:
    (s,) = plan_of(rate_hz, step, edge_slew=edge_slew).steps
    return s


def left_out(s: PlannedStep) -> int:
    """Fine-grid points the shortcut leaves out of ``s``."""
    fine_rate = s.rate_hz * OVERSAMPLE
    w = window_points(averaging_window_s(s.frequency_hz), fine_rate)
    return sum(hi - lo for lo, hi in repeat_skips(s.waveform, OVERSAMPLE, w))


def fine_points(s: PlannedStep) -> int:
    return (s.n_samples - 1) * OVERSAMPLE + 1


def assert_same_load(short: DriveLoad, full: DriveLoad, scale_V: float) -> None:
    """The shortcut's record is the full scan's: currents to 1e-9, voltages to 1e-9 of
    ``scale_V`` (the drive's amplitude)."""
    assert short.peak_current_A == pytest.approx(full.peak_current_A, rel=1e-9, abs=0)
    assert short.mean_current_A == pytest.approx(full.mean_current_A, rel=1e-9, abs=0)
    assert short.v_max_V == pytest.approx(full.v_max_V, rel=0, abs=1e-9 * scale_V)
    assert short.v_min_V == pytest.approx(full.v_min_V, rel=0, abs=1e-9 * scale_V)
    assert (short.window_s, short.duration_s, short.name) == (
        full.window_s,
        full.duration_s,
        full.name,
    )


def compare(s: PlannedStep, scale_V: float, must_skip: bool = True) -> None:
    """The shortcut and the full scan of ``s`` agree, raw and after the formula currents."""
    if must_skip:
        assert left_out(s) > 0, f"{s.name}: the shortcut left nothing out"
    short, full = measure(s, WIDE), measure(s, WIDE, full=True)
    assert_same_load(short, full, scale_V)
    assert_same_load(continuous_load(s, short, WIDE), continuous_load(s, full, WIDE), scale_V)


# -- entries drawn at random ---------------------------------------------------------------

RATES = st.sampled_from([1000.0, 1130.0, 5000.0, 10000.0, 100000.0])


@st.composite
def points_per_period(draw: st.DrawFn) -> float:
    """Fine points per period ``P``: whole (the grid repeats every period), a fraction ``m +
    a/b`` (every ``b`` periods), or any number (its phases never repeat exactly)."""
    form = draw(st.sampled_from(["whole", "fraction", "any"]))
    if form == "whole":
        return float(draw(st.integers(80, 3000)))
    if form == "fraction":
        b = draw(st.integers(2, 40))
        return draw(st.integers(80, 1500)) + draw(st.integers(1, b - 1)) / b
    return draw(st.floats(80.0, 3000.0, allow_nan=False, allow_infinity=False))


@st.composite
def periodic_entries(draw: st.DrawFn) -> tuple[float, dict, float]:
    """``(rate_hz, step, amplitude)``: a sine, an offset sine of constant envelope, a
    triangle from its bias or its low corner, of whole cycles or not, some starting or ending
    away from 0 V; or a hold."""
    rate = draw(RATES)
    kind = draw(st.sampled_from(["sine", "offset_sine", "triangle", "hold"]))
    a = draw(st.floats(0.5, 150.0))
    if kind == "hold":
        seconds = draw(st.floats(0.01, MOST_POINTS / (OVERSAMPLE * rate)))
        volts = draw(st.sampled_from([-1.0, 1.0])) * a
        return rate, {"kind": "hold", "voltage_V": volts, "duration_s": seconds}, a
    per = draw(points_per_period())
    f = rate * OVERSAMPLE / per
    most_cycles = MOST_POINTS / per
    cycles = draw(st.one_of(st.integers(1, int(most_cycles)), st.floats(1.0, most_cycles)))
    length = {"cycles": cycles}
    if draw(st.booleans()):
        length = {"duration_s": cycles / f}
    step = {"kind": kind, "amplitude_V": a, "frequency_hz": f, **length}
    if kind == "offset_sine":
        step |= {
            "offset_V": draw(st.floats(-100.0, 100.0)),
            "ramp_s": draw(st.sampled_from([0.0, 0.002, 0.05])),
            "settle_s": draw(st.sampled_from([0.0, 0.01, 0.2])),
        }
    elif kind == "triangle":
        step |= {
            "offset_V": draw(st.floats(-100.0, 100.0)),
            "start": draw(st.sampled_from(["bias", "low"])),
        }
    return rate, step, a


@CASES
@given(periodic_entries())
def test_the_shortcut_measures_what_the_full_scan_does(drawn):
    """Random sines, offset sines, triangles and holds (amplitude, frequency as fine points per
    period, rate, length in cycles or seconds, offset, start phase, ramps and settle): the same
    record as every point."""
    rate, step, a = drawn
    s = entry(rate, step)
    assume(left_out(s) > 0)  # long enough to leave something out (most are)
    compare(s, a)


@CASES
@given(
    rate=RATES,
    f=st.floats(0.3, 2000.0),
    a=st.floats(0.5, 100.0),
    seconds=st.floats(0.05, 5.0),
    cycles_or_seconds=st.booleans(),
)
def test_sines_of_any_frequency_are_measured_alike(rate, f, a, seconds, cycles_or_seconds):
    """A unipolar sine at any frequency of at least 20 samples a cycle: whole cycles or a
    duration (then an edge ramp back to 0 V after the last, partial, cycle)."""
    assume(rate / f >= 20 and seconds * rate * OVERSAMPLE <= MOST_POINTS)
    length = (
        {"cycles": max(1, round(seconds * f))} if cycles_or_seconds else {"duration_s": seconds}
    )
    s = entry(rate, {"kind": "sine", "amplitude_V": a, "frequency_hz": f, **length})
    compare(s, a, must_skip=False)


#: entries whose worst point is where a shortcut that measured too little would miss it: grids
#: that repeat only every 2 to 8 periods (one period too few leaves out their phases), ramps and
#: edges at the start (the start left out), partial cycles, a hold and a vanishing envelope's
#: hold
EDGE_CASES = {
    "sine, grid every 2 periods": (10000.0, {"kind": "sine", "amplitude_V": 50,
                                             "frequency_hz": 40000 / 80.5, "cycles": 300}),
    "sine, every 4 periods": (1000.0, {"kind": "sine", "amplitude_V": 50,
                                       "frequency_hz": 4000 / 80.25, "cycles": 300}),
    "sine, every 8 periods": (5000.0, {"kind": "sine", "amplitude_V": 50,
                                       "frequency_hz": 20000 / 83.625, "cycles": 400}),
    "sine ending mid-cycle": (10000.0, {"kind": "sine", "amplitude_V": 70,
                                        "frequency_hz": 40000 / 161.5, "cycles": 250.5}),
    "offset sine, steep ramps": (10000.0, {"kind": "offset_sine", "offset_V": 60,
                                           "amplitude_V": 30, "frequency_hz": 40000 / 80.5,
                                           "cycles": 300, "ramp_s": 0.0003, "settle_s": 0.05}),
    "offset sine, edge ramps": (10000.0, {"kind": "offset_sine", "offset_V": -40,
                                          "amplitude_V": 30, "frequency_hz": 40000 / 100.25,
                                          "cycles": 300, "ramp_s": 0, "settle_s": 0}),
    "triangle from its low corner": (10000.0, {"kind": "triangle", "offset_V": 40,
                                               "amplitude_V": 50, "frequency_hz": 40000 / 80.5,
                                               "cycles": 300, "start": "low"}),
    "triangle, every 3 periods": (1130.0, {"kind": "triangle", "offset_V": -30,
                                           "amplitude_V": 45, "frequency_hz": 4520 / (90 + 1 / 3),
                                           "duration_s": 30.01}),
    "offset sine ending low, steep start": (10000.0, {"kind": "offset_sine", "offset_V": 60,
                                                      "amplitude_V": 30,
                                                      "frequency_hz": 40000 / 80.5,
                                                      "cycles": 300.75, "ramp_s": 0.0004,
                                                      "settle_s": 0.05}),
    "triangle ending low, from its bias": (10000.0, {"kind": "triangle", "offset_V": 50,
                                                     "amplitude_V": 20, "frequency_hz": 125,
                                                     "cycles": 300.75, "start": "bias"}),
    "hold": (1000.0, {"kind": "hold", "voltage_V": 80, "duration_s": 12}),
    "vanishing envelope's hold": (1000.0, {"kind": "vanishing", "amplitude_V": 80,
                                           "frequency_hz": 10, "decay_s": 1, "hold_s": 12}),
}  # fmt: skip


@pytest.mark.parametrize("slew", [1000.0, 1e6])
@pytest.mark.parametrize("name", list(EDGE_CASES))
def test_the_edges_and_every_phase_of_the_grid_are_measured(name, slew):
    """Each case at the default edge slew and at one steep enough for the straight edge ramps
    to draw the most."""
    rate, step = EDGE_CASES[name]
    s = entry(rate, step, edge_slew=slew)
    scale = float(step.get("amplitude_V", step.get("voltage_V", 1.0)))
    compare(s, scale)


# -- the bug: a long sweep at the highest rate -----------------------------------------------


def test_a_long_sweep_at_100_khz_is_measured_from_a_sliver_of_it():
    """15 sines of 499 s at 100 kHz: each entry's scan leaves out all but at most 1 % of its
    2e8 fine points, and its figures are the grid's own in closed form (the whole scan would
    take minutes): ``V`` from 0 to ``A``, cycle mean ``2 C A f``, peak ``pi C A f sin(2 pi/P) /
    (2 pi/P)`` (the central difference over ``P = 4e5/f`` points a period) or up to 3e-8 above
    it: the points kept at the end of the entry carry, as the whole scan's do, the rounding of
    late times (a phase of 3000 rad is rounded by 5e-13 rad, a difference of two voltages 10 V
    apart from 3e-4 V by 1e-8 of it)."""
    sweep = {"kind": "sweep", "amplitudes_V": [20, 50, 80], "frequencies_hz": [1, 5, 10, 20, 40],
             "cycles": 1, "min_duration_s": 499}  # fmt: skip
    plan = plan_of(100000.0, sweep)
    lim = RigLimits()
    c = lim.effective_capacitance_F
    for s, chk in zip(plan.steps, preflight_checks(plan, lim), strict=True):
        assert left_out(s) > 0.99 * fine_points(s)
        a, f = s.amplitude_V, s.frequency_hz
        x = 2 * math.pi * f / 4e5
        raw = measure(s, lim)
        grid = math.pi * c * a * f * math.sin(x) / x
        assert grid * (1 - 1e-9) <= raw.peak_current_A <= grid * (1 + 3e-8)
        assert raw.mean_current_A == pytest.approx(2 * c * a * f, rel=1e-9)
        assert (raw.v_min_V, raw.v_max_V) == (0.0, pytest.approx(a, rel=1e-12))
        formula = math.pi * c * a * f  # what the preflight takes when it is larger
        assert formula <= chk.peak_current_A <= formula * (1 + 3e-8)


# -- the safety margin -----------------------------------------------------------------------

#: a rig whose current limits a sine reaches within the voltage range at 1 kHz and 20 samples
#: a cycle (half the built-in rig's currents)
HALF = RigLimits(i_peak_A=0.09, i_avg_A=0.06)


def highest_amplitude(kind: str, f: float, lim: RigLimits) -> float:
    """The largest amplitude at ``f`` within both current limits: unipolar sine ``pi C A f``
    peak and ``2 C A f`` mean, offset sine ``2 pi C A f`` and ``4 C A f``, triangle ``4 C A f``
    for both."""
    c = lim.effective_capacitance_F
    peak, mean = {"sine": (math.pi, 2.0), "offset_sine": (2 * math.pi, 4.0),
                  "triangle": (4.0, 4.0)}[kind]  # fmt: skip
    return min(lim.i_peak_A / (peak * c * f), lim.i_avg_A / (mean * c * f))


def refused(plan: Plan, lim: RigLimits) -> bool:
    try:
        preflight_checks(plan, lim)
    except InputFileError as e:
        assert "peak" in str(e) or "on average" in str(e) or "reaches" in str(e), str(e)
        return True
    return False


@pytest.mark.parametrize("rate", [1000.0, 1130.0, 10000.0, 100000.0])
@pytest.mark.parametrize("kind", ["sine", "offset_sine", "triangle"])
@pytest.mark.parametrize(("factor", "over"), [(0.999, False), (1.001, True)])
def test_a_drive_a_tenth_of_a_per_cent_over_a_limit_is_refused(rate, kind, factor, over):
    """At 50 Hz (20 samples a cycle at 1 kHz) for 6 s, the shortcut in use: an amplitude 0.1 %
    over the highest the current limits allow is refused, 0.1 % under passes."""
    f = 50.0
    a = highest_amplitude(kind, f, HALF) * factor
    step = {"kind": kind, "amplitude_V": a, "frequency_hz": f, "duration_s": 6.0}
    if kind != "sine":
        step["offset_V"] = 40.0
    plan = plan_of(rate, step)
    assert left_out(plan.steps[0]) > 0.5 * fine_points(plan.steps[0])
    assert refused(plan, HALF) is over


@pytest.mark.parametrize("rate", [5000.0, 100000.0])
@pytest.mark.parametrize(("factor", "over"), [(0.999, False), (1.001, True)])
def test_a_sine_of_any_frequency_a_tenth_of_a_per_cent_over_is_refused(rate, factor, over):
    """The highest frequency of a 60 V sine on the built-in rig (an irrational number of points
    a period: no run of the grid repeats it), 0.1 % under and over, for 8 s (at 100 kHz the
    shortcut leaves out most of it)."""
    lim = RigLimits()
    c = lim.effective_capacitance_F
    f = min(lim.i_peak_A / (math.pi * c * 60), lim.i_avg_A / (2 * c * 60)) * factor
    plan = plan_of(rate, {"kind": "sine", "amplitude_V": 60, "frequency_hz": f, "duration_s": 8})
    if rate == 100000.0:
        assert left_out(plan.steps[0]) > 0.5 * fine_points(plan.steps[0])
    assert refused(plan, lim) is over


@pytest.mark.parametrize("rate", [1000.0, 100000.0])
@pytest.mark.parametrize(("factor", "over"), [(0.999, False), (1.001, True)])
def test_a_hold_a_tenth_of_a_per_cent_over_the_range_is_refused(rate, factor, over):
    plan = plan_of(rate, {"kind": "hold", "voltage_V": 100.0 * factor, "duration_s": 5})
    assert left_out(plan.steps[0]) > 0.3 * fine_points(plan.steps[0])
    assert refused(plan, RigLimits()) is over


# -- how many points stand for a repeating piece -----------------------------------------------


def phases_gap(r: Fraction, q: int) -> float:
    """The widest gap (cycles) the phases ``j r mod 1`` of ``q`` points leave on the circle
    (to about 1e-11)."""
    x = np.sort(np.arange(q) * float(r) % 1.0)
    return float(np.max(np.diff(np.concatenate([x, [x[0] + 1.0]]))))


@settings(max_examples=60, deadline=None)
@given(
    per=st.floats(2.0, 5e5),
    n=st.integers(10, 10**9),
    sinusoid=st.booleans(),
)
def test_a_run_of_points_holds_every_phase_of_the_piece(per, n, sinusoid):
    """``repeat_span``'s run: either every later point repeats one of the run to within the
    drift allowed (any piece), or, for a sinusoid, its phases leave no gap wider than the one
    allowed or drift little enough between the run at each end; never more than half the
    piece."""
    r = Fraction(1.0 / per)
    q = repeat_span(r, n, sinusoid)
    if q is None:
        return
    assert 1 <= q <= n // 2
    off = abs(q * r - round(q * r))
    drift = float(math.ceil(n / q) * off)
    if drift <= REPEAT_RTOL / (2 * math.pi):
        return
    assert sinusoid
    if drift <= math.sqrt(REPEAT_RTOL / 2) / math.pi:
        return
    if q > 2_000_000:
        return  # too many phases to sort here
    deficit = 1 - math.cos(math.pi * phases_gap(r, q))  # a maximum half a gap from a point
    assert deficit <= REPEAT_RTOL * 1.0001


def test_exact_repeats_take_the_grids_period():
    """A grid that repeats every ``q`` points takes ``q``; a constant takes 1; a drive whose
    grid never repeats within half the piece, and is no sinusoid, takes none."""
    r = Fraction(40.0) / Fraction(400000)  # 40 Hz at 100 kHz: 10000 points a period
    assert repeat_span(r, 10**8) == 10000
    assert repeat_span(Fraction(0), 10**8) == 1
    r = Fraction(37.77) / Fraction(40000)  # 37.77 Hz at 10 kHz: every 4e6 points (3777 periods)
    assert repeat_span(r, 10**8) == 4_000_000
    assert repeat_span(r, 7_000_000) is None
    assert repeat_span(r, 7_000_000, sinusoid=True) is not None


def test_a_crest_just_past_the_range_is_refused_as_the_whole_scan_refuses_it() -> None:
    """A review's case: a 100.0000000025 V sine at 38.9474 Hz (10 kHz, 20 s) on the default
    rig (-20 .. 100 V, 1 nV tolerance). The whole scan reaches 100.0000000025 V and refuses it;
    the shortcut's scanned points reached the crest to within 1.4e-6 cycles only (2e-9 V low)
    and passed it. The formula's crest is past the range, so every point is scanned: refused
    with the whole scan's figure. At 100 V exactly (the range's end) the shortcut stands."""
    lim = RigLimits()
    step = {"kind": "sine", "amplitude_V": 100.0000000025, "frequency_hz": 38.9474}
    over = plan_of(10_000.0, {**step, "duration_s": 20})
    (s,) = over.steps
    assert left_out(s) > 0
    full = measure(s, lim, full=True)
    assert full.v_max_V > lim.v_max_V + RANGE_TOL_V  # what the whole scan says
    assert measure(s, lim) == full
    with pytest.raises(InputFileError, match=r"reaches 100\.000000002"):
        preflight_checks(over, lim)
    at_end = plan_of(10_000.0, {**step, "amplitude_V": 100.0, "duration_s": 20})
    (e,) = at_end.steps
    short = measure(e, lim)
    assert left_out(e) > 0 and short.v_max_V <= lim.v_max_V
    preflight_checks(at_end, lim)
