"""The drive frequency of a voltage with white noise on it (labrig.analysis.spectra): only bins
where the voltage's spectrum stands DRIVE_FLOOR_RATIO times above its median are candidates, so
differenced noise rising toward Nyquist no longer outweighs a slow drive; on records without
noise the estimate is the one before the rule, to the bit."""

from __future__ import annotations

from pathlib import Path
from unittest.mock import patch

import numpy as np
import pytest

from labrig.analysis import spectra
from labrig.analysis.diagnose import split_entries
from labrig.analysis.diagnose.sparse_ode import decimation
from labrig.analysis.records import Record
from labrig.analysis.spectra import DRIVE_FLOOR_RATIO, estimate_frequency_hz
from labrig.protocol.broadband import prbs_bits

REAL = Path(__file__).resolve().parents[1] / "data" / "real"


def _before_the_rule(voltage: np.ndarray, rate_hz: float) -> float | None:
    """The estimate as it was before the noise-floor rule (the whole rate spectrum's peak): the
    reference the clean records must still give, bit for bit. With the ratio at 0 no bin is
    below the floor (magnitudes are not negative), so the rule keeps every bin."""
    with patch.object(spectra, "DRIVE_FLOOR_RATIO", 0.0):
        return estimate_frequency_hz(voltage, rate_hz)


def _smart_rows() -> np.ndarray:
    """time, displacement, voltage of the real SmartHysteresis record (+-150 V, 1 Hz, 1 kHz)."""
    path = REAL / "chandratue-SmartHysteresis" / "hysteresis_v_150_1hz_2cycles_1khz.csv"
    return np.loadtxt(path, delimiter=",", usecols=(1, 2, 3))


def _smart_5khz(sigma: float = 0.0, seed: int = 1) -> list[Record]:
    """The SmartHysteresis record resampled to 5 kHz and cut into 4 parts (as the review read it),
    with N(0, sigma) V added to the voltage."""
    from scipy.signal import resample_poly

    rows = _smart_rows()
    v, s = (resample_poly(x, 5, 1, padtype="line") for x in (rows[:, 2], rows[:, 1]))
    v = v + np.random.default_rng(seed).normal(0.0, sigma, v.size)
    rec = Record.from_arrays("smart", 5000.0, v, s, hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def _prbs(rate_hz: float = 2000.0) -> np.ndarray:
    """An 8-bit PRBS at a 200 Hz clock, 10 +- 60 V, 1.5 ms edges (experiments/wideband.yaml's)."""
    chip = round(rate_hz / 200.0)
    levels = np.repeat(10.0 + 60.0 * (2.0 * prbs_bits(8, 3, 255) - 1.0), chip)
    edge = np.ones(3) / 3
    return np.convolve(np.concatenate(([10.0], levels)), edge, mode="same")


def _clean_voltages() -> list[tuple[str, np.ndarray, float]]:
    out = []
    for name in ("Model_Vi_Do.dat", "Test_Vi_Do_Di.dat"):
        v = np.loadtxt(REAL / "yan9a-micromanipulator" / name)[:, 0]
        rec = Record.from_arrays(name, 200.0, v, v, hold="linear")
        out += [(name, v, 200.0)] + [(r.name, r.voltage_V, 200.0) for r in split_entries([rec], 4)]
    v = _smart_rows()[:, 2]
    out.append(("smart 1 kHz", v, 1000.0))
    out += [(f"smart 5 kHz {r.name}", r.voltage_V, 5000.0) for r in _smart_5khz()]
    t = np.arange(4000) / 1000.0
    out.append(("bipolar 1 Hz", 150 * np.sin(2 * np.pi * t), 1000.0))
    out.append(("unipolar 7 Hz", 50 * (1 - np.cos(2 * np.pi * 7.0 * t)), 1000.0))
    out.append(("vanishing", np.clip(1 - t / 2.5, 0, None) * 100 * np.sin(2 * np.pi * t), 1000.0))
    ms = sum(np.sin(2 * np.pi * f * t + f) for f in (2, 5, 11, 23, 47, 97))
    out.append(("multisine", 20.0 + 80.0 * ms / np.ptp(ms), 1000.0))
    out.append(("prbs", _prbs(), 2000.0))
    return out


def test_clean_records_give_the_estimate_before_the_rule_to_the_bit() -> None:
    """The real records (micromanipulator whole and in parts, SmartHysteresis at 1 kHz and in
    parts at 5 kHz) and clean synthetic drives (sines, a vanishing envelope, a multisine, the
    wideband protocol's PRBS): the same float as the whole rate spectrum's peak."""
    for name, v, rate in _clean_voltages():
        assert estimate_frequency_hz(v, rate) == _before_the_rule(v, rate), name


@pytest.mark.parametrize("sigma", [0.1, 0.3, 0.5, 1.0, 3.0])
def test_a_noisy_5khz_record_keeps_its_drive(sigma: float) -> None:
    """The review's record: SmartHysteresis at 5 kHz, 4 parts, N(0, sigma) V on the voltage. Each
    part's estimate within 0.5 % of its clean value up to 3 V RMS (0.2 % measured at 3 V), and
    the sparse ODE's decimation that of the clean record; before the rule the parts read
    about 2 kHz from 0.5 V on."""
    clean, noisy = _smart_5khz(), _smart_5khz(sigma)
    for c, n in zip(clean, noisy, strict=True):
        f = estimate_frequency_hz(n.voltage_V, n.rate_hz)
        assert f == pytest.approx(estimate_frequency_hz(c.voltage_V, c.rate_hz), rel=5e-3)
    assert decimation(noisy) == decimation(clean) == 14
    if sigma >= 1.0:
        assert all(_before_the_rule(n.voltage_V, n.rate_hz) > 1000.0 for n in noisy)


@pytest.mark.parametrize("sigma", [0.5, 2.0, 5.0])
def test_a_noisy_whole_sine_reads_its_frequency(sigma: float) -> None:
    """+-150 V at 1 Hz, 2 s at 5 kHz, N(0, sigma) V: 1 Hz within 0.2 % up to 5 V RMS (the whole
    rate spectrum's peak is the noise from 2 V on)."""
    t = np.arange(10_000) / 5000.0
    v = 150 * np.sin(2 * np.pi * t) + np.random.default_rng(2).normal(0.0, sigma, t.size)
    assert estimate_frequency_hz(v, 5000.0) == pytest.approx(1.0, rel=2e-3)
    if sigma >= 2.0:
        assert _before_the_rule(v, 5000.0) > 1000.0


@pytest.mark.parametrize("n", [1_000, 20_000, 200_000])
def test_white_noise_alone_has_no_drive(n: int) -> None:
    """No bin of white noise stands DRIVE_FLOOR_RATIO times above the median (the largest of
    1e5 bins about 4 times): no drive frequency, where the whole rate spectrum gave one."""
    for seed in range(3):
        v = np.random.default_rng(seed).normal(size=n)
        assert estimate_frequency_hz(v, 1000.0) is None
        assert _before_the_rule(v, 1000.0) is not None


def _line_over_noise(ratio: float) -> tuple[np.ndarray, float]:
    """White noise (1 V, 4096 samples at 1 kHz) and a sine on bin 20 scaled so that the
    voltage's Hann spectrum at that bin stands ``ratio`` times above its median; the bin's
    frequency."""
    n, k = 4096, 20
    noise = np.random.default_rng(5).normal(size=n)
    line = np.sin(2 * np.pi * k * np.arange(n) / n)
    w = np.hanning(n)

    def standing(a: float) -> float:
        v = noise + a * line
        mag = np.abs(np.fft.rfft((v - v.mean()) * w))
        return float(mag[k] / np.median(mag[1:]))

    lo, hi = 0.0, 1.0
    while standing(hi) < ratio:
        hi *= 2
    for _ in range(60):  # standing() rises with a once the line dominates the bin
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if standing(mid) < ratio else (lo, mid)
    v = noise + hi * line
    assert standing(hi) == pytest.approx(ratio, rel=1e-6)
    return v, k * 1000.0 / n


def test_the_floor_ratio_just_inside_and_just_outside() -> None:
    """A line standing 2 % above DRIVE_FLOOR_RATIO times the median is the drive; 2 % below it
    is not a candidate, and nothing else is: no drive. (The whole rate spectrum's peak is the
    noise near Nyquist either way.)"""
    v, f = _line_over_noise(1.02 * DRIVE_FLOOR_RATIO)
    assert estimate_frequency_hz(v, 1000.0) == pytest.approx(f, abs=0.5 * 1000.0 / v.size)
    assert _before_the_rule(v, 1000.0) > 250.0
    v, _ = _line_over_noise(0.98 * DRIVE_FLOOR_RATIO)
    assert estimate_frequency_hz(v, 1000.0) is None
