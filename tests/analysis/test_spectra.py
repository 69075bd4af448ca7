"""Drive frequency, harmonics and lines on the records real benches make: a bias with a ramp to
it, rests, growing and vanishing envelopes, bipolar drives (labrig.analysis.spectra)."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.analysis.spectra import (
    detect_mains_hz,
    estimate_frequency_hz,
    is_harmonic,
    spectral_lines,
)

RATE = 1000.0


def _biased_growing(
    f: float, seconds: float = 4.0, bias: float = -90.0, before_s: float = 0.0
) -> np.ndarray:
    """``before_s`` at 0 V, a 0.5 s raised-cosine ramp to the bias, 1 s held, then a sine whose
    envelope grows from zero over the rest (the captures of the issue)."""
    ramp = bias * 0.5 * (1 - np.cos(np.pi * np.arange(500) / 500))
    hold = np.full(1000, bias)
    t = np.arange(round(seconds * RATE)) / RATE
    sine = bias + 60 * (t / t[-1]) * np.sin(2 * np.pi * f * t)
    return np.concatenate([np.zeros(round(before_s * RATE)), ramp, hold, sine])


@pytest.mark.parametrize("before_s", [0.0, 2.0])
@pytest.mark.parametrize("f", [20.0, 40.0, 100.0])
def test_drive_frequency_of_a_biased_growing_envelope(f: float, before_s: float) -> None:
    """With the capture starting before the bias is applied, the step to the bias outweighs the
    drive at the voltage spectrum's lowest bins; the drive is found all the same."""
    v = _biased_growing(f, before_s=before_s)
    assert estimate_frequency_hz(v, RATE) == pytest.approx(f, rel=5e-3)


def test_drive_frequency_with_rests_and_bipolar_drives() -> None:
    t = np.arange(3000) / RATE
    rest = np.zeros(2000)
    sine = 50 * (1 - np.cos(2 * np.pi * 5.0 * t))
    assert estimate_frequency_hz(np.concatenate([rest, sine, rest]), RATE) == pytest.approx(
        5.0, rel=5e-3
    )
    bipolar = 150 * np.sin(2 * np.pi * 1.0 * np.arange(5000) / RATE)
    assert estimate_frequency_hz(bipolar, RATE) == pytest.approx(1.0, rel=5e-3)
    vanishing = np.clip(1 - t / 2.5, 0, None) * sine
    assert estimate_frequency_hz(vanishing, RATE) == pytest.approx(5.0, rel=1e-2)


@pytest.mark.parametrize("f", [20.0, 40.0, 100.0])
def test_a_harmonic_of_the_drive_is_never_a_line(f: float) -> None:
    """A residual made only of drive harmonics (2nd to 6th, envelope-modulated like the drive,
    with a little noise) has no line that is 'not a drive harmonic', whether the drive frequency
    was stated or estimated from the voltage."""
    v = _biased_growing(f)
    u = (v - v[0]) / 60.0  # the drive's own shape, envelope included
    rng = np.random.default_rng(1)
    res = sum(0.3 / k * np.sign(u) * np.abs(u) ** k for k in range(2, 7))
    res = res + 0.01 * rng.standard_normal(v.size)
    f0 = estimate_frequency_hz(v, RATE)
    for f_drive, du in ((f, 1e-4 * f), (f0, 0.5 * RATE / v.size)):
        assert spectral_lines(res, RATE, f_drive, du) == []
    # and a line that is not a harmonic is found
    t = np.arange(v.size) / RATE
    hum = res + 0.2 * np.sin(2 * np.pi * 1.5 * f * t)  # between the 1st and 2nd harmonics
    lines = spectral_lines(hum, RATE, f0, 0.5 * RATE / v.size)
    assert lines and lines[0]["frequency_hz"] == pytest.approx(1.5 * f, abs=0.5)


def test_is_harmonic_tolerance_grows_with_the_order() -> None:
    bin_hz = 0.1
    assert is_harmonic(40.4, 20.2, bin_hz)
    assert is_harmonic(10 * 20.21, 20.2, bin_hz)  # 10th harmonic of a drive known to 0.05 Hz
    assert not is_harmonic(30.0, 20.2, bin_hz)
    assert not is_harmonic(3.0, None, bin_hz)


def _record(name: str, strain: np.ndarray, f: float | None = None) -> Record:
    t = np.arange(strain.size) / RATE
    v = 50 * (1 - np.cos(2 * np.pi * (f or 1.0) * t))
    meta = {} if f is None else {"frequency_hz": f}
    return Record(name, RATE, t, v, strain, {}, "zoh", meta)


@pytest.mark.parametrize("mains", [50.0, 60.0])
def test_mains_is_found_only_where_there_is_a_line(mains: float) -> None:
    rng = np.random.default_rng(3)
    t = np.arange(4000) / RATE
    clean = [
        _record(
            f"e{f:g}", 8 * 50 * (1 - np.cos(2 * np.pi * f * t)) + 2 * rng.standard_normal(t.size), f
        )
        for f in (1.0, 10.0, 20.0)
    ]
    assert detect_mains_hz(clean) is None  # a clean run: no mains is claimed
    hummed = [
        Record(r.name, RATE, t, r.voltage_V, r.strain_ue + 3 * np.sin(2 * np.pi * mains * t + 1))
        for r in clean
    ]
    for r, c in zip(hummed, clean, strict=True):
        r.meta.update(c.meta)
    assert detect_mains_hz(hummed) == mains


def test_evidence_names_no_harmonic_as_a_line_on_a_biased_capture() -> None:
    """Through the diagnosis's evidence, on captures with no stated frequency that are not
    periodic (a bias, a fading envelope, a final hold): the residual's drive harmonics are not
    reported as lines, a line between harmonics is."""
    from labrig.analysis.diagnose.evidence import collect_evidence

    f = 40.0
    ramp = -90.0 * 0.5 * (1 - np.cos(np.pi * np.arange(500) / 500))
    t = np.arange(3000) / RATE
    env = 1 - 0.3 * t / t[-1]
    v = np.concatenate([ramp, np.full(500, -90.0), -90 + 60 * env * np.sin(2 * np.pi * f * t)])
    v = np.concatenate([v, np.full(1000, -90.0)])
    tt = np.arange(v.size) / RATE
    on = (tt >= 1.0) & (tt < 4.0)
    harm = on * sum(0.3 / k * np.cos(2 * np.pi * k * f * tt) for k in range(2, 6))
    rng = np.random.default_rng(2)
    strain = 10 * v + 0.02 * rng.standard_normal(v.size)
    recs = [Record.from_arrays(n, RATE, v, strain) for n in "abc"]
    ev = collect_evidence(recs, {n: strain - harm for n in "abc"})
    assert all(e.lines == [] for e in ev.entries.values())
    assert not any("not a drive harmonic" in s for s in ev.sentences)
    hum = {n: strain - harm - on * 0.3 * np.sin(2 * np.pi * 1.5 * f * tt) for n in "abc"}
    ev = collect_evidence(recs, hum)
    assert all(
        e.lines and e.lines[0]["frequency_hz"] == pytest.approx(60.0, abs=0.5)
        for e in ev.entries.values()
    )


def _lines_one_by_one(x, rate_hz, f0_hz=None, min_hz=2.0, max_lines=3, snr=6.0):
    """The module's definition of a line, bin by bin (each neighbourhood's median on its own),
    with numpy only: the reference for the batched medians of ``spectral_lines``."""
    w = np.hanning(x.size)
    amp = np.abs(np.fft.rfft((x - x.mean()) * w)) * 2 / w.sum()
    freqs = np.fft.rfftfreq(x.size, 1 / rate_hz)
    bin_hz = rate_hz / x.size
    out = []
    for i in np.argsort(amp)[::-1][:200]:
        f = float(freqs[i])
        if f < min_hz or i < 1 or amp[i] < amp[max(i - 2, 0) : i + 3].max():
            continue
        lo, hi = max(i - 30, 1), min(i + 31, amp.size)
        near = np.concatenate((amp[lo : max(i - 3, lo)], amp[min(i + 4, hi) : hi]))
        s = 0.0 if near.size < 5 else float(amp[i] / (np.median(near) + 1e-300))
        if s < snr or is_harmonic(f, f0_hz, bin_hz):
            continue
        if any(abs(f - o["frequency_hz"]) < 3 * bin_hz for o in out):
            continue
        out.append({"frequency_hz": f, "amplitude": float(amp[i]), "snr": s})
        if len(out) >= max_lines:
            break
    return out


@pytest.mark.parametrize("n", [300, 2_000, 50_000])
def test_lines_are_those_found_bin_by_bin(n: int) -> None:
    """Lines near both ends of the spectrum (neighbourhoods cut short) and inside, on noise:
    the same lines, amplitudes and SNR, to the bit, as the bin-by-bin definition."""
    rng = np.random.default_rng(n)
    t = np.arange(n) / RATE
    x = rng.normal(0, 0.3, n)
    for f in (3.0, 50.0, 180.0, 497.0):
        x += np.sin(2 * np.pi * f * t)
    for max_lines in (3, 20):
        got = spectral_lines(x, RATE, None, min_hz=1.0, max_lines=max_lines, snr=3.0)
        assert got == _lines_one_by_one(x, RATE, None, 1.0, max_lines, 3.0)
        assert len(got) >= 2


@pytest.mark.parametrize(
    ("freqs", "amps", "scaled"),
    [
        ((10.0, 10.25, 10.5), (100.0, 100.0, 100.0), False),  # 4.8 % apart: one drive
        ((10.0, 10.3, 10.56), (100.0, 100.0, 100.0), True),  # 5.3 %: a frequency scaling
        ((10.0, 10.0, 10.0), (100.0, 102.0, 104.8), False),  # amplitudes 4.6 % apart
        ((10.0, 10.0, 10.0), (100.0, 102.0, 105.6), True),  # 5.3 %
    ],
)
def test_no_scaling_is_read_from_entries_of_one_drive(freqs, amps, scaled) -> None:
    """The residual's scaling with frequency or amplitude is read only from entries whose
    frequencies (amplitudes) differ by at least 5 % of the largest: the parts of one record,
    whose estimates differ by rounding, would otherwise give a correlation of noise ("the
    residual shrinks with frequency (r = -0.69)")."""
    from labrig.analysis.diagnose.evidence import MIN_SPREAD, collect_evidence

    assert MIN_SPREAD == 0.05
    t = np.arange(4000) / RATE
    recs, preds = [], {}
    rng = np.random.default_rng(3)
    for k, (f, a) in enumerate(zip(freqs, amps, strict=True)):
        v = a / 2 * (1 - np.cos(2 * np.pi * f * t))
        s = 10 * v + 0.05 * rng.standard_normal(t.size)
        recs.append(Record.from_arrays(f"e{k}", RATE, v, s))
        preds[f"e{k}"] = s - (1 + k) * 0.5 * np.sin(2 * np.pi * f * t)  # error grows along
    feats = collect_evidence(recs, preds).features
    which = "excess_vs_log_frequency" if len(set(freqs)) > 1 else "excess_vs_amplitude"
    assert (feats[which] is not None) is scaled, feats
    if scaled:
        assert np.isfinite(feats[which])
