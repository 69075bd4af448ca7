"""The zero-phase anti-aliasing low-pass (``labrig/analysis/band_limit.py``) against
``scipy.signal.resample_poly`` (an independent implementation of the same filter), and the
sparse ODE's prediction at a faster rate than it was identified at
(:meth:`~labrig.analysis.sindy.SindyBaseline.predict`) against the prediction of the clean
drive."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.band_limit import band_limit, taps
from labrig.analysis.sindy import LIBRARY, SindyBaseline, free_run


@pytest.mark.parametrize("q", [2, 3, 14])
@pytest.mark.parametrize("n", [5, 30, 1001, 5003])
def test_every_qth_sample_is_resample_poly(q: int, n: int) -> None:
    """Decimated by ``q``, the band-limited signal is scipy's polyphase resampling with its
    default Kaiser filter and line padding, to 1e-12 of the signal's size (a random walk: the
    ends do not meet, so the line padding matters; lengths shorter than the filter too)."""
    from scipy.signal import resample_poly  # here: importing it costs every worker ~0.6 s

    x = np.cumsum(np.random.default_rng(q * n).normal(size=n)) + 3.0
    want = resample_poly(x, 1, q, padtype="line")
    got = band_limit(x, 1.0 / q)[::q]
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(x)))


def test_a_line_passes_unchanged_and_a_tone_above_the_band_is_removed() -> None:
    """The ends are extended by the line through the first and last samples, so a straight line
    comes out as it went in (to rounding); a tone at 0.8 of the Nyquist frequency, four times
    the cutoff of ``ratio = 0.2``, is attenuated below 1e-3 away from the ends while a tone at a
    tenth of the cutoff keeps its amplitude within 2e-3 (a Kaiser window of ``beta = 5`` leaves
    a pass-band ripple of about 1e-3)."""
    n = 4000
    line = 2.5 - 0.01 * np.arange(n)
    np.testing.assert_allclose(band_limit(line, 0.2), line, rtol=0, atol=1e-12)
    k = np.arange(n)
    high = np.sin(np.pi * 0.8 * k)
    low = np.sin(np.pi * 0.02 * k)
    mid = slice(200, n - 200)
    assert np.max(np.abs(band_limit(high, 0.2)[mid])) < 1e-3
    assert np.max(np.abs(band_limit(low, 0.2)[mid] - low[mid])) < 2e-3


def test_ratio_one_is_the_identity_and_the_ratio_is_checked() -> None:
    x = np.array([1.0, -2.0, 3.0])
    np.testing.assert_array_equal(band_limit(x, 1.0), x)
    # at the full band the windowed sinc is zero at every nonzero integer: a unit impulse
    impulse = np.zeros(taps(1.0).size)
    impulse[impulse.size // 2] = 1.0
    np.testing.assert_allclose(taps(1.0), impulse, rtol=0, atol=1e-15)
    for bad in (0.0, -0.5, 1.5):
        with pytest.raises(ValueError, match="ratio"):
            taps(bad)


def test_a_faster_noisy_record_is_predicted_like_its_clean_drive() -> None:
    """An ODE with a ``|V'|`` term identified at 250 Hz, asked to predict a record sampled at
    4 kHz whose voltage carries 0.3 V of white noise: the differences of noisy samples make
    ``|V'|`` large everywhere (the noise's rate, not the drive's), but the prediction cuts the
    voltage to the model's band first and stays within 0.5 % of the strain span of the clean
    drive's prediction; fed the raw samples, the same ODE is off by more than 5 %."""
    names = [t.name for t in LIBRARY]
    xi = np.zeros(len(names))
    for name, value in (("S", -2.0), ("V'", 0.1), ("|V'| S", -0.001), ("|V'|", 0.02)):
        xi[names.index(name)] = value
    model = SindyBaseline(tuple(xi), 250.0, 0.0)
    rate = 4000.0
    t = np.arange(round(2.0 * rate)) / rate
    clean = 150.0 * np.sin(2.0 * np.pi * t)
    noisy = clean + np.random.default_rng(7).normal(0.0, 0.3, t.size)
    want = free_run(xi, clean, rate)
    span = float(np.ptp(want))
    got = model.predict(noisy, 0.0, rate)
    raw = free_run(xi, noisy, rate)
    assert np.max(np.abs(got - want)) < 0.005 * span
    assert np.max(np.abs(raw - want)) > 0.05 * span


@pytest.mark.parametrize("where", [0, 57, -1])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_sample_is_refused_with_its_index(where: int, bad: float) -> None:
    """A NaN at either end would spread over the whole signal through the line its ends are
    extended by; anywhere, over the filter's length: refused, naming the first such sample.
    With ``ratio == 1`` nothing is filtered and the signal is returned as it is."""
    x = np.sin(np.linspace(0.0, 6.0, 200))
    x[where] = bad
    with pytest.raises(ValueError, match=f"index {where % x.size} of 200"):
        band_limit(x, 0.25)
    same = band_limit(x, 1.0)
    assert np.array_equal(same, x, equal_nan=True)
