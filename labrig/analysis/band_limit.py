"""A zero-phase anti-aliasing low-pass: a signal cut to the band of a lower sample rate.

The filter is ``scipy.signal.resample_poly``'s for a decimation by ``q = 1 / ratio``: a
Kaiser-windowed sinc (``beta = 5``) of ``2 ceil(10 q) + 1`` taps with its cutoff at ``ratio``
times the Nyquist frequency, unit gain at DC, applied centred (no delay), the signal's ends
extended by the line through its first and last samples (``padtype="line"``). Every ``q``-th
sample of :func:`band_limit` is ``resample_poly(x, 1, q, padtype="line")`` to rounding, so a
record decimated for an identification and the same record at its own rate band-limited for a
prediction see one drive. The taps are ``scipy.signal.firwin(2 half + 1, ratio,
window=("kaiser", 5.0))``'s to 1e-18, written with NumPy (``numpy.kaiser``, ``numpy.sinc``);
the tests check the whole against ``resample_poly``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["BETA", "band_limit", "taps"]

#: the Kaiser window's shape parameter (``resample_poly``'s)
BETA = 5.0


def taps(ratio: float) -> NDArray[np.float64]:
    """The low-pass's impulse response for a cutoff at ``ratio`` (0 < ratio <= 1) times the
    Nyquist frequency: ``h[n] = ratio sinc(ratio n) w[n]`` for ``|n| <= ceil(10 / ratio)``,
    ``w`` the Kaiser window, scaled to ``sum(h) = 1``."""
    if not 0.0 < ratio <= 1.0:
        raise ValueError(f"ratio must be in (0, 1], got {ratio}")
    half = math.ceil(10.0 / ratio - 1e-9)
    n = np.arange(-half, half + 1)
    h = ratio * np.sinc(ratio * n) * np.kaiser(2 * half + 1, BETA)
    return h / np.sum(h)


def band_limit(x: ArrayLike, ratio: float) -> NDArray[np.float64]:
    """``x`` low-passed to ``ratio`` (0 < ratio <= 1) times its Nyquist frequency, zero phase,
    same length (module docstring); ``x`` itself (as floats) for ``ratio == 1`` or fewer than
    two samples. Raises ``ValueError`` for a non-finite sample: the filter would spread it over
    its length, and a NaN at either end, through the line the ends are extended by, over the
    whole signal."""
    x = np.asarray(x, dtype=float)
    if ratio == 1.0 or x.size < 2:
        return x.copy()
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise ValueError(
            f"cannot band-limit a signal with {bad.size} non-finite sample(s), the first at "
            f"index {int(bad[0])} of {x.size}: drop or fill them first"
        )
    h = taps(ratio)
    half = h.size // 2
    line = np.linspace(x[0], x[-1], x.size)
    return np.convolve(x - line, h)[half : half + x.size] + line
