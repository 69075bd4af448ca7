"""The ``triangle``, ``prbs`` and ``multisine`` steps: their formulas, pieces and definitions.

Each is a drive around a bias ``V0 = offset_V`` with amplitude ``A = amplitude_V`` (0 V bias: a
bipolar drive; ``V0 = A``: unipolar from 0 V), played as one piece; where it does not start or
end at 0 V the protocol's straight edge ramps (``edge_slew_V_per_s``) are added by
:func:`labrig.protocol.waveforms.compose`. ``t`` is the piece's local time (s).

- triangle: ``V = V0 + A tri(f t + p)``, ``tri(x) = 4 |frac(x - 1/4) - 1/2| - 1`` (0 rising
  at x = 0, +1 at x = 1/4, -1 at x = 3/4); ``p = 0``
  (``start: bias``) or ``p = -1/4`` (``start: low``: -1 at t = 0, rising). The slope is
  ``+-4 A f``.
- prbs: chip ``k`` (``k / fc <= t < (k + 1) / fc``, ``fc = clock_hz``) sits at level ``L_k =
  V0 + A (2 b_k - 1)``, ``b`` the maximal-length LFSR bits (:func:`prbs_bits`); from the start
  of chip ``k`` the voltage goes from ``L_{k-1}`` to ``L_k`` along a straight ramp lasting
  ``transition_s`` (slew-limited edges: slope ``(L_k - L_{k-1}) / transition_s``); chip 0 starts
  at ``L_0``.
- multisine: ``V = V0 + A m(t) / M``, ``m(t) = sum_k cos(2 pi f_k t + phi_k)``, ``phi_k = -pi k
  (k - 1) / K`` over the ``K`` frequencies sorted ascending (Schroeder phases), ``M = max |m|``
  on a grid :data:`MULTISINE_PEAK_OVERSAMPLE` times finer than the output rate over the piece,
  a grid that holds the preflight's (4 times finer), so the preflight sees ``|V - V0| <= A``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from labrig.protocol import waveforms as wf
from labrig.protocol.concrete import num_tag
from labrig.protocol.schema import MultisineStep, PrbsStep, TriangleStep

__all__ = [
    "MULTISINE_PEAK_OVERSAMPLE",
    "multisine_parts",
    "prbs_bits",
    "prbs_parts",
    "schroeder_phases",
    "triangle_parts",
    "triangle_wave",
]

Array = NDArray[np.float64]
#: the multisine's peak ``M`` is found on a grid this many times finer than the output rate
MULTISINE_PEAK_OVERSAMPLE = 16
#: grid points evaluated at a time when the multisine's peak is searched
_CHUNK = 1 << 18


def triangle_wave(x: Array) -> Array:
    """``tri(x) = 4 |frac(x - 1/4) - 1/2| - 1``: period 1, 0 rising at x = 0, +1 at 1/4,
    -1 at 3/4 (dimensionless)."""
    u = np.asarray(x, dtype=float) - 0.25
    return 4.0 * np.abs(u - np.floor(u) - 0.5) - 1.0


def prbs_bits(order: int, seed: int, n_chips: int) -> NDArray[np.int8]:
    """``n_chips`` bits of the maximal-length LFSR of ``order`` bits started at the state whose
    bits (least significant first) are those of ``seed`` (``1 <= seed < 2**order``); period
    ``2**order - 1``. ``scipy.signal.max_len_seq`` with its default taps."""
    from scipy.signal import max_len_seq

    state = np.array([(seed >> i) & 1 for i in range(order)], dtype=np.int8)
    seq, _ = max_len_seq(order, state=state, length=n_chips)
    return seq.astype(np.int8)


def schroeder_phases(k: int) -> Array:
    """``phi_j = -pi j (j - 1) / k`` for ``j = 1..k`` (rad)."""
    j = np.arange(1, k + 1, dtype=float)
    return -np.pi * j * (j - 1.0) / k


# -- triangle ------------------------------------------------------------------------------


def triangle_segment(
    offset_V: float, amplitude_V: float, frequency_hz: float, start: str, n: int
) -> wf.Segment:
    p = -0.25 if start == "low" else 0.0

    def f(t: Array) -> Array:
        return offset_V + amplitude_V * triangle_wave(frequency_hz * np.asarray(t) + p)

    reach = (offset_V - abs(amplitude_V), offset_V + abs(amplitude_V))
    return wf.Segment("triangle", n, f, "frequency_hz", repeat_hz=frequency_hz, extremes=reach)


def triangle_name(s: TriangleStep) -> str:
    """``triangle_<V0>V_<A>V_<f>Hz``, e.g. ``triangle_50V_50V_2Hz``."""
    return f"triangle_{num_tag(s.offset_V)}V_{num_tag(s.amplitude_V)}V_{num_tag(s.frequency_hz)}Hz"


def triangle_parts(s: TriangleStep, n: int, rate_hz: float) -> tuple[list[wf.Segment], dict]:
    seg = triangle_segment(s.offset_V, s.amplitude_V, s.frequency_hz, s.start, n)
    definition = {
        "kind": "triangle",
        "offset_V": s.offset_V,
        "amplitude_V": s.amplitude_V,
        "frequency_hz": s.frequency_hz,
        "start": s.start,
        "cycles": s.cycles if s.cycles is not None else float(s.duration_s or 0.0) * s.frequency_hz,
        "duration_s": n / rate_hz,
    }
    return [seg], definition


# -- prbs ----------------------------------------------------------------------------------


def prbs_segment(levels: Array, clock_hz: float, transition_s: float, n: int) -> wf.Segment:
    """Chip levels ``levels`` (V) at ``clock_hz`` with straight transitions of ``transition_s``."""
    lv = np.asarray(levels, dtype=float)
    prev = np.concatenate(([lv[0]], lv[:-1]))
    last = lv.size - 1

    def f(t: Array) -> Array:
        t = np.asarray(t, dtype=float)
        k = np.clip(np.floor(t * clock_hz + 1e-9).astype(np.int64), 0, last)
        into = np.clip((t - k / clock_hz) / transition_s, 0.0, 1.0)
        return prev[k] + (lv[k] - prev[k]) * into

    return wf.Segment("prbs", n, f, "transition_s")


def prbs_name(s: PrbsStep) -> str:
    """``prbs_<V0>V_<A>V_<fc>Hz_o<order>_s<seed>``, e.g. ``prbs_0V_80V_20Hz_o7_s1``."""
    return (
        f"prbs_{num_tag(s.offset_V)}V_{num_tag(s.amplitude_V)}V_{num_tag(s.clock_hz)}Hz_"
        f"o{s.order}_s{s.seed}"
    )


def prbs_chips(s: PrbsStep) -> int:
    """Chips played: ``periods (2**order - 1)`` or ``ceil(duration_s clock_hz)``."""
    if s.periods is not None:
        return s.periods * (2**s.order - 1)
    return max(1, math.ceil(float(s.duration_s or 0.0) * s.clock_hz - 1e-9))


def prbs_parts(s: PrbsStep, n: int, rate_hz: float) -> tuple[list[wf.Segment], dict]:
    """The piece of ``n`` sample intervals and its definition (chips, levels, edges)."""
    chips = prbs_chips(s)
    bits = prbs_bits(s.order, s.seed, chips)
    levels = s.offset_V + s.amplitude_V * (2.0 * bits - 1.0)
    seg = prbs_segment(np.asarray(levels, dtype=np.float64), s.clock_hz, s.transition_s, n)
    definition = {
        "kind": "prbs",
        "offset_V": s.offset_V,
        "amplitude_V": s.amplitude_V,
        "low_V": s.offset_V - s.amplitude_V,
        "high_V": s.offset_V + s.amplitude_V,
        "clock_hz": s.clock_hz,
        "order": s.order,
        "seed": s.seed,
        "generator": "maximal-length LFSR (scipy.signal.max_len_seq)",
        "edges": "slew-limited: straight ramps of transition_s",
        "transition_s": s.transition_s,
        "chips": chips,
        "transitions": int(np.count_nonzero(np.diff(bits))),
        "duration_s": n / rate_hz,
    }
    return [seg], definition


# -- multisine -----------------------------------------------------------------------------


#: the most line-samples (lines x samples of the entry) a multisine may ask of its peak search
#: (``MULTISINE_PEAK_OVERSAMPLE`` times the entry's samples, each a sum over every line): about
#: 30 ns each, so that ``labrig check`` of one entry stays within about 20 s of CPU
MAX_MULTISINE_LINE_SAMPLES = 30_000_000


def multisine_work(n_lines: int, n_samples: int) -> int:
    """Line-samples of an entry's multisine: ``n_lines x n_samples`` (each sample a sum of every
    line); at most :data:`MAX_MULTISINE_LINE_SAMPLES`."""
    return n_lines * n_samples


def _multisine_sum(t: Array, freqs: Array, phases: Array) -> Array:
    t = np.asarray(t, dtype=float)
    out = np.zeros(t.shape)
    for f, p in zip(freqs, phases, strict=True):
        out += np.cos(2.0 * np.pi * f * t + p)
    return out


def multisine_peak(freqs: Array, phases: Array, length_s: float, rate_hz: float) -> float:
    """``max |m(t)|`` on ``0 <= t <= length_s`` on a grid ``MULTISINE_PEAK_OVERSAMPLE`` times
    finer than ``rate_hz``, a chunk at a time."""
    step = 1.0 / (rate_hz * MULTISINE_PEAK_OVERSAMPLE)
    n = round(length_s / step) + 1
    peak = 0.0
    for lo in range(0, n, _CHUNK):
        t = np.arange(lo, min(n, lo + _CHUNK), dtype=float) * step
        peak = max(peak, float(np.max(np.abs(_multisine_sum(t, freqs, phases)))))
    return peak


def multisine_segment(
    offset_V: float, amplitude_V: float, freqs: Array, phases: Array, peak: float, n: int
) -> wf.Segment:
    def f(t: Array) -> Array:
        return offset_V + amplitude_V * _multisine_sum(t, freqs, phases) / peak

    return wf.Segment("multisine", n, f, "amplitude_V")


def multisine_name(s: MultisineStep) -> str:
    """``multisine_<V0>V_<A>V_<K>f_<f_min>to<f_max>Hz``, e.g.
    ``multisine_0V_100V_8f_1to80Hz``."""
    lo, hi = min(s.frequencies_hz), max(s.frequencies_hz)
    return (
        f"multisine_{num_tag(s.offset_V)}V_{num_tag(s.amplitude_V)}V_{len(s.frequencies_hz)}f_"
        f"{num_tag(lo)}to{num_tag(hi)}Hz"
    )


def multisine_parts(s: MultisineStep, n: int, rate_hz: float) -> tuple[list[wf.Segment], dict]:
    freqs = np.sort(np.asarray(s.frequencies_hz, dtype=float))
    phases = schroeder_phases(freqs.size)
    peak = multisine_peak(freqs, phases, n / rate_hz, rate_hz)
    seg = multisine_segment(s.offset_V, s.amplitude_V, freqs, phases, peak, n)
    definition = {
        "kind": "multisine",
        "offset_V": s.offset_V,
        "amplitude_V": s.amplitude_V,
        "frequencies_hz": [float(x) for x in freqs],
        "phases_rad": [float(x) for x in phases],
        "phases": "Schroeder: -pi k (k - 1) / K",
        "line_amplitude_V": s.amplitude_V / peak,
        "crest_factor": peak / math.sqrt(freqs.size / 2.0),
        "duration_s": n / rate_hz,
    }
    return [seg], definition
