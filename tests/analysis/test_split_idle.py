"""A single record cut into parts for leave-one-entry-out (:func:`labrig.analysis.split.
split_entries`) when it ends with a long hold: the parts are cut over the driven stretch and the
hold stays as the last part's tail, so no part is a hold alone."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.analysis.split import idle_lead, idle_trail, split_entries

RATE = 200.0


def driven_then_held(drive_s: float, hold_s: float) -> Record:
    """A bipolar 1 Hz sine for ``drive_s`` seconds, then 0 V held for ``hold_s`` seconds (the
    strain relaxing towards 0 meanwhile)."""
    t = np.arange(round((drive_s + hold_s) * RATE)) / RATE
    v = np.where(t < drive_s, 150.0 * np.sin(2 * np.pi * t), 0.0)
    s = 0.1 * v + np.where(t < drive_s, 0.0, np.exp(-(t - drive_s)))
    return Record.from_arrays("run", RATE, v, s, hold="linear")


def test_a_long_hold_at_the_end_is_the_last_parts_tail() -> None:
    """4 s of drive then 8 s held (the review's case: two of four parts were holds alone,
    scored in percent of their noise). Every part now has a drive; the samples are all kept,
    in order; the last part ends with the whole hold."""
    rec = driven_then_held(4.0, 8.0)
    parts = split_entries([rec], 4)
    spans = [float(np.ptp(p.voltage_V)) for p in parts]
    assert min(spans) > 0.5 * max(spans), spans
    assert np.array_equal(np.concatenate([p.voltage_V for p in parts]), rec.voltage_V)
    assert np.array_equal(np.concatenate([p.strain_ue for p in parts]), rec.strain_ue)
    assert parts[-1].meta["idle_trail_s"] == pytest.approx(8.0, abs=2 / RATE)
    assert np.all(parts[-1].voltage_V[-round(8.0 * RATE) :] == 0.0)


def test_the_hold_counts_from_half_a_part() -> None:
    """A hold counts when it is longer than half of one of the parts (``n / 8`` for 4 parts):
    with 800 driven samples the edge is a hold of 800 / 7 = 114.3 samples; 115 counts (the parts
    cut over the drive), 114 does not (equal parts, as before)."""
    for h, counts in ((115, True), (114, False)):
        rec = driven_then_held(4.0, h / RATE)
        assert idle_trail(rec, 4) == (h if counts else 0), (h, rec.n)
        assert ("idle_trail_s" in split_entries([rec], 4)[-1].meta) is counts


def test_the_diagnosis_keeps_what_was_done_with_the_holds() -> None:
    """The diagnosis' messages (on diagnosis.html, not only on stderr) say what
    cutting the record did with a hold before and after the drive; a record without holds
    gets no such message."""
    from labrig.analysis.diagnose.procedure import holds_set_aside

    t = np.arange(round(16.0 * RATE)) / RATE
    v = np.where((t >= 4.0) & (t < 8.0), 150.0 * np.sin(2 * np.pi * (t - 4.0)), 0.0)
    rec = Record.from_arrays("both", RATE, v, 0.1 * v, hold="linear")
    first, last = holds_set_aside(split_entries([rec], 4))
    assert "first 4 s" in first and "left out" in first
    assert "last 8 s" in last and "tail" in last
    assert holds_set_aside(split_entries([driven_then_held(4.0, 0.0)], 4)) == []


def test_diagnosis_json_says_what_was_done_with_the_holds() -> None:
    """``diagnosis.json`` (``Diagnosis.to_json()``) carries the same sentences under
    ``messages``: a user reading only the JSON learns that the first 4 s were left out and the
    last 8 s kept as a tail (no candidates are tried, to keep the test short)."""
    from labrig.analysis.diagnose.procedure import diagnose

    t = np.arange(round(16.0 * RATE)) / RATE
    v = np.where((t >= 4.0) & (t < 8.0), 150.0 * np.sin(2 * np.pi * (t - 4.0)), 0.0)
    rec = Record.from_arrays("both", RATE, v, 0.1 * v, hold="linear")
    doc = diagnose(split_entries([rec], 4), effects=[], max_effects=0).to_json()
    said = " ".join(doc["messages"])
    assert "first 4 s" in said and "left out" in said
    assert "last 8 s" in said and "tail" in said


def idle_then_sine(idle_v: np.ndarray, drive_s: float = 4.0) -> Record:
    """``idle_v`` (the idle stretch's voltage samples), then a bipolar 1 Hz 150 V sine."""
    t = np.arange(round(drive_s * RATE)) / RATE
    v = np.concatenate([idle_v, 150.0 * np.sin(2 * np.pi * t)])
    return Record.from_arrays("run", RATE, v, 0.1 * v, hold="linear")


def test_a_noisy_measured_idle_is_found_whatever_its_first_sample() -> None:
    """A measured voltage: 4 s idle at 0 V with 0.4 % of the span of white noise (1.2 V RMS),
    its first sample at +3 sigma. The idle stretch is found (to a few samples: where the sine
    leaves the noise band), not cut at the first sample that strays 1 % of the span from it."""
    rng = np.random.default_rng(5)
    idle = rng.normal(0.0, 1.2, round(4.0 * RATE))
    idle[0] = 3.6
    lead = idle_lead(idle_then_sine(idle))
    assert round(4.0 * RATE) <= lead <= round(4.0 * RATE) + 8, lead


def test_a_record_that_starts_driven_has_no_idle_start() -> None:
    """A sine from the first sample, and a pseudo-random binary drive (its differences are
    mostly 0: the noise estimate is 0 and the band 1 % of the span): no idle start."""
    t = np.arange(round(8.0 * RATE)) / RATE
    sine = Record.from_arrays("sine", RATE, 150 * np.sin(2 * np.pi * t), t, hold="linear")
    bits = np.repeat(np.random.default_rng(2).integers(0, 2, 160), 10) * 100.0
    prbs = Record.from_arrays("prbs", RATE, bits, bits, hold="zoh")
    assert idle_lead(sine) == 0 and idle_lead(prbs) == 0


@pytest.mark.parametrize(("step_pct", "idle"), [(0.9, True), (1.1, False)])
def test_the_band_is_one_percent_of_the_span_for_a_clean_voltage(step_pct, idle) -> None:
    """Exact voltages (no noise): 2 s at 0 V then 2 s at ``step_pct`` % of the span, then the
    sine. 0.9 % stays in the band (4 s idle, and the sine's first sample at 0 V), 1.1 % leaves
    it (2 s idle)."""
    n = round(2.0 * RATE)
    v = np.concatenate([np.zeros(n), np.full(n, step_pct / 100 * 300.0)])
    lead = idle_lead(idle_then_sine(v))
    assert (2 * n <= lead <= 2 * n + 1) if idle else lead == n, lead


@pytest.mark.parametrize(("a_pct", "idle"), [(4.9, True), (5.1, False)])
def test_the_noise_band_is_capped_at_five_percent_of_the_span(a_pct, idle) -> None:
    """An idle stretch flipping between +-a every sample reads as noise of 2.1 a (its band
    10.5 a), but the band is at most 5 % of the span: a = 4.9 % of the span is idle, 5.1 % is a
    drive."""
    n = round(4.0 * RATE)
    a = a_pct / 100 * 300.0
    v = a * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    assert (idle_lead(idle_then_sine(v)) > 0) is idle


def test_the_diagnosis_names_where_its_worst_part_lies_in_the_record() -> None:
    """A diagnosis of a cut record names its worst part with the stretch of the record it
    covers (the record's own time): a user cannot find "run_part3" in their file. 12 s of
    drive at 200 Hz in four parts of whole periods: part 3 is t = 6-9 s; the prediction's
    error is put on that stretch only, so it is the worst."""
    from labrig.analysis.diagnose.evidence import collect_evidence

    rec = driven_then_held(12.0, 0.0)
    parts = split_entries([rec], 4)
    preds = {p.name: p.strain_ue.copy() for p in parts}
    rng = np.random.default_rng(1)
    for p in parts:
        preds[p.name] += 1e-3 * rng.standard_normal(p.n)
    preds["run_part3"] += 0.5 * np.sin(2 * np.pi * 3.0 * parts[2].time_s)
    ev = collect_evidence(parts, preds)
    worst = next(s for s in ev.sentences if s.startswith("worst entry"))
    assert worst.startswith("worst entry run_part3 (t = 6-9 s of run): ")
    assert ev.entries["run_part1"].part_of == "t = 0-3 s of run"
    whole = collect_evidence([rec], {"run": rec.strain_ue + 1e-3})
    assert whole.entries["run"].part_of is None
