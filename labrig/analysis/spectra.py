"""Spectral lines of a record: the drive frequency, harmonics, lines that are not the drive's.

One amplitude spectrum (Hann window, one-sided amplitude, so a sine of amplitude ``a`` on a bin
shows ``a``) and one notion of a *line*: a bin that is the largest within +-2 bins and stands
:data:`LINE_SNR` times above the median of its neighbourhood (+-:data:`LOCAL_BINS` bins, the
+-3 bins of its own main lobe left out). A broad low-frequency hump (a transient, a drift) is not
a line: it has no neighbourhood below it.

A frequency ``f`` is a harmonic of the drive ``f0`` when ``|f - k f0|`` is within 3 bins (the
main lobe and the spread of an envelope-modulated drive) plus ``k`` times the uncertainty of
``f0`` (half a bin of the record the drive was estimated from, or 1e-4 of ``f0`` when it was
stated), for the nearest whole ``k >= 1``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.analysis.records import Record

__all__ = [
    "DRIVE_FLOOR_RATIO",
    "LINE_SNR",
    "LOCAL_BINS",
    "MAINS_CANDIDATES_HZ",
    "amplitude_spectrum",
    "detect_mains_hz",
    "drive_frequency_hz",
    "estimate_frequency_hz",
    "is_harmonic",
    "spectral_lines",
]

#: a line stands this many times above the median of its neighbourhood
LINE_SNR = 6.0
#: the neighbourhood of a line: +-LOCAL_BINS bins
LOCAL_BINS = 30
#: a bin is a candidate for the drive when the voltage's spectrum there stands this many times
#: above its median (:func:`estimate_frequency_hz`)
DRIVE_FLOOR_RATIO = 6.0
#: the mains frequencies looked for
MAINS_CANDIDATES_HZ = (50.0, 60.0)
#: a mains line must stand this far above its neighbourhood (stricter than a residual line:
#: claiming pickup needs a clear line)
MAINS_SNR = 10.0


def amplitude_spectrum(x: ArrayLike, rate_hz: float) -> tuple[NDArray, NDArray]:
    """``(frequencies Hz, amplitudes)`` of ``x`` about its mean: Hann window, one-sided, scaled
    so that a sine of amplitude ``a`` centred on a bin shows ``a``."""
    x = np.asarray(x, dtype=float)
    w = np.hanning(x.size)
    amp = np.abs(np.fft.rfft((x - x.mean()) * w)) * 2 / w.sum()
    return np.fft.rfftfreq(x.size, 1 / rate_hz), amp


def estimate_frequency_hz(voltage: ArrayLike, rate_hz: float) -> float | None:
    """Dominant frequency of the voltage (Hz), ``None`` for a constant signal, one shorter
    than 8 samples, or one whose spectrum has no bin above its noise floor (white noise alone).

    The peak is looked for in the spectrum of the voltage's *rate* ``dV/dt`` (Hann window),
    where a bias, a ramp to it, rests and slow envelopes weigh little against the drive (in the
    voltage's own spectrum a step to a bias outweighs the drive at the lowest bins). Only bins
    where the voltage's own spectrum stands at least :data:`DRIVE_FLOOR_RATIO` times above its
    median (the noise floor: most bins of a drive's record hold no drive) are candidates:
    differencing white voltage noise gives a rate spectrum rising with frequency that would
    otherwise outweigh a slow drive near Nyquist. White noise's Hann-windowed bins are Rayleigh
    distributed: the largest of a million stands about 4.5 times above their median, and a bin
    exceeds 6 times it with probability 2**-36 (1.5e-11). The drives of the shipped protocols
    and of the real records stand at least 33 times above (a PRBS the lowest), so on a record
    without noise the peak is the one of the whole rate spectrum. Noise that is not white (a
    floor rising or falling across the band) is not what the median measures. The peak is
    refined by a parabola through the log magnitudes of the peak bin and its neighbours in the
    voltage's spectrum when the voltage has its own peak there, else in the rate's."""
    v = np.asarray(voltage, dtype=float)
    if v.size < 8 or not np.ptp(v) > 0:
        return None
    w = np.hanning(v.size)
    mag_v = np.abs(np.fft.rfft((v - v.mean()) * w))
    dv = np.diff(v, prepend=v[0])
    mag_r = np.abs(np.fft.rfft((dv - dv.mean()) * w))
    mag_r[0] = 0.0
    mag_r[mag_v < DRIVE_FLOOR_RATIO * np.median(mag_v[1:])] = 0.0
    k = int(np.argmax(mag_r))
    if k == 0:
        return None
    mag = mag_v if 1 <= k < mag_v.size - 1 and mag_v[k] >= mag_v[k - 1 : k + 2].max() else mag_r
    delta = 0.0
    if 1 <= k < mag.size - 1 and np.all(mag[k - 1 : k + 2] > 0):
        a, b, c = np.log(mag[k - 1 : k + 2])
        den = a - 2 * b + c
        if den < 0:
            delta = 0.5 * (a - c) / den
    return float((k + delta) * rate_hz / v.size)


def drive_frequency_hz(record: Record) -> float | None:
    """The record's drive frequency: ``record.meta`` if stated, else estimated from the voltage."""
    f = record.frequency_hz
    return f if f is not None else estimate_frequency_hz(record.voltage_V, record.rate_hz)


def is_harmonic(
    f_hz: float, f0_hz: float | None, bin_hz: float, f0_uncertainty_hz: float | None = None
) -> bool:
    """Whether ``f_hz`` is a harmonic ``k f0`` (``k >= 1``) within the module's tolerance;
    ``bin_hz`` is the spectrum's resolution; ``f0_uncertainty_hz`` how well ``f0`` is known
    (default: half a bin)."""
    if not f0_hz or not f0_hz > 0:
        return False
    k = max(1, round(f_hz / f0_hz))
    du = 0.5 * bin_hz if f0_uncertainty_hz is None else f0_uncertainty_hz
    return abs(f_hz - k * f0_hz) <= 3 * bin_hz + k * du


def _local_snr(amp: NDArray, i: int) -> float:
    lo, hi = max(i - LOCAL_BINS, 1), min(i + LOCAL_BINS + 1, amp.size)
    near = np.concatenate((amp[lo : max(i - 3, lo)], amp[min(i + 4, hi) : hi]))
    if near.size < 5:
        return 0.0
    return float(amp[i] / (np.median(near) + 1e-300))


#: a bin's neighbourhood in :func:`_local_snr` when it is whole: offsets from the bin
_NEAR = np.r_[np.arange(-LOCAL_BINS, -3), np.arange(4, LOCAL_BINS + 1)]


def _interior_snr(amp: NDArray, bins: NDArray) -> dict[int, float]:
    """:func:`_local_snr` of the bins whose neighbourhood is whole (the same numbers: each
    row's median is its own), all medians in one call."""
    i = bins[(bins - LOCAL_BINS >= 1) & (bins + LOCAL_BINS + 1 <= amp.size)]
    if i.size == 0:
        return {}
    near = amp[i[:, None] + _NEAR[None, :]]
    snr = amp[i] / (np.median(near, axis=1) + 1e-300)
    return dict(zip(i.tolist(), snr.tolist(), strict=True))


def spectral_lines(
    x: ArrayLike,
    rate_hz: float,
    f0_hz: float | None = None,
    f0_uncertainty_hz: float | None = None,
    min_hz: float = 2.0,
    max_lines: int = 3,
    snr: float = LINE_SNR,
) -> list[dict[str, float]]:
    """The strongest lines of ``x`` (module docstring) above ``min_hz`` that are not harmonics
    of the drive ``f0_hz``: ``frequency_hz``, ``amplitude`` (units of ``x``), ``snr``."""
    x = np.asarray(x, dtype=float)
    if x.size < 256:
        return []
    freqs, amp = amplitude_spectrum(x, rate_hz)
    bin_hz = rate_hz / x.size
    out: list[dict[str, float]] = []
    top = np.argsort(amp)[::-1][:200]
    snr_of = _interior_snr(amp, top)
    for i in top:
        f = float(freqs[i])
        if f < min_hz or i < 1 or amp[i] < amp[max(i - 2, 0) : i + 3].max():
            continue
        s = snr_of.get(int(i))
        if s is None:
            s = _local_snr(amp, int(i))
        if s < snr or is_harmonic(f, f0_hz, bin_hz, f0_uncertainty_hz):
            continue
        if any(abs(f - o["frequency_hz"]) < 3 * bin_hz for o in out):
            continue
        out.append({"frequency_hz": f, "amplitude": float(amp[i]), "snr": s})
        if len(out) >= max_lines:
            break
    return out


def detect_mains_hz(records: Sequence[Record]) -> float | None:
    """50 or 60 Hz when the records' strain shows a clear line there (:data:`MAINS_SNR` above
    its neighbourhood, within 1 Hz of it, not a harmonic of the drive up to the 5th), in more
    records at that frequency than at the other; ``None`` when no record shows one."""
    count = dict.fromkeys(MAINS_CANDIDATES_HZ, 0)
    for r in records:
        if r.n < 512 or not np.all(np.isfinite(r.strain_ue)):
            continue
        f0 = drive_frequency_hz(r)
        bin_hz = r.rate_hz / r.n
        for line in spectral_lines(r.strain_ue, r.rate_hz, None, min_hz=40.0, max_lines=20):
            f = line["frequency_hz"]
            if line["snr"] < MAINS_SNR or (f0 and f / f0 < 5.5 and is_harmonic(f, f0, bin_hz)):
                continue
            for fm in MAINS_CANDIDATES_HZ:
                if abs(f - fm) <= max(1.0, 2 * bin_hz):
                    count[fm] += 1
    best = max(count, key=lambda fm: count[fm])
    if count[best] == 0:
        return None
    return best
