"""Preflight: check every concrete step against the rig's limits before any output moves.

For each entry of a plan:

- sample rate within the DAQ's ``rate_min_hz .. rate_max_hz`` (once, for the protocol);
- at least :data:`MIN_SAMPLES_PER_CYCLE` samples per cycle of a sine or envelope carrier (an
  offset sine's too);
- every command value within ``v_min_V .. v_max_V``;
- peak current ``i = C_eff dV/dt`` (``C_eff = capacitance_F * large_signal_factor``) at most
  ``i_peak_A``;
- mean ``|i|`` over a sliding window at most ``i_avg_A``; the window is one carrier cycle for
  sines and envelopes, :data:`AVG_WINDOW_S` otherwise (0 V assumed before the entry starts);
  the mean is the grid's total variation over the window (each interval's own change), and for
  sines, offset sines and triangles of constant amplitude the formula's current when larger
  (:func:`continuous_load`).

The measurement is :func:`labrig.rig.drive_load.measure_load`, one
:class:`~labrig.rig.drive_load.DriveLoad` per entry (the record the controller's
:func:`labrig.control.check_drive` gives too, compared with the limits by its methods): the
current ``i = C_eff dV/dt`` on a grid :data:`OVERSAMPLE` times finer than the output rate
(waveforms are functions of continuous time, so the preflight evaluates them there). For a
unipolar sine of amplitude A and frequency f this gives ``i_peak = pi C_eff A f`` and a
cycle-mean ``2 C_eff A f``, so the highest frequency at amplitude A is ``min(i_peak_A / (pi C_eff
A), i_avg_A / (2 C_eff A))`` (56.17 Hz at 100 V on the default rig). A sine of amplitude A
around a bias (``offset_sine``) gives ``i_peak = 2 pi C_eff A f`` and a cycle-mean ``4 C_eff A
f`` (:func:`max_offset_sine_frequency_hz`); its raised-cosine ramps are measured with the rest,
and their current scales as ``1 / ramp_s``.

Where a drive repeats between its edges (a sine, an offset sine of constant envelope, a
triangle, a hold), the scan keeps the edges and enough points at each end of the repeating piece
to hold every phase its other points have, and leaves out the middle (:func:`repeat_skips`,
:func:`labrig.rig.drive_load.repeat_skip`): a 499 s sine at 100 kHz is measured from at most a
few million of its 2e8 fine points (4e4 at 40 Hz), its figures the full scan's to ``1e-10`` of
their scale.

Numbers in the messages are printed by :mod:`labrig.core.numbers`: a value over a limit
never prints as the limit, and a huge one never prints with hundreds of digits.

Problems are collected for all entries and raised together as :class:`InputFileError`, each
naming the protocol file, line and field that produced the step, and what would be valid.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.numbers import amps, at_least, at_most, beyond, exact, fixed_down
from labrig.protocol.plan import Plan, PlannedStep, Where
from labrig.protocol.schema import STRAIN_KINDS
from labrig.protocol.waveforms import Waveform
from labrig.rig.drive_load import (
    AVG_WINDOW_S,
    CHUNK,
    OVERSAMPLE,
    DriveLoad,
    averaging_window_s,
    measure_load,
    repeat_skip,
    window_points,
)
from labrig.rig.limits import RigLimits

__all__ = [
    "AVG_WINDOW_S",
    "BROADBAND_KINDS",
    "MIN_SAMPLES_PER_CYCLE",
    "OVERSAMPLE",
    "max_offset_sine_frequency_hz",
    "max_sine_amplitude_V",
    "max_sine_frequency_hz",
    "max_triangle_frequency_hz",
    "measure",
    "preflight",
    "preflight_checks",
    "sine_currents_A",
]

#: fewest samples per cycle of a sine or envelope carrier
MIN_SAMPLES_PER_CYCLE = 20
_TOL = 1e-9


def max_sine_frequency_hz(amplitude_V: float, limits: RigLimits) -> float:
    """Highest frequency of a unipolar sine of ``amplitude_V`` within both current limits."""
    c = limits.effective_capacitance_F
    return min(
        limits.i_peak_A / (math.pi * c * amplitude_V), limits.i_avg_A / (2.0 * c * amplitude_V)
    )


def max_sine_amplitude_V(frequency_hz: float, limits: RigLimits) -> float:
    """Largest unipolar-sine amplitude at ``frequency_hz`` within the current and voltage limits."""
    c = limits.effective_capacitance_F
    return min(
        limits.v_max_V,
        limits.i_peak_A / (math.pi * c * frequency_hz),
        limits.i_avg_A / (2.0 * c * frequency_hz),
    )


def max_offset_sine_frequency_hz(amplitude_V: float, limits: RigLimits) -> float:
    """Highest frequency of a sine of amplitude ``amplitude_V`` around any offset (constant
    envelope) within both current limits: ``min(i_peak / (2 pi C A), i_avg / (4 C A))``."""
    c = limits.effective_capacitance_F
    return min(
        limits.i_peak_A / (2.0 * math.pi * c * amplitude_V),
        limits.i_avg_A / (4.0 * c * amplitude_V),
    )


def sine_currents_A(amplitude_V: float, frequency_hz: float, limits: RigLimits) -> tuple:
    """``(peak, cycle-mean)`` current of a unipolar sine (A)."""
    c = limits.effective_capacitance_F
    return math.pi * c * amplitude_V * frequency_hz, 2.0 * c * amplitude_V * frequency_hz


def repeat_skips(wave: Waveform, oversample: int, window: int) -> list[tuple[int, int]]:
    """The fine-grid points of ``wave`` that need not be scanned: in each piece that repeats
    (:attr:`~labrig.protocol.waveforms.Segment.repeat_hz`: a sine, an offset sine of constant
    envelope, a triangle, a hold), the points between enough of its start and of its end
    (:func:`labrig.rig.drive_load.repeat_skip`; its phase per fine point is ``f / (rate_hz
    oversample)`` cycles, exactly). The fine points ``a oversample .. b oversample - 1`` of a
    piece of samples ``a .. b`` take its values, but the first and the last point of the
    waveform, which are 0 V exactly.

    Parameters
    ----------
    wave : Waveform
        The entry's waveform.
    oversample : int
        Fine-grid points per sample interval.
    window : int
        The mean current's window (fine points).

    Returns
    -------
    list of tuple of int
        ``[lo, hi)`` ranges of fine points, in order.
    """
    return [skip for skip, _ in _repeating(wave, oversample, window)]


def _repeating(
    wave: Waveform, oversample: int, window: int
) -> list[tuple[tuple[int, int], tuple[float, float] | None]]:
    """:func:`repeat_skips`, each range with the extremes of its piece (V:
    :attr:`~labrig.protocol.waveforms.Segment.extremes`)."""
    fine_rate = Fraction(wave.rate_hz) * oversample
    last = (wave.n_samples - 1) * oversample
    out = []
    for start, seg in wave.pieces():
        if seg.repeat_hz is None:
            continue
        first, stop = max(start * oversample, 1), min((start + seg.n) * oversample, last)
        r = Fraction(seg.repeat_hz) / fine_rate
        found = repeat_skip(first, stop, r, window, seg.sinusoid)
        if found is not None:
            out.append((found, seg.extremes))
    return out


def _range_undecided(
    load: DriveLoad, reach: list[tuple[float, float] | None], limits: RigLimits
) -> bool:
    """Whether the shortcut's voltage range (``load``: the scanned points) passes ``limits``
    while the formula's extremes of the pieces it left out (``reach``: at least what any
    left-out point reaches) do not. The scanned points reach a crest between them only to
    within the shortcut's allowance (``REPEAT_RTOL`` of the amplitude, 5 nV at 100 V), which
    the range's 1 nV tolerance does not cover; there the whole scan decides. A drive whose
    formula stays within the range (an amplitude at the range's end included) never needs it."""
    if load.beyond_range(limits) is not None:
        return False  # the whole scan reaches at least what its subset of points reaches
    lows = [lo for lo, _ in filter(None, reach)]
    highs = [hi for _, hi in filter(None, reach)]
    widened = dataclasses.replace(
        load, v_min_V=min([load.v_min_V, *lows]), v_max_V=max([load.v_max_V, *highs])
    )
    return widened.beyond_range(limits) is not None


def measure(
    step: PlannedStep,
    limits: RigLimits,
    oversample: int = OVERSAMPLE,
    chunk: int = CHUNK,
    *,
    full: bool = False,
) -> DriveLoad:
    """What one entry asks of the amplifier (:func:`labrig.rig.drive_load.measure_load` on its
    waveform, ``chunk`` fine-grid points at a time: never the whole fine grid at once; times from
    the entry's start). The middle of a repeating piece is left out (:func:`repeat_skips`): its
    figures are those of its ends, to ``REPEAT_RTOL`` of their scale; where that allowance could
    turn a refusal of the voltage range into a pass, every point is scanned
    (:func:`_range_undecided`); ``full``: scan every fine point (the reference the shortcut is
    tested against)."""
    wave = step.waveform
    fine_rate = step.rate_hz * oversample
    w = window_points(averaging_window_s(step.frequency_hz), fine_rate)

    def voltage(lo: int, hi: int) -> np.ndarray:
        return wave.at_index(np.arange(lo, hi, dtype=float) / oversample)

    n_points = (wave.n_samples - 1) * oversample + 1
    pieces = [] if full else _repeating(wave, oversample, w)
    load = measure_load(
        voltage,
        n_points,
        fine_rate,
        limits,
        w,
        chunk,
        duration_s=step.duration_s,
        name=step.name,
        skip=[skip for skip, _ in pieces],
    )
    if pieces and _range_undecided(load, [reach for _, reach in pieces], limits):
        return measure(step, limits, oversample, chunk, full=True)
    return load


def continuous_load(step: PlannedStep, chk: DriveLoad, limits: RigLimits) -> DriveLoad:
    """``chk`` with its peak and mean currents raised to what the waveform's formula gives, for
    the kinds of constant amplitude that have one (unipolar sine ``pi C A f`` and ``2 C A f``,
    offset sine ``2 pi C A f`` and ``4 C A f``, triangle ``4 C A f`` for both), when the entry
    holds at least one whole cycle at constant amplitude (an envelope that grows or vanishes,
    or half a cycle, never draws the cycle's mean: the grid's value stands). The fine grid
    reads a triangle's corner or a sine's crest between its points a little low (a triangle at
    20 samples a cycle by up to 2.5 %), so without this the verdict near a limit would depend on
    the sample rate."""
    d = step.definition if isinstance(step.definition, dict) else {}
    a, f, cycles = d.get("amplitude_V"), step.frequency_hz, d.get("cycles")
    if not isinstance(a, int | float) or not f:
        return chk
    if d.get("envelope", "constant") != "constant":
        return chk  # a growing or vanishing envelope reaches the formula's current nowhere
    if not isinstance(cycles, int | float) or cycles < 1:
        return chk  # under a period the window's mean is not the cycle's (half a triangle)
    if step.kind not in ("sine", "offset_sine", "triangle"):
        return chk
    peak, mean = sine_currents_A(a, f, limits)
    if step.kind == "offset_sine":  # the swing is 2 A, not A
        peak, mean = 2.0 * peak, 2.0 * mean
    elif step.kind == "triangle":  # a slope of 4 A f throughout
        peak = mean = 4.0 * limits.effective_capacitance_F * a * f
    return dataclasses.replace(
        chk,
        peak_current_A=max(chk.peak_current_A, peak),
        mean_current_A=max(chk.mean_current_A, mean),
    )


def _blame_segment(step: PlannedStep, t_s: float) -> tuple[Where, str]:
    seg = step.waveform.segment_at(t_s * step.rate_hz)
    if seg.role == "edge":
        return step.blame("edge_slew_V_per_s"), "edge"
    return step.blame(seg.field or "step"), seg.kind


def _samples_per_cycle_issue(
    step: PlannedStep, f: float | None, lim: RigLimits | None = None
) -> tuple[Where, str] | None:
    """Too few samples per cycle of a carrier at ``f`` (Hz; ``None``: not periodic); the
    remedy offered is a rate the rig's DAQ can take (``lim``), or else a lower frequency."""
    if not (f and step.rate_hz / f < MIN_SAMPLES_PER_CYCLE - _TOL):
        return None
    per_cycle = beyond(step.rate_hz / f, MIN_SAMPLES_PER_CYCLE)
    needed = MIN_SAMPLES_PER_CYCLE * f
    lower = f"lower frequency_hz to <= {at_most(step.rate_hz / MIN_SAMPLES_PER_CYCLE)}"
    if lim is not None and needed > lim.rate_max_hz:
        remedy = f"{lower} (the rig's DAQ runs at most {lim.rate_max_hz:g} Hz)"
    else:
        remedy = f"raise rate_hz to >= {at_least(needed)} or {lower}"
    return (
        step.blame("frequency_hz"),
        f"{beyond(f, step.rate_hz / MIN_SAMPLES_PER_CYCLE)} Hz sampled at rate_hz "
        f"{step.rate_hz:g} gives {per_cycle} samples per cycle; "
        f"at least {MIN_SAMPLES_PER_CYCLE} are needed: {remedy}",
    )


def _rig_range(lim: RigLimits) -> str:
    return f"the rig allows {exact(lim.v_min_V)} to {exact(lim.v_max_V)} V"


def _beyond_range(bad: float, too_high: bool, lim: RigLimits) -> str:
    """The voltage out of range, printed so that it reads as out of range."""
    return beyond(bad, lim.v_max_V if too_high else lim.v_min_V)


def _strain_issues(step: PlannedStep, chk: DriveLoad, lim: RigLimits) -> list[tuple[Where, str]]:
    """Limits of a strain-command entry: its computed drive is checked like any waveform;
    the messages say which command and control need it and what to change."""
    out: list[tuple[Where, str]] = []
    d = step.definition
    c = lim.effective_capacitance_F
    key = "path" if step.kind == "strain_csv" else "amplitude_ue"
    if step.kind == "strain_csv":
        what = f"the {d['control']} drive of {step.name}"
    else:
        what = f"the {d['control']} drive for {d['amplitude_ue']:g} ue at {d['frequency_hz']:g} Hz"
    lower = "lower amplitude_ue or frequency_hz" if key == "amplitude_ue" else "check the file"
    outside = chk.beyond_range(lim)
    if outside is not None:
        hi, bad = outside
        why = (
            ""
            if hi
            else " (compensation goes below 0 V to cancel the drift; the amplifier's negative "
            "range limits how much)"
        )
        out.append(
            (
                step.blame(key),
                f"{what} reaches {_beyond_range(bad, hi, lim)} V; {_rig_range(lim)}{why}; "
                + ("lower amplitude_ue" if key == "amplitude_ue" else "check the file"),
            )
        )
    f = step.frequency_hz
    cycles = _samples_per_cycle_issue(step, f, lim)
    if cycles is not None:
        out.append(cycles)
    if chk.over_peak(lim):
        where, seg = _blame_segment(step, chk.peak_time_s)
        need = amps(chk.peak_current_A, lim.i_peak_A)
        if seg == "edge":
            msg = (
                f"the 0 V edge ramp at the end of {step.name} needs {need} peak; the amplifier "
                f"gives {amps(lim.i_peak_A)}; use edge_slew_V_per_s <= {at_most(lim.i_peak_A / c)}"
            )
        else:
            msg = (
                f"{what} needs {need} peak at t = {chk.peak_time_s:.4g} s; the amplifier "
                f"gives {amps(lim.i_peak_A)}; {lower}"
            )
        out.append((where, msg))
    if chk.over_mean(lim):
        where = step.blame(key)
        window = "a cycle" if f else f"{chk.window_s:g} s"
        out.append(
            (
                where,
                f"{what} draws {amps(chk.mean_current_A, lim.i_avg_A)} on average over "
                f"{window} (around t = {chk.mean_time_s:.4g} s); the amplifier's average limit "
                f"is {amps(lim.i_avg_A)}; {lower}",
            )
        )
    return out


def _voltage_range_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, what: str | None
) -> tuple[Where, str] | None:
    """A voltage step outside the rig's range, blamed on the key that sets the voltage
    (``what``: the periodic step's description, ``None`` for the others)."""
    outside = chk.beyond_range(lim)
    if outside is None:
        return None
    _, bad = outside
    key = {"sine": "amplitude_V", "vanishing": "amplitude_V", "hold": "voltage_V"}.get(
        step.kind, "path"
    )
    hint = ""
    if step.kind == "ramp":
        to = step.definition["to_V"]
        key = "to_V" if (to > lim.v_max_V or to < lim.v_min_V) else "from_V"
    if key == "amplitude_V":
        hint = f"; use amplitude_V <= {exact(lim.v_max_V)}"
    elif step.kind == "csv":
        hint = " (check column and scale)"
    hi = outside[0]
    return (
        step.blame(key),
        f"{what if what is not None else step.kind + ' ' + step.name} reaches "
        f"{_beyond_range(bad, hi, lim)} V; {_rig_range(lim)}{hint}",
    )


def _peak_current_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, periodic: bool, what: str
) -> tuple[Where, str]:
    """The message for a voltage step over the peak current: what to change, by step kind."""
    c = lim.effective_capacitance_F
    a, f = step.amplitude_V, step.frequency_hz
    where, seg = _blame_segment(step, chk.peak_time_s)
    need = amps(chk.peak_current_A, lim.i_peak_A)
    gives = f"the amplifier gives {amps(lim.i_peak_A)}"
    if seg == "edge":
        msg = (
            f"the 0 V edge ramps of {step.name} need {need} peak; {gives}; use "
            f"edge_slew_V_per_s <= {at_most(lim.i_peak_A / c)}"
        )
    elif step.kind == "vanishing" and sine_currents_A(a, f, lim)[0] <= lim.i_peak_A:
        where = step.blame("length")
        msg = (
            f"the envelope of {what} falls too fast: it needs {need} peak; {gives}; "
            "make decay_s (or tau_s) longer"
        )
    elif periodic:
        msg = (
            f"{what} needs {need} peak; {gives}; max frequency at {a:g} V is "
            f"{fixed_down(max_sine_frequency_hz(a, lim), 1)} Hz (max amplitude at {f:g} Hz is "
            f"{fixed_down(max_sine_amplitude_V(f, lim), 1)} V)"
        )
    elif step.kind == "ramp":
        d = step.definition
        dv = abs(d["to_V"] - d["from_V"])
        msg = (
            f"the ramp {d['from_V']:g} -> {d['to_V']:g} V in {d['duration_s']:g} s needs "
            f"{need}; {gives}; use duration_s >= {at_least(dv * c / lim.i_peak_A)} s"
        )
    else:
        msg = (
            f"{step.kind} {step.name} needs {need} peak at t = {chk.peak_time_s:.4g} s; "
            f"{gives}; its slope may be at most {at_most(lim.i_peak_A / c)} V/s"
        )
    return where, msg


def _mean_current_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, periodic: bool, what: str
) -> tuple[Where, str]:
    """The message for a voltage step over the mean current."""
    where, _seg = _blame_segment(step, chk.mean_time_s)
    draws = f"draws {amps(chk.mean_current_A, lim.i_avg_A)} on average over"
    if periodic:
        a = step.amplitude_V
        where = step.blame("frequency_hz")
        msg = (
            f"{what} {draws} a cycle; the "
            f"amplifier's average limit is {amps(lim.i_avg_A)}; max frequency at {a:g} V "
            f"is {fixed_down(max_sine_frequency_hz(a, lim), 1)} Hz"
        )
    else:
        msg = (
            f"{step.kind} {step.name} {draws} "
            f"{chk.window_s:g} s (around t = {chk.mean_time_s:.4g} s); the amplifier's "
            f"average limit is {amps(lim.i_avg_A)}"
        )
    return where, msg


def _offset_sine_range_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, what: str
) -> tuple[Where, str] | None:
    """An offset sine outside the rig's range: blamed on ``offset_V`` when the bias itself is
    outside, else on ``amplitude_V`` with the largest amplitude around that bias."""
    outside = chk.beyond_range(lim)
    if outside is None:
        return None
    hi, bad = outside
    v0 = step.definition["offset_V"]
    if not lim.v_min_V <= v0 <= lim.v_max_V:
        return step.blame("offset_V"), f"offset_V {exact(v0)} V is out of range: {_rig_range(lim)}"
    room = min(lim.v_max_V - v0, v0 - lim.v_min_V)
    return (
        step.blame("amplitude_V"),
        f"{what} reaches {_beyond_range(bad, hi, lim)} V; {_rig_range(lim)}; around "
        f"offset_V {exact(v0)} use amplitude_V <= {at_most(room)}",
    )


def _offset_sine_current_issues(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, what: str
) -> list[tuple[Where, str]]:
    """An offset sine over the peak or mean current: its ramps (ramp_s), its edge ramps or the
    sine itself (frequency_hz, with the highest frequency at its amplitude)."""
    out: list[tuple[Where, str]] = []
    a, ramp_s = step.amplitude_V, step.definition["ramp_s"]
    f_max = fixed_down(max_offset_sine_frequency_hz(a, lim), 1)
    gives = f"the amplifier gives {amps(lim.i_peak_A)}"
    if chk.over_peak(lim):
        where, seg = _blame_segment(step, chk.peak_time_s)
        need = amps(chk.peak_current_A, lim.i_peak_A)
        if seg == "edge":
            c = lim.effective_capacitance_F
            msg = f"the 0 V edge ramps of {step.name} need {need} peak; {gives}; use "
            msg += f"edge_slew_V_per_s <= {at_most(lim.i_peak_A / c)} (or ramp_s > 0)"
        elif seg == "raised_cosine":
            longer = at_least(ramp_s * chk.peak_current_A / lim.i_peak_A)
            msg = f"the ramps of {what} need {need} peak; {gives}; use ramp_s >= {longer}"
        else:
            msg = f"{what} needs {need} peak; {gives}; max frequency at {a:g} V is {f_max} Hz"
        out.append((where, msg))
    if chk.over_mean(lim):
        where, seg = _blame_segment(step, chk.mean_time_s)
        draws = f"draws {amps(chk.mean_current_A, lim.i_avg_A)} on average over a cycle"
        limit = f"the amplifier's average limit is {amps(lim.i_avg_A)}"
        if seg in ("raised_cosine", "edge"):
            out.append((where, f"the ramps of {what} {draws}; {limit}; make them longer"))
        else:
            where = step.blame("frequency_hz")
            msg = f"{what} {draws}; {limit}; max frequency at {a:g} V is {f_max} Hz"
            out.append((where, msg))
    return out


def _offset_sine_issues(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits
) -> list[tuple[Where, str]]:
    """Every limit an offset sine breaks (range, samples per cycle, currents)."""
    d = step.definition
    what = f"{step.amplitude_V:g} V at {step.frequency_hz:g} Hz around {d['offset_V']:g} V"
    found = [
        _offset_sine_range_issue(step, chk, lim, what),
        _samples_per_cycle_issue(step, step.frequency_hz, lim),
    ]
    return [x for x in found if x is not None] + _offset_sine_current_issues(step, chk, lim, what)


#: step kinds around a bias checked by :func:`_broadband_issues`
BROADBAND_KINDS = ("triangle", "prbs", "multisine")


def max_triangle_frequency_hz(amplitude_V: float, limits: RigLimits) -> float:
    """Highest frequency of a triangle of amplitude ``amplitude_V`` (swing ``2 A``) within both
    current limits: its slope is ``4 A f`` throughout, so ``min(i_peak, i_avg) / (4 C_eff A)``."""
    c = limits.effective_capacitance_F
    return min(limits.i_peak_A, limits.i_avg_A) / (4.0 * c * amplitude_V)


def _broadband_what(step: PlannedStep) -> str:
    d = step.definition
    around = f"around {d['offset_V']:g} V"
    if step.kind == "triangle":
        return f"the {d['amplitude_V']:g} V, {d['frequency_hz']:g} Hz triangle {around}"
    if step.kind == "prbs":
        return f"the +-{d['amplitude_V']:g} V prbs {around} at {d['clock_hz']:g} Hz"
    return f"the {d['amplitude_V']:g} V multisine {around}"


def _broadband_peak_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, what: str
) -> tuple[Where, str]:
    c = lim.effective_capacitance_F
    d = step.definition
    a = d["amplitude_V"]
    where, seg = _blame_segment(step, chk.peak_time_s)
    need = amps(chk.peak_current_A, lim.i_peak_A)
    gives = f"the amplifier gives {amps(lim.i_peak_A)}"
    if seg == "edge":
        return where, (
            f"the 0 V edge ramps of {step.name} need {need} peak; {gives}; use "
            f"edge_slew_V_per_s <= {at_most(lim.i_peak_A / c)}"
        )
    if step.kind == "triangle":
        f_max = fixed_down(max_triangle_frequency_hz(a, lim), 1)
        return step.blame("frequency_hz"), (
            f"{what} needs {need} peak (4 C_eff A f); {gives}; max frequency at {a:g} V is "
            f"{f_max} Hz"
        )
    if step.kind == "prbs":
        shortest = at_least(2.0 * a * c / lim.i_peak_A)
        return step.blame("transition_s"), (
            f"each {2 * a:g} V level change of {what} in {d['transition_s']:g} s needs {need} "
            f"peak (2 C_eff A / transition_s); {gives}; use transition_s >= {shortest}"
        )
    return step.blame("amplitude_V"), (
        f"{what} needs {need} peak; {gives}; the current scales with amplitude_V: use "
        f"amplitude_V <= {at_most(a * lim.i_peak_A / chk.peak_current_A)} or lower frequencies"
    )


def _broadband_mean_issue(
    step: PlannedStep, chk: DriveLoad, lim: RigLimits, what: str
) -> tuple[Where, str]:
    d = step.definition
    a = d["amplitude_V"]
    window = "a cycle" if step.frequency_hz else f"{chk.window_s:g} s"
    draws = f"{what} draws {amps(chk.mean_current_A, lim.i_avg_A)} on average over {window}"
    limit = f"the amplifier's average limit is {amps(lim.i_avg_A)}"
    if step.kind == "triangle":
        f_max = fixed_down(max_triangle_frequency_hz(a, lim), 1)
        return step.blame("frequency_hz"), (
            f"{draws}; {limit}; max frequency at {a:g} V is {f_max} Hz"
        )
    if step.kind == "prbs":
        return step.blame("clock_hz"), (
            f"{draws} (each level change carries 2 C_eff A); {limit}; lower clock_hz or amplitude_V"
        )
    return step.blame("amplitude_V"), (
        f"{draws}; {limit}; use amplitude_V <= "
        f"{at_most(a * lim.i_avg_A / chk.mean_current_A)} or lower frequencies"
    )


def _broadband_issues(step: PlannedStep, chk: DriveLoad, lim: RigLimits) -> list[tuple[Where, str]]:
    """Every limit a triangle, prbs or multisine breaks (range, samples per cycle, currents),
    each blamed on the key to change with the value that would pass."""
    what = _broadband_what(step)
    found = [_offset_sine_range_issue(step, chk, lim, what)]
    if step.kind == "triangle":
        found.append(_samples_per_cycle_issue(step, step.frequency_hz, lim))
    elif step.kind == "multisine":
        f_hi = max(step.definition["frequencies_hz"])
        cycles = _samples_per_cycle_issue(step, f_hi, lim)
        if cycles is not None:
            found.append((step.blame("frequencies_hz"), cycles[1]))
    if chk.over_peak(lim):
        found.append(_broadband_peak_issue(step, chk, lim, what))
    if chk.over_mean(lim):
        found.append(_broadband_mean_issue(step, chk, lim, what))
    return [x for x in found if x is not None]


def _step_issues(step: PlannedStep, chk: DriveLoad, lim: RigLimits) -> list[tuple[Where, str]]:
    """Every limit ``step`` breaks, in the order: voltage range, samples per cycle, peak
    current, mean current."""
    if step.kind in STRAIN_KINDS:
        return _strain_issues(step, chk, lim)
    if step.kind == "offset_sine":
        return _offset_sine_issues(step, chk, lim)
    if step.kind in BROADBAND_KINDS:
        return _broadband_issues(step, chk, lim)
    a, f = step.amplitude_V, step.frequency_hz
    periodic = step.kind in ("sine", "vanishing") and a is not None and f is not None
    what = f"{a:g} V at {f:g} Hz" if periodic else f"entry {step.name}"
    found = [
        _voltage_range_issue(step, chk, lim, what if periodic else None),
        _samples_per_cycle_issue(step, f if periodic else None, lim),
        _peak_current_issue(step, chk, lim, periodic, what) if chk.over_peak(lim) else None,
        _mean_current_issue(step, chk, lim, periodic, what) if chk.over_mean(lim) else None,
    ]
    return [x for x in found if x is not None]


def preflight_checks(plan: Plan, limits: RigLimits) -> list[DriveLoad]:
    """Check every entry of ``plan`` against ``limits``; the plan is left as it is.

    Returns one :class:`DriveLoad` per entry; raises :class:`InputFileError` listing every
    problem found (a rate outside the DAQ's range alone: the samples at it would tell nothing).
    """
    found: list[tuple[Where, str]] = []
    rate = plan.rate_hz
    if not limits.rate_min_hz <= rate <= limits.rate_max_hz:
        nearest = limits.rate_min_hz if rate < limits.rate_min_hz else limits.rate_max_hz
        found.append(
            (
                plan.where(("rate_hz",)),
                f"rate_hz {beyond(rate, nearest)} is outside the rig's DAQ range "
                f"{limits.rate_min_hz:g} to "
                f"{limits.rate_max_hz:g} Hz",
            )
        )
    checks = []
    for step in [] if found else plan.steps:
        chk = continuous_load(step, measure(step, limits), limits)
        checks.append(chk)
        found.extend(_step_issues(step, chk, limits))
    issues, seen = [], set()
    for w, msg in found:
        if (w.line, w.field, msg) not in seen:
            seen.add((w.line, w.field, msg))
            issues.append(InputIssue(plan.file, w.line, w.field, msg))
    if issues:
        raise InputFileError(issues)
    return checks


def preflight(plan: Plan, limits: RigLimits | None = None) -> list[DriveLoad]:
    """:func:`preflight_checks` against ``limits`` (default: the built-in rig's), handing the
    results to the plan (:meth:`Plan.take_checks`) for callers that read them from it
    (``labrig.runner.execute.preflight``). Returns the checks; raises :class:`InputFileError`."""
    lim = limits if limits is not None else RigLimits()
    checks = preflight_checks(plan, lim)
    plan.take_checks(checks, lim)
    return checks
