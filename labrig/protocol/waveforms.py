"""Waveform generators: continuous-time voltage functions, sampled on demand.

A concrete step's command is a :class:`Waveform`: a chain of :class:`Segment` pieces (sine,
envelope, hold, ramp, table) joined end to start. :func:`compose` inserts *edge ramps* wherever
two neighbours disagree, and before the first / after the last piece when they do not start /
end at 0 V, so every waveform starts and ends at exactly 0 V. Edge ramps are straight lines at
the protocol's ``edge_slew_V_per_s`` (default 1000 V/s, i.e. 0.1 s for 100 V), at least one
sample long.

Sample ``k`` of a waveform is its value at ``t = k / rate_hz``; a piece lasting ``D`` seconds
spans ``N = round(D rate_hz)`` sample intervals, and neighbouring pieces share their joint
sample. Because the pieces are functions of continuous time, the preflight can evaluate them
on a grid finer than the output rate (see :mod:`labrig.protocol.preflight`), and the runner can
ask for any block of samples without the whole array existing in memory.

Formulas (A amplitude, f frequency, t local time in s):

- unipolar sine: ``V = A/2 (1 - cos 2 pi f t)``: 0 V at t = 0, A at t = 1/(2f), period 1/f;
- vanishing envelope: ``V = e(t - t0) A/2 (1 - cos 2 pi f t)`` with ``t0 = 1/(2f)`` (the first
  peak reaches the full amplitude A), ``e(s) = 1`` for ``s <= 0`` and from 1 at s = 0 to 0 at
  s = T: linear ``1 - s/T`` or exponential ``(exp(-s/tau) - exp(-T/tau))/(1 - exp(-T/tau))``,
  0 for s >= T; the envelope part lasts ``t0 + T``;
- offset sine: ``V = V0 + e(t) A sin(2 pi f t)`` on ``0 <= t <= T`` (the piece's length), with
  ``e = 1`` (constant), ``t/T`` (growing) or ``1 - t/T`` (vanishing);
- raised-cosine ramp: ``V = V0 + (V1 - V0) (1 - cos(pi t/D))/2``: zero slope at both ends;
- ramp: ``V = V0 + (V1 - V0) t/D``; hold: ``V = V0``;
- table (CSV): linear interpolation between the samples.

A piece that repeats says so (:attr:`Segment.repeat_hz`: a unipolar sine, an offset sine of
constant envelope, a triangle, a hold), so that the preflight may measure its edges and enough
of it instead of every point (:func:`labrig.rig.drive_load.repeat_skip`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
#: two pieces whose joint differs by less than this (V) are considered continuous
JOIN_TOL_V = 1e-6


def unipolar_sine(t: Array, amplitude_V: float, frequency_hz: float) -> Array:
    """``A/2 (1 - cos 2 pi f t)``."""
    return 0.5 * amplitude_V * (1.0 - np.cos(2.0 * np.pi * frequency_hz * np.asarray(t)))


def envelope(t: Array, decay_s: float, shape: str, tau_s: float | None = None) -> Array:
    """Vanishing envelope: 1 at t <= 0, exactly 0 at t >= decay_s (see module docstring)."""
    t = np.clip(np.asarray(t, dtype=float), 0.0, decay_s)
    if shape == "linear":
        return 1.0 - t / decay_s
    tau = decay_s / 2.0 if tau_s is None else tau_s
    r = decay_s / tau
    if r > 700:  # exp(-T/tau) underflows: plain exponential
        return np.where(t >= decay_s, 0.0, np.exp(-t / tau))
    # (exp(-t/tau) - exp(-T/tau)) / (1 - exp(-T/tau)) = expm1((T - t)/tau) / expm1(T/tau),
    # written so it neither overflows nor loses precision for tau >> T
    return np.expm1((decay_s - t) / tau) / np.expm1(r)


@dataclass(frozen=True)
class Segment:
    """One piece of a waveform: ``n`` sample intervals of ``func(local time in s)``.

    ``role`` is ``"main"`` for the waveform the protocol asked for and ``"edge"`` for ramps
    inserted to reach 0 V; ``field`` names the protocol key that controls the piece (preflight
    uses it to point at the right line). ``repeat_hz``: the piece repeats at this frequency
    (Hz), ``func(t + k / repeat_hz) = func(t)`` for every whole ``k`` in exact arithmetic, its
    value a function of the phase ``repeat_hz t`` alone (0: a constant; None: it does not
    repeat); ``sinusoid``: it is ``c + a cos(2 pi repeat_hz t + phi)`` (a constant too);
    ``extremes``: for a repeating piece, its lowest and highest value over a period (V), from
    its formula: at least what any of its points reaches (the preflight's shortcut over
    repeating pieces scans every point when they would leave the rig's range and its scanned
    points do not).
    """

    kind: str
    n: int
    func: Callable[[Array], Array] = field(repr=False)
    field: str = ""
    role: str = "main"
    repeat_hz: float | None = None
    sinusoid: bool = False
    extremes: tuple[float, float] | None = None

    def value(self, tau: Array) -> Array:
        return np.asarray(self.func(np.asarray(tau, dtype=float)), dtype=float)

    def start_end(self, rate_hz: float) -> tuple[float, float]:
        v = self.value(np.array([0.0, self.n / rate_hz]))
        return float(v[0]), float(v[1])


def sine_segment(amplitude_V: float, frequency_hz: float, n: int, field: str = "") -> Segment:
    """The unipolar sine ``A/2 (1 - cos 2 pi f t)`` over ``n`` sample intervals (repeats at f)."""
    return Segment(
        "sine",
        n,
        lambda t: unipolar_sine(t, amplitude_V, frequency_hz),
        field,
        repeat_hz=frequency_hz,
        sinusoid=True,
        extremes=(min(0.0, amplitude_V), max(0.0, amplitude_V)),
    )


def vanishing_segment(
    amplitude_V: float,
    frequency_hz: float,
    decay_s: float,
    shape: str,
    tau_s: float | None,
    n: int,
    field: str = "",
) -> Segment:
    """Envelope-modulated unipolar sine: full amplitude up to the first peak ``t0 = 1/(2f)``,
    then ``e(t - t0)`` decaying to exactly zero at ``t0 + decay_s``."""
    t0 = 0.5 / frequency_hz

    def f(t: Array) -> Array:
        e = envelope(t - t0, decay_s, shape, tau_s)
        return e * unipolar_sine(t, amplitude_V, frequency_hz)

    return Segment("vanishing", n, f, field)


#: the envelopes of an offset sine: e(t) on 0 <= t <= T, from its local time and length
ENVELOPES: dict[str, Callable[[Array, float], Array]] = {
    "constant": lambda t, T: np.ones(np.shape(t)),
    "growing": lambda t, T: np.clip(t / T, 0.0, 1.0),
    "vanishing": lambda t, T: np.clip(1.0 - t / T, 0.0, 1.0),
}


def offset_sine_segment(
    offset_V: float,
    amplitude_V: float,
    frequency_hz: float,
    envelope_name: str,
    n: int,
    rate_hz: float,
    field: str = "",
) -> Segment:
    """``V = offset + e(t) A sin(2 pi f t)`` over ``n`` sample intervals (``T = n / rate_hz``);
    a constant envelope repeats at f."""
    length_s = n / rate_hz
    e = ENVELOPES[envelope_name]

    def f(t: Array) -> Array:
        t = np.asarray(t, dtype=float)
        return offset_V + e(t, length_s) * amplitude_V * np.sin(2.0 * np.pi * frequency_hz * t)

    constant = envelope_name == "constant"
    repeat = frequency_hz if constant else None
    reach = (offset_V - abs(amplitude_V), offset_V + abs(amplitude_V)) if constant else None
    return Segment("offset_sine", n, f, field, repeat_hz=repeat, sinusoid=constant, extremes=reach)


def raised_cosine_segment(
    from_V: float, to_V: float, n: int, rate_hz: float, field: str = ""
) -> Segment:
    """``V0 + (V1 - V0) (1 - cos(pi t/D))/2`` over ``n`` intervals (``D = n / rate_hz``): a
    ramp that starts and ends with zero slope; its steepest slope is ``pi |V1 - V0| / (2 D)``."""
    d = n / rate_hz

    def f(t: Array) -> Array:
        x = np.clip(np.asarray(t, dtype=float) / d, 0.0, 1.0)
        return from_V + (to_V - from_V) * 0.5 * (1.0 - np.cos(np.pi * x))

    return Segment("raised_cosine", n, f, field)


def const_segment(voltage_V: float, n: int, field: str = "", kind: str = "hold") -> Segment:
    """``voltage_V`` held over ``n`` sample intervals (a constant: ``repeat_hz`` 0)."""
    v = float(voltage_V)
    return Segment(
        kind,
        n,
        lambda t: np.full(np.shape(t), v),
        field,
        repeat_hz=0.0,
        sinusoid=True,
        extremes=(v, v),
    )


def ramp_segment(
    from_V: float, to_V: float, n: int, rate_hz: float, field: str = "", role: str = "main"
) -> Segment:
    d = n / rate_hz

    def f(t: Array) -> Array:
        return from_V + (to_V - from_V) * np.clip(t / d, 0.0, 1.0)

    return Segment("ramp", n, f, field, role)


def table_segment(values: Array, rate_hz: float, field: str = "") -> Segment:
    """Samples at ``rate_hz`` played as they are (linear interpolation between them)."""
    v = np.asarray(values, dtype=float)
    idx = np.arange(v.size, dtype=float)

    def f(t: Array) -> Array:
        return np.interp(t * rate_hz, idx, v)

    return Segment("table", v.size - 1, f, field)


def edge_samples(delta_V: float, rate_hz: float, slew_V_per_s: float) -> int:
    """Sample intervals of an edge ramp covering ``delta_V`` at ``slew_V_per_s``."""
    x = abs(delta_V) / slew_V_per_s * rate_hz
    if not math.isfinite(x) or x > 2.0**62:
        return 2**62
    return max(1, math.ceil(x - 1e-9))


class Waveform:
    """A chain of segments sampled at ``rate_hz``; starts and ends at exactly 0 V."""

    def __init__(self, segments: list[Segment], rate_hz: float):
        self.segments = [s for s in segments if s.n > 0]
        self.rate_hz = float(rate_hz)
        starts = [0]
        for s in self.segments:
            starts.append(starts[-1] + s.n)
        self._starts = np.array(starts, dtype=np.int64)  # first sample index of each segment
        self.n_samples = int(starts[-1]) + 1

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample."""
        return (self.n_samples - 1) / self.rate_hz

    def segment_at(self, index: float) -> Segment:
        """The segment that sample ``index`` (possibly fractional) belongs to."""
        i = int(np.searchsorted(self._starts, index, side="right")) - 1
        return self.segments[min(max(i, 0), len(self.segments) - 1)]

    def segment_start(self, seg: Segment) -> int:
        return int(self._starts[self.segments.index(seg)])

    def pieces(self) -> list[tuple[int, Segment]]:
        """Each segment with its first sample index, in order (samples ``start .. start + n``;
        the last of them is the next segment's first)."""
        return [(int(a), s) for a, s in zip(self._starts, self.segments, strict=False)]

    def at_index(self, u: Array) -> Array:
        """Values at (possibly fractional) sample indices ``u`` in ``[0, n_samples - 1]``."""
        u = np.asarray(u, dtype=float)
        out = np.empty(u.shape)
        if not self.segments:
            out.fill(0.0)
            return out
        which = np.searchsorted(self._starts, u, side="right") - 1
        np.clip(which, 0, len(self.segments) - 1, out=which)
        for i in np.unique(which):
            m = which == i
            out[m] = self.segments[i].value((u[m] - self._starts[i]) / self.rate_hz)
        out[(u <= 0) | (u >= self.n_samples - 1)] = 0.0  # exactly 0 V at both ends
        return out

    def samples(self, start: int = 0, stop: int | None = None) -> Array:
        """Command samples ``start .. stop-1`` (V)."""
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        return self.at_index(np.arange(max(start, 0), stop, dtype=float))

    def times(self, start: int = 0, stop: int | None = None) -> Array:
        """Sample times ``start .. stop-1`` (s from the start of the waveform)."""
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        return np.arange(max(start, 0), stop, dtype=float) / self.rate_hz


class TooLongError(ValueError):
    """A composed waveform would exceed the allowed number of samples. For an edge ramp
    (``edge``): the volts it spans (``from_V`` to ``to_V``) and the protocol key that sets the
    piece it joins (``field``)."""

    def __init__(self, n: int, edge: bool, from_V: float = 0.0, to_V: float = 0.0, field: str = ""):
        super().__init__(f"{n} samples")
        self.n, self.edge = n, edge
        self.from_V, self.to_V, self.field = from_V, to_V, field


def compose(
    pieces: list[Segment],
    rate_hz: float,
    slew_V_per_s: float,
    edge_field: str = "",
    max_samples: int | None = None,
) -> Waveform:
    """Join ``pieces`` into a waveform starting and ending at 0 V, adding edge ramps as needed.

    Raises :class:`TooLongError` when the result would have more than ``max_samples`` intervals.
    """
    out: list[Segment] = []
    level = 0.0
    total = 0
    last_field = ""

    def add(seg: Segment, span: tuple[float, float] = (0.0, 0.0), joins: str = "") -> None:
        nonlocal total
        total += seg.n
        if max_samples is not None and total > max_samples:
            raise TooLongError(total, seg.role == "edge", *span, joins)
        out.append(seg)

    for p in pieces:
        if p.n <= 0:
            continue
        a, b = p.start_end(rate_hz)
        if abs(a - level) > JOIN_TOL_V:
            n = edge_samples(a - level, rate_hz, slew_V_per_s)
            add(ramp_segment(level, a, n, rate_hz, edge_field, role="edge"), (level, a), p.field)
        add(p)
        level = b
        last_field = p.field
    if abs(level) > JOIN_TOL_V:
        n = edge_samples(level, rate_hz, slew_V_per_s)
        edge = ramp_segment(level, 0.0, n, rate_hz, edge_field, role="edge")
        add(edge, (level, 0.0), last_field)
    return Waveform(out, rate_hz)
