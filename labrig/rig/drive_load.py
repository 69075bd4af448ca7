"""What a voltage drive asks of the amplifier: its voltage range, peak current and mean current.

One measurement, one record (:class:`DriveLoad`), behind both limit checks: the protocol
preflight (:func:`labrig.protocol.preflight.measure`, one record per planned entry, on its
waveform) and the controller's :func:`labrig.control.check_drive` (on a computed drive). Both
compare the record with the rig's :class:`~labrig.rig.limits.RigLimits` through its methods
(:meth:`DriveLoad.beyond_range`, :meth:`DriveLoad.over_peak`, :meth:`DriveLoad.over_mean`) and
word their own messages.

The current into the stack is ``i = C_eff dV/dt`` (:meth:`RigLimits.current_A`: ``C_eff =
capacitance_F * large_signal_factor``, ``dV/dt`` by central differences). It is taken on a grid
:data:`OVERSAMPLE` times finer than the output rate: the finer grid sees the slope the amplifier
follows after the DAQ's reconstruction, independent of the rate (a 100 V, 56 Hz sine sampled at
1 kHz underestimates its peak slope by 2 %). The peak uses the central differences; the mean
current over a sliding window of :func:`averaging_window_s` (one period of a periodic drive,
else :data:`AVG_WINDOW_S`), with 0 A before the drive starts, uses each interval's own change
``C_eff |V[j+1] - V[j]| / dt`` (the window's total variation: a central difference reads 0 at a
triangle's corner). For a unipolar sine of amplitude ``A``
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
    "CURRENT_RTOL",
    "MAX_WINDOW_POINTS",
    "OVERSAMPLE",
    "RANGE_TOL_V",
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
#: a voltage this far (V) beyond the rig's range is beyond it (rounding of the waveforms)
RANGE_TOL_V = 1e-9
#: a current this much (relative) above a limit is above it
CURRENT_RTOL = 1e-6

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DriveLoad:
    """What a drive asks of the amplifier (times in s from the drive's start).

    ``v_min_V`` / ``v_max_V``: its voltage range (V); ``peak_current_A``: the largest ``|i|``
    (A), at ``peak_time_s``; ``mean_current_A``: the largest mean ``|i|`` (A) over ``window_s``
    (s), for the window that ends at ``mean_time_s``; ``duration_s``: the drive's duration (s);
    ``name``: what was measured (a planned entry's name; for a computed drive, its description).
    """

    v_min_V: float
    v_max_V: float
    peak_current_A: float
    peak_time_s: float
    mean_current_A: float
    mean_time_s: float
    window_s: float
    duration_s: float
    name: str = ""

    def beyond_range(self, limits: RigLimits) -> tuple[bool, float] | None:
        """``(too high, the voltage out of range)`` when the drive leaves ``limits``'
        ``v_min_V .. v_max_V`` by more than :data:`RANGE_TOL_V` (the top first), else None."""
        if self.v_max_V > limits.v_max_V + RANGE_TOL_V:
            return True, self.v_max_V
        if self.v_min_V < limits.v_min_V - RANGE_TOL_V:
            return False, self.v_min_V
        return None

    def over_peak(self, limits: RigLimits) -> bool:
        """The peak current is above ``limits.i_peak_A`` (relative tolerance
        :data:`CURRENT_RTOL`; a current that is not a number is above)."""
        return not self.peak_current_A <= limits.i_peak_A * (1 + CURRENT_RTOL)

    def over_mean(self, limits: RigLimits) -> bool:
        """The mean current is above ``limits.i_avg_A`` (as :meth:`over_peak`)."""
        return not self.mean_current_A <= limits.i_avg_A * (1 + CURRENT_RTOL)


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
    *,
    duration_s: float,
    time_s: Callable[[int], float] | None = None,
    name: str = "",
) -> DriveLoad:
    """Voltage range, peak and windowed-mean current of a drive on its fine grid.

    ``voltage(lo, hi)`` gives the drive (V) at fine-grid points ``lo .. hi - 1`` of
    ``n_points``, spaced ``1 / fine_rate_hz``; ``time_s(j)`` is the time of point ``j`` in s from
    the drive's start (default ``j / fine_rate_hz``: the grid starts with the drive).
    ``window`` is the mean current's window in points (:func:`window_points`); ``chunk`` points
    are scanned at a time (``None``: all at once); ``duration_s`` and ``name`` are recorded as
    given. A current that is not finite counts as the peak (and a non-finite mean as the largest
    mean), so a broken drive fails the check.
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
            # the mean from each interval's own change (|dV| over the interval after each point;
            # 0 after the last): the windowed sum is the waveform's total variation, exact at a
            # triangle's corner, where a central difference reads 0 and a coarse grid would
            # pass a drive over the limit (at 20 samples a cycle by 2.5 %)
            ahead = np.abs(np.diff(v[a - lo : a - lo + (b - a) + 1])) * (
                limits.effective_capacitance_F * fine_rate_hz
            )
            flow = np.zeros(b - a)
            flow[: ahead.size] = ahead
            vmin = min(vmin, float(np.min(body_v)))
            vmax = max(vmax, float(np.max(body_v)))
            k = int(np.argmax(body))
            if body[k] > peak or not math.isfinite(body[k]):
                peak, peak_j = float(body[k]), a + k
            cs = total + np.cumsum(flow)
            arr = np.concatenate([hist, cs])
            means = (arr[w:] - arr[: b - a]) / w
            k = int(np.argmax(means))
            if means[k] > mean or not math.isfinite(means[k]):
                mean, mean_j = float(means[k]), a + k
            total = float(cs[-1])
            hist = arr[-w:]
    return DriveLoad(
        v_min_V=vmin,
        v_max_V=vmax,
        peak_current_A=peak,
        peak_time_s=peak_j / fine_rate_hz if time_s is None else time_s(peak_j),
        mean_current_A=mean,
        mean_time_s=mean_j / fine_rate_hz if time_s is None else time_s(mean_j),
        window_s=w / fine_rate_hz,
        duration_s=duration_s,
        name=name,
    )
