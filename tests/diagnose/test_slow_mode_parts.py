"""Whether a slow viscoelastic mode can be identified is judged on the record as measured, not
on the parts it was cut into for the folds."""

from __future__ import annotations

import numpy as np

from labrig.analysis.diagnose.procedure import (
    SLOW_MODE_MAX_HZ,
    SLOW_MODE_RECORD_S,
    slow_mode_identifiable,
)
from labrig.analysis.records import Record
from labrig.analysis.split import split_entries, whole_records

RATE = 10_000.0


def _prbs(seconds: float) -> Record:
    n = int(seconds * RATE)
    bits = np.random.default_rng(1).integers(0, 2, n // 50 + 1).repeat(50)[:n]
    v = 20.0 + 60.0 * bits
    return Record.from_arrays("capture", RATE, v, 0.8 * v)


def _sine(seconds: float, f: float) -> Record:
    t = np.arange(int(seconds * RATE)) / RATE
    v = 50.0 + 40.0 * np.sin(2 * np.pi * f * t)
    return Record.from_arrays("sine", RATE, v, 0.8 * v)


def test_a_2_s_prbs_in_four_parts_counts_as_2_s():
    parts = split_entries([_prbs(2.0)], 4)
    assert len(parts) == 4 and all(p.duration_s < SLOW_MODE_RECORD_S for p in parts)
    assert not any(slow_mode_identifiable([p]) for p in parts)  # each part alone: too short
    assert slow_mode_identifiable(parts)  # the capture they were cut from


def test_the_length_bound_on_a_cut_record_just_inside_and_outside():
    inside = split_entries([_prbs(SLOW_MODE_RECORD_S + 0.01)], 4)
    outside = split_entries([_prbs(SLOW_MODE_RECORD_S - 0.01)], 4)
    assert slow_mode_identifiable(inside)
    assert not slow_mode_identifiable(outside)


def test_a_fast_sine_stays_unidentifiable_however_long():
    parts = split_entries([_sine(4.0, 50.0)], 4)
    assert not slow_mode_identifiable(parts)
    slow = split_entries([_sine(4.0, SLOW_MODE_MAX_HZ)], 4)
    assert slow_mode_identifiable(slow)


def test_whole_records_rejoins_the_parts_exactly_and_keeps_other_records():
    rec, other = _prbs(2.0), _sine(0.5, 20.0)
    parts = split_entries([rec], 4)
    joined = whole_records([other, *parts])
    assert [r.name for r in joined] == ["sine", "capture"]
    assert joined[0] is other
    assert np.array_equal(joined[1].voltage_V, rec.voltage_V)
    assert np.array_equal(joined[1].strain_ue, rec.strain_ue)


def test_whole_records_keeps_a_meta_naming_the_rate_and_the_hold():
    """A run's record carries its step's definition in ``meta`` (a sweep's ``rate_hz``...):
    joining its parts passed that as a second ``rate_hz`` (a TypeError: ``labrig diagnose`` of
    any one-entry run file failed so)."""
    rec = Record.from_arrays("capture", RATE, _prbs(2.0).voltage_V, _prbs(2.0).strain_ue, "linear")
    rec.meta.update(rate_hz=5.0, hold="zoh", name="x", kind="prbs")
    joined = whole_records(split_entries([rec], 4))
    assert len(joined) == 1 and joined[0].name == "capture"
    assert joined[0].rate_hz == RATE and joined[0].hold == "linear"
    assert {k: joined[0].meta[k] for k in ("rate_hz", "hold", "name", "kind")} == rec.meta
    assert np.array_equal(joined[0].voltage_V, rec.voltage_V)
    assert joined[0].duration_s == rec.duration_s
