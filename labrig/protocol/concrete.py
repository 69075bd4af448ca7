"""A concrete step while a protocol is expanded: its pieces, definition and derived name.

Shared by the expansion (:mod:`labrig.protocol.expand`) and the builders of single step kinds
(:mod:`labrig.protocol.offset_sine`); the plan's own types are in :mod:`labrig.protocol.plan`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from labrig.protocol import waveforms as wf
from labrig.protocol.plan import Where

__all__ = ["Concrete", "intervals", "num_tag", "sanitize"]


def num_tag(x: float) -> str:
    """Number for an entry name: 100 -> '100', 2.5 -> '2p5', -10 -> 'm10' (-0 -> '0')."""
    s = f"{x + 0.0:.6g}"  # + 0.0: -0.0 becomes 0.0
    return s.replace("-", "m").replace("+", "").replace(".", "p")


def sanitize(s: str) -> str:
    """``s`` with every run of characters outside ``[A-Za-z0-9_]`` replaced by ``_``."""
    s = re.sub(r"[^A-Za-z0-9_]+", "_", s).strip("_")
    return s or "data"


def intervals(seconds: float, rate_hz: float) -> int:
    """``round(seconds * rate_hz)`` without overflowing on absurd inputs."""
    x = seconds * rate_hz
    return round(x) if math.isfinite(x) and x < 2.0**62 else 2**62


@dataclass
class Concrete:
    """One repetition of a step: its waveform pieces (joined later by edge ramps), the JSON-able
    ``definition`` stored with the entry, where its keys are in the protocol file, and the
    amplitude (V) and frequency (Hz) preflight messages speak of."""

    kind: str
    base_name: str
    pieces: list[wf.Segment]
    definition: dict
    where: dict[str, Where]
    amplitude_V: float | None = None
    frequency_hz: float | None = None
    #: strain command (ue, one value per command sample) for strain-command steps
    strain: np.ndarray | None = None
