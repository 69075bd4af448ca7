"""What a voltage drive asks of the amplifier: its voltage range, peak current and mean current.

The one measurement behind both limit checks: the protocol preflight
(:func:`labrig.protocol.preflight.measure`, on a planned step's waveform) and the controller's
:func:`labrig.control.check_drive` (on a computed drive). Both then compare it with the rig's
:class:`~labrig.rig.limits.RigLimits` and word their own messages.

The current into the stack is ``i = C_eff dV/dt`` (:meth:`RigLimits.current_A`: ``C_eff =
capacitance_F * large_signal_factor``, ``dV/dt`` by central differences). It is taken on a grid
:data:`OVERSAMPLE` times finer than the output rate: the finer grid sees the slope the amplifier
follows after the DAQ's reconstruction, independent of the rate (a 100 V, 56 Hz sine sampled at
1 kHz underestimates its peak slope by 2 %). The mean current is the mean of ``|i|`` over a
sliding window of :func:`averaging_window_s` (one period of a periodic drive, else
:data:`AVG_WINDOW_S`), with 0 A before the drive starts. For a unipolar sine of amplitude ``A``
(V) and frequency ``f`` (Hz) this gives ``i_peak = pi C_eff A f`` and a period mean
``2 C_eff A f``.

The fine grid is scanned in chunks of ``chunk`` points so a long step never holds it whole; the
running sums carry over from one chunk to the next.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from labrig.rig.limits import RigLimits

__all__ = [
    "AVG_WINDOW_S",
    "CHUNK",
    "MAX_WINDOW_POINTS",
    "OVERSAMPLE",
    "DriveLoad",
    "averaging_window_s",
    "measure_load",
    "window_points",
]

#: the current is computed on a grid this many times finer than the output rate
OVERSAMPLE = 4
#: averaging window of the mean current (s) when the drive has no period
AVG_WINDOW_S = 1.0
#: fine-grid points scanned at a time
CHUNK = 1 << 20
#: the protocol preflight caps its averaging window at this many fine-grid points
MAX_WINDOW_POINTS = 50_000_000

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DriveLoad:
    """The load of a drive on the amplifier, on the fine grid (index ``j`` is at ``j /
    fine_rate_hz`` s from the grid's first point).

    ``v_min_V`` / ``v_max_V``: the voltage range over the grid; ``peak_current_A`` at
    ``peak_index``: the largest ``|i|`` (A); ``mean_current_A``: the largest mean ``|i|`` over
    ``window_points`` consecutive points, for the window that ends at ``mean_index``.
    """

    v_min_V: float
    v_max_V: float
    peak_current_A: float
    peak_index: int
    mean_current_A: float
    mean_index: int
    window_points: int


def averaging_window_s(frequency_hz: float | None) -> float:
    """The mean current's window (s): one period ``1 / frequency_hz``, else :data:`AVG_WINDOW_S`."""
    if frequency_hz:
        return 1.0 / frequency_hz
    return AVG_WINDOW_S


def window_points(window_s: float, fine_rate_hz: float, cap: int | None = MAX_WINDOW_POINTS) -> int:
    """``round(window_s * fine_rate_hz)`` fine-grid points, at least 1 and at most ``cap``."""
    n = round(window_s * fine_rate_hz)
    return max(1, n if cap is None else min(n, cap))


def measure_load(
    voltage: Callable[[int, int], Array],
    n_points: int,
    fine_rate_hz: float,
    limits: RigLimits,
    window: int,
    chunk: int | None = CHUNK,
) -> DriveLoad:
    """Voltage range, peak and windowed-mean current of a drive on its fine grid.

    ``voltage(lo, hi)`` gives the drive (V) at fine-grid points ``lo .. hi - 1`` of
    ``n_points``, spaced ``1 / fine_rate_hz``; ``window`` is the mean current's window in points
    (:func:`window_points`); ``chunk`` points are scanned at a time (``None``: all at once). A
    current that is not finite counts as the peak (and a non-finite mean as the largest mean), so
    a broken drive fails the check.
    """
    m = n_points
    step = m if chunk is None else chunk
    w = window
    hist = np.zeros(w)  # cumulative |i| at the w points before the chunk (0 before the start)
    total = 0.0
    vmin, vmax = math.inf, -math.inf
    peak, peak_j, mean, mean_j = 0.0, 0, 0.0, 0
    with np.errstate(all="ignore"):
        for a in range(0, m, max(step, 1)):
            b = min(m, a + step)
            # one point either side so the central differences at the chunk's ends are exact
            lo, hi = max(0, a - 1), min(m, b + 1)
            v = voltage(lo, hi)
            cur = np.abs(limits.current_A(v, fine_rate_hz)) if v.size > 1 else np.zeros(v.size)
            body_v = v[a - lo : a - lo + (b - a)]
            body = cur[a - lo : a - lo + (b - a)]
            vmin = min(vmin, float(np.min(body_v)))
            vmax = max(vmax, float(np.max(body_v)))
            k = int(np.argmax(body))
            if body[k] > peak or not math.isfinite(body[k]):
                peak, peak_j = float(body[k]), a + k
            cs = total + np.cumsum(body)
            arr = np.concatenate([hist, cs])
            means = (arr[w:] - arr[: b - a]) / w
            k = int(np.argmax(means))
            if means[k] > mean or not math.isfinite(means[k]):
                mean, mean_j = float(means[k]), a + k
            total = float(cs[-1])
            hist = arr[-w:]
    return DriveLoad(vmin, vmax, peak, peak_j, mean, mean_j, w)
