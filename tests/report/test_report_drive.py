"""How a report states an imported entry's drive: a frequency only where the drive repeats,
and the span of what was played."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.report.data import drive_of

RATE = 10_000.0


def _prbs(seed: int = 3, n: int = 20_000, hold: int = 20) -> np.ndarray:
    bits = np.random.default_rng(seed).integers(0, 2, n // hold + 1).repeat(hold)[:n]
    return 20.0 + 60.0 * bits  # 20 or 80 V: a span of 60 V


def test_a_prbs_has_no_drive_frequency_and_its_whole_span():
    v = _prbs()
    rec = Record.from_arrays("prbs", RATE, v, 0.8 * v)
    f, periodic, amplitude = drive_of(rec)
    assert f is None and periodic is False
    assert amplitude == 60.0  # was 0 V: the span of one "period" of a spectral line


@pytest.mark.parametrize("f0", [2.0, 50.0, 100.0])
def test_an_imported_sine_keeps_its_estimated_frequency_and_peak_to_peak(f0):
    t = np.arange(int(RATE)) / RATE  # 1 s
    v = 40.0 + 30.0 * np.sin(2 * np.pi * f0 * t)
    rec = Record.from_arrays("sine", RATE, v, 0.8 * v)
    f, periodic, amplitude = drive_of(rec)
    assert periodic and f == pytest.approx(f0, rel=0.01)
    assert amplitude == pytest.approx(60.0, rel=0.01)


def test_a_stated_frequency_is_kept_even_when_the_drive_does_not_repeat():
    t = np.arange(int(RATE)) / RATE
    v = 100.0 * t * np.sin(2 * np.pi * 5.0 * t)  # a growing envelope at a stated 5 Hz
    rec = Record.from_arrays("grow", RATE, v, 0.8 * v, frequency_hz=5.0)
    f, periodic, amplitude = drive_of(rec)
    assert f == 5.0 and not periodic
    last = v[-2000:]  # its last period: 0.2 s
    assert amplitude == pytest.approx(float(np.ptp(last)), rel=1e-3)
