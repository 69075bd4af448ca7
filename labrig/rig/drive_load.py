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
running sums carry over from one chunk to the next (the one behind the window means restarts at
each multiple of ``chunk``, so that a window's sum is the difference of two sums over at most
that many points, not over the whole drive: a 499 s entry's would round by up to ``1e-8``).

**Repeating pieces** (:func:`repeat_skip`): where a drive repeats (a sine, a triangle, a hold:
``V(t + k/f) = V(t)``), every figure at an inner point ``j`` of the piece (its window and its
central difference inside the piece) is a function of the point's phase ``theta_j = j r mod 1``
(cycles; ``r = f / fine_rate`` the phase per point). A run of :func:`repeat_span` consecutive
points holds, to :data:`REPEAT_RTOL` of each figure's scale, every phase the piece's other inner
points have, so the scan keeps the edges, that many inner points at the start of the piece and
at its end, and leaves out the points between (``skip``). The figures are those of the whole
scan to that tolerance in exact arithmetic. In floating point the whole scan's peak carries
the rounding of late times, which the points near the start do not: the phase of point ``j`` is
rounded to about ``1e-16`` of itself and a central difference over ``1/P`` of a cycle magnifies
that ``P / (2 pi)`` times, so the current at point ``j`` is rounded by about ``1e-16 j`` of
itself (the whole scan of a 499 s sine at 100 kHz finds its peak up to ``1.2e-8`` higher).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction

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
    "REPEAT_RTOL",
    "DriveLoad",
    "averaging_window_s",
    "measure_load",
    "repeat_skip",
    "repeat_span",
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
#: what a repeating piece's left-out points may hide of each figure, relative to its scale (the
#: amplitude for the voltages, the figure itself for the currents)
REPEAT_RTOL = 1e-10
#: any repeating piece: phases this close (cycles) count as one. The largest and smallest value
#: of no figure moves by more than ``2 pi`` of its scale per cycle of shift (a sinusoid's; a
#: triangle's voltage by ``4 A``, its window's total variation by 6 times itself, its peak
#: current not at all), so a drift this small moves it by ``REPEAT_RTOL`` at most
REPEAT_DRIFT_CYCLES = REPEAT_RTOL / (2.0 * math.pi)
#: a sinusoid: within ``d`` cycles of its maximum every figure is within ``1 - cos(2 pi d) <=
#: 2 pi^2 d^2`` of it (its voltage, its central difference ``|sin|``, its window's total
#: variation, a sum of ``|sin|``: ``y'' = -(2 pi)^2 y`` between kinks that only bend it up), so a
#: run of points whose phases drift by at most this much reaches its maxima to REPEAT_RTOL
SINUSOID_DRIFT_CYCLES = math.sqrt(REPEAT_RTOL / 2.0) / math.pi
#: ... and a run whose phases leave no gap wider than this on the circle (each phase within half
#: of it of a point of the run)
SINUSOID_GAP_CYCLES = math.sqrt(2.0 * REPEAT_RTOL) / math.pi

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


# -- repeating pieces ------------------------------------------------------------------------


def _convergents(x: Fraction) -> Iterator[int]:
    """The denominators ``q`` of the continued-fraction convergents ``p/q`` of ``x >= 0``, in
    order (increasing; the first two may both be 1)."""
    q0, q1 = 1, 0  # q_{-2}, q_{-1}
    while True:
        a = math.floor(x)
        q0, q1 = q1, a * q1 + q0
        yield q1
        if x == a:
            return
        x = 1 / (x - a)


def _off_whole(x: Fraction) -> Fraction:
    """``||x||``: the distance from ``x`` to the nearest whole number."""
    f = x - math.floor(x)
    return min(f, 1 - f)


def repeat_span(phase_per_point: Fraction, n_points: int, sinusoid: bool = False) -> int | None:
    """How many consecutive points of a repeating piece stand for all ``n_points`` of them.

    Point ``j`` is at phase ``theta_j = j r mod 1`` (cycles), ``r = phase_per_point`` (exact:
    ``f / fine_rate``). Over the continued-fraction denominators ``q`` of ``r`` (the runs whose
    phases are spread most evenly), the first that passes one of:

    - any piece: the run of ``q`` points repeats to within ``D = ceil(n_points / q) ||q r||``
      cycles over the piece (``||x||``: distance to the nearest whole number; point ``j + k q``
      is at ``theta_j + k (q r - p)``) and ``D <= REPEAT_DRIFT_CYCLES``;
    - a sinusoid, when both the first and the last ``q`` points are kept: each point's phase lies
      between those of the two ends of its residue class, ``D`` apart at most, and
      ``D <= SINUSOID_DRIFT_CYCLES``;
    - a sinusoid: the ``q`` points leave no gap wider than ``||q' r|| + ||q r||`` (three-gap
      theorem; ``q'`` the previous denominator, ``q' < q``) and that is at most
      ``SINUSOID_GAP_CYCLES``.

    Parameters
    ----------
    phase_per_point : Fraction
        ``r``, cycles per fine-grid point (0: a constant).
    n_points : int
        The piece's inner points.
    sinusoid : bool
        The piece is ``c + a cos(2 pi theta + phi)``.

    Returns
    -------
    int or None
        ``q`` (points), or None when no run of at most half the piece passes (two such runs,
        one at each end, would be the whole piece).
    """
    longest = n_points // 2
    prev_q, prev_off = 0, Fraction(0)
    for q in _convergents(phase_per_point):
        if q > longest:
            return None
        off = _off_whole(q * phase_per_point)
        drift = -(-n_points // q) * off
        if drift <= REPEAT_DRIFT_CYCLES:
            return q
        spread = 0 < prev_q < q and prev_off + off <= SINUSOID_GAP_CYCLES
        if sinusoid and (drift <= SINUSOID_DRIFT_CYCLES or spread):
            return q
        prev_q, prev_off = q, off
    return None


def repeat_skip(
    first: int, stop: int, phase_per_point: Fraction, window: int, sinusoid: bool = False
) -> tuple[int, int] | None:
    """The fine-grid points ``[lo, hi)`` of a repeating piece :func:`measure_load` may leave out.

    The piece gives points ``first .. stop - 1``, its value at point ``j`` a function of its
    phase ``j r mod 1`` alone. Its inner points ``first + window .. stop - 2`` have their window
    of ``window`` intervals and their central difference inside it, so each figure there is a
    function of the phase too. The scan keeps the :func:`repeat_span` first inner points, the
    as many last ones with their whole windows, and everything outside (the edges: what comes
    before, 0 V before the drive, the ramps, what comes after).

    Parameters
    ----------
    first, stop : int
        The piece's first point and the first point after it.
    phase_per_point : Fraction
        Cycles per point (0: a constant).
    window : int
        The mean current's window (points).
    sinusoid : bool
        The piece is a sinusoid (:func:`repeat_span`).

    Returns
    -------
    tuple of int or None
        ``(lo, hi)``, or None when nothing may be left out.
    """
    j0, j1 = first + window, stop - 2
    if j1 < j0:
        return None
    span = repeat_span(phase_per_point, j1 - j0 + 1, sinusoid)
    if span is None:
        return None
    lo, hi = j0 + span, j1 - span - window + 2
    return (lo, hi) if lo < hi else None


# -- the scan --------------------------------------------------------------------------------


def _stretches(n_points: int, skip: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """The ``[start, stop)`` stretches of ``0 .. n_points - 1`` left once ``skip`` is out."""
    out, at = [], 0
    for lo, hi in sorted(skip):
        lo, hi = max(lo, at), min(hi, n_points)
        if lo >= hi:
            continue
        if at < lo:
            out.append((at, lo))
        at = hi
    if at < n_points:
        out.append((at, n_points))
    return out


def _chunks(stretches: list[tuple[int, int]], step: int) -> Iterator[tuple[int, int, bool]]:
    """``(a, b, first)``: the points ``a .. b - 1`` of each stretch, cut at the multiples of
    ``step`` (the same cuts whatever is left out); ``first``: the first chunk of a stretch."""
    for start, stop in stretches:
        a = start
        while a < stop:
            b = min(stop, (a // step + 1) * step)
            yield a, b, a == start
            a = b


@dataclass
class _Figures:
    """The running figures of a scan: voltage range (V), peak current (A) at point
    ``peak_j``, largest window mean (A) for the window ending at point ``mean_j``."""

    vmin: float = math.inf
    vmax: float = -math.inf
    peak: float = 0.0
    peak_j: int = 0
    mean: float = 0.0
    mean_j: int = 0

    def take(self, a: int, v: Array, cur: Array, means: Array) -> None:
        """Fold in points ``a ..`` of a chunk: their voltages, ``|i|`` and window means (an
        earlier point wins a tie; a value that is not finite wins)."""
        self.vmin = min(self.vmin, float(np.min(v)))
        self.vmax = max(self.vmax, float(np.max(v)))
        k = int(np.argmax(cur))
        if cur[k] > self.peak or not math.isfinite(cur[k]):
            self.peak, self.peak_j = float(cur[k]), a + k
        k = int(np.argmax(means))
        if means[k] > self.mean or not math.isfinite(means[k]):
            self.mean, self.mean_j = float(means[k]), a + k


class _WindowSums:
    """Window means of ``|i|`` over ``window`` intervals, chunk by chunk, from a running sum.

    The running sum restarts at each multiple of ``step`` (a block): a window's sum is the
    difference of two running sums at most a block long, not as long as the drive (where each
    addition would round at the drive's total: 1e-8 of a window's sum after 2e8 points), and the
    blocks sit at the same places however the scan is cut. ``hist``: the running sum at the
    ``window`` points before the next chunk (0 before the drive)."""

    def __init__(self, window: int, step: int):
        self.w, self.step = window, step
        self.block, self.rel = 0, 0.0
        self.hist = np.zeros(window)

    def after_gap(self) -> None:
        """Points were left out before the next chunk: their intervals count as no change (the
        sums of a hold's left-out middle, where none changes, are the whole scan's to the bit)."""
        self.hist = np.full(self.w, self.rel)

    def means(self, a: int, flow: Array) -> Array:
        """The mean of ``flow`` (A) over the window ending at each point ``a ..`` of a chunk."""
        if a // self.step != self.block:  # a new block: sums from its start
            self.hist, self.rel, self.block = self.hist - self.rel, 0.0, a // self.step
        cs = np.cumsum(np.concatenate(([self.rel], flow)))[1:]
        arr = np.concatenate([self.hist, cs])
        self.rel, self.hist = float(cs[-1]), arr[-self.w :]
        return (arr[self.w :] - arr[: flow.size]) / self.w


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
    skip: Sequence[tuple[int, int]] = (),
) -> DriveLoad:
    """Voltage range, peak and windowed-mean current of a drive on its fine grid.

    ``voltage(lo, hi)`` gives the drive (V) at fine-grid points ``lo .. hi - 1`` of
    ``n_points``, spaced ``1 / fine_rate_hz``; ``time_s(j)`` is the time of point ``j`` in s from
    the drive's start (default ``j / fine_rate_hz``: the grid starts with the drive).
    ``window`` is the mean current's window in points (:func:`window_points`); ``chunk`` points
    are scanned at a time (``None``: all at once); ``duration_s`` and ``name`` are recorded as
    given. A current that is not finite counts as the peak (and a non-finite mean as the largest
    mean), so a broken drive fails the check. ``skip``: ``[lo, hi)`` ranges of points left out,
    whose figures the scanned points already hold (:func:`repeat_skip`); the running sum carries
    over one as if its intervals had not changed the voltage (a window reaching into it reads
    low: that window is left out too; over a hold, where they do not, the sums are the whole
    scan's to the last bit).
    """
    step = n_points if chunk is None else max(chunk, 1)
    found, sums = _Figures(), _WindowSums(window, step)
    with np.errstate(all="ignore"):
        for a, b, first in _chunks(_stretches(n_points, skip), step):
            if first:
                sums.after_gap()
            # one point either side so the central differences at the chunk's ends are exact
            lo, hi = max(0, a - 1), min(n_points, b + 1)
            v = voltage(lo, hi)
            cur = np.abs(limits.current_A(v, fine_rate_hz)) if v.size > 1 else np.zeros(v.size)
            # the mean from each interval's own change (|dV| over the interval after each point;
            # 0 after the last): the windowed sum is the waveform's total variation, exact at a
            # triangle's corner, where a central difference reads 0 and a coarse grid would pass
            # a drive over the limit (at 20 samples a cycle by 2.5 %)
            ahead = np.abs(np.diff(v[a - lo : b - lo + 1])) * (
                limits.effective_capacitance_F * fine_rate_hz
            )
            flow = np.zeros(b - a)
            flow[: ahead.size] = ahead
            found.take(a, v[a - lo : b - lo], cur[a - lo : b - lo], sums.means(a, flow))
    at = (lambda j: j / fine_rate_hz) if time_s is None else time_s
    return DriveLoad(
        v_min_V=found.vmin,
        v_max_V=found.vmax,
        peak_current_A=found.peak,
        peak_time_s=at(found.peak_j),
        mean_current_A=found.mean,
        mean_time_s=at(found.mean_j),
        window_s=window / fine_rate_hz,
        duration_s=duration_s,
        name=name,
    )
