"""The four-waveform stand-in (labrig.studies.waveforms): what its captures are, checked against
the bench's stated physics, and that they go through the CSV importer as written. The captures
through validate and diagnose are measured in benchmarks/bench_waveforms.py."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.load import records_from_run
from labrig.core.errors import InputFileError
from labrig.importers.options import ImportOptions
from labrig.importers.pipeline import import_files
from labrig.studies.waveforms import (
    CAPTURES,
    STAND_IN_EFFECTS,
    capture_records,
    write_captures,
)


@pytest.fixture(scope="module")
def prbs():
    (r,) = capture_records(3, names=["prbs"])
    return r


def test_capture_shape_and_drive(prbs):
    """2 s at 10 kHz, time from 0, a measured (linear-hold) voltage swinging -100..+73 V."""
    assert prbs.rate_hz == 10_000.0 and prbs.strain_ue.size == 20_000
    assert prbs.time_s[0] == 0.0 and prbs.time_s[-1] == pytest.approx(1.9999)
    assert prbs.hold == "linear" and prbs.meta["kind"] == "import"
    # the amplifier monitor: 16-bit over 10 V at 0.025 V/V (0.0122 V per bit) plus 20 mV noise
    assert -100.0 - 0.2 < prbs.voltage_V.min() < -100.0 + 0.2
    assert 73.0 - 0.2 < prbs.voltage_V.max() < 73.0 + 0.2
    # not from rest: the capture starts inside the running drive
    assert abs(prbs.voltage_V[0]) > 10.0


def test_resonance_rings_at_the_bench_frequency(prbs):
    """After each PRBS edge the strain rings at the damped frequency f_n sqrt(1 - zeta^2),
    f_n = sqrt(k / m) / (2 pi) (the bench's stated stack: 20 N/um on 0.35 kg, 1 203 Hz; damping
    0.05): the averaged spectrum of the 4 ms after each edge's 2 ms ramp, on levels held that
    long, each detrended by a quadratic, peaks there within 2 % (its bins are 1.2 Hz)."""
    res = next(e for e in STAND_IN_EFFECTS if e["name"] == "stack_resonance")
    zeta = res["damping_ratio"]
    f_d = math.sqrt(res["stiffness_N_per_um"] * 1e6 / res["mass_kg"]) / (2 * math.pi)
    f_d *= math.sqrt(1 - zeta**2)
    v, s, fs = prbs.voltage_V, prbs.strain_ue, prbs.rate_hz
    n0, n1 = round(2.5e-3 * fs), round(6.5e-3 * fs)
    moving = np.abs(np.diff(v)) > 1.0
    power, used = np.zeros(4097), 0
    for a in np.flatnonzero(moving[1:] & ~moving[:-1]) + 1:
        seg_v, seg = v[a + n0 : a + n1], s[a + n0 : a + n1]
        if seg.size < n1 - n0 or np.ptp(seg_v) > 2.0:
            continue
        t = np.arange(seg.size)
        seg = seg - np.polyval(np.polyfit(t, seg, 2), t)
        power += np.abs(np.fft.rfft(seg * np.hanning(seg.size), 8192)) ** 2
        used += 1
    assert used >= 50
    f = np.fft.rfftfreq(8192, 1 / fs)
    band = f > 300
    peak = f[band][np.argmax(power[band])]
    assert abs(peak / f_d - 1) < 0.02, (peak, f_d)


def test_loop_widens_with_rate():
    """Rate-dependent hysteresis: at equal voltage, the loop of the 100 Hz sine is wider than
    the 50 Hz sine's (viscous slip and the amplifier's corner; width at the bias, in % of the
    span)."""
    widths = {}
    for r in capture_records(5, names=["sine_50Hz", "sine_100Hz"]):
        v, s = r.voltage_V, r.strain_ue
        dv = np.gradient(v)
        near = np.abs(v - CAPTURES[r.name]["offset_V"]) < 3.0
        up, down = s[near & (dv > 0)].mean(), s[near & (dv < 0)].mean()
        widths[r.name] = 100 * (down - up) / np.ptp(s)
    assert widths["sine_50Hz"] > 2.0
    assert widths["sine_100Hz"] > 1.1 * widths["sine_50Hz"], widths


def test_written_csv_imports_as_the_capture(tmp_path: Path):
    """The CSV the study writes is read by the importer (header names and units found) to the
    numbers numpy reads from it, at 10 kHz, as an imported entry."""
    (path,) = write_captures(tmp_path, 2, names=["sine_100Hz"])
    assert path.read_text().splitlines()[0] == "time_s,voltage_V,strain_ue"
    t, v, s = np.loadtxt(path, delimiter=",", skiprows=1).T
    assert t.size == 20_000 and np.ptp(v) > 170.0
    run = tmp_path / "run.h5"
    import_files([path], run, ImportOptions())
    (back,) = records_from_run(run)
    assert back.rate_hz == pytest.approx(10_000.0, rel=1e-9)
    np.testing.assert_allclose(back.voltage_V, v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.strain_ue, s, rtol=0, atol=1e-9)
    assert back.meta["kind"] == "import"


def test_never_replaces_a_file_without_overwrite(tmp_path: Path):
    (tmp_path / "prbs.csv").write_text("keep\n")
    with pytest.raises(InputFileError, match=r"prbs\.csv"):
        write_captures(tmp_path, names=["prbs"])
    assert (tmp_path / "prbs.csv").read_text() == "keep\n"
