"""The ``offset_sine`` step: a sine around a bias, with an envelope, a recorded ramp and settle.

An entry is, in order (each piece recorded; ``rate_hz`` sampling, pieces rounded to whole
sample intervals):

1. a raised-cosine ramp from 0 V to ``offset_V`` over ``ramp_s``;
2. ``offset_V`` held for ``settle_s``;
3. ``V = offset_V + e(t) A sin(2 pi f t)``, ``0 <= t <= T`` (``T = cycles / f`` or
   ``duration_s``), with ``e = 1`` (``constant``), ``t/T`` (``growing``) or ``1 - t/T``
   (``vanishing``); every envelope starts at ``offset_V`` (``sin 0 = 0``);
4. a raised-cosine ramp from where the sine ended (``offset_V`` after whole cycles) to 0 V
   over ``ramp_s``.

With ``ramp_s: 0`` and a non-zero offset the protocol's straight edge ramps
(``edge_slew_V_per_s``) take the place of the raised-cosine ones. The formulas are in
:mod:`labrig.protocol.waveforms`.
"""

from __future__ import annotations

from labrig.protocol import waveforms as wf
from labrig.protocol.concrete import num_tag
from labrig.protocol.schema import OffsetSineStep

__all__ = ["offset_sine_name", "offset_sine_parts"]


def offset_sine_name(step: OffsetSineStep) -> str:
    """``offset_sine_<offset>V_<A>V_<f>Hz_<envelope>``, e.g.
    ``offset_sine_m90V_60V_20Hz_growing``."""
    return (
        f"offset_sine_{num_tag(step.offset_V)}V_{num_tag(step.amplitude_V)}V_"
        f"{num_tag(step.frequency_hz)}Hz_{step.envelope}"
    )


def offset_sine_parts(
    step: OffsetSineStep, n_sine: int, n_ramp: int, n_settle: int, rate_hz: float
) -> tuple[list[wf.Segment], dict]:
    """The pieces of one entry and its definition, for a sine of ``n_sine`` sample intervals,
    ramps of ``n_ramp`` and a settle of ``n_settle`` (each may be 0 but the sine)."""
    v0, a, f = step.offset_V, step.amplitude_V, step.frequency_hz
    sine = wf.offset_sine_segment(v0, a, f, step.envelope, n_sine, rate_hz, "frequency_hz")
    _, end_V = sine.start_end(rate_hz)
    pieces = [
        wf.raised_cosine_segment(0.0, v0, n_ramp, rate_hz, "ramp_s"),
        wf.const_segment(v0, n_settle, "settle_s", kind="settle"),
        sine,
        wf.raised_cosine_segment(end_V, 0.0, n_ramp, rate_hz, "ramp_s"),
    ]
    start = (n_ramp + n_settle) / rate_hz
    definition = {
        "kind": "offset_sine",
        "offset_V": v0,
        "amplitude_V": a,
        "frequency_hz": f,
        "cycles": step.cycles if step.cycles is not None else step.duration_s * f,
        "envelope": step.envelope,
        "ramp_s": n_ramp / rate_hz,
        "settle_s": n_settle / rate_hz,
        "duration_s": n_sine / rate_hz,
        "sine_start_s": start,
        "sine_end_s": start + n_sine / rate_hz,
    }
    return pieces, definition
