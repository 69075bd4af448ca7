"""What the preflight measured on one planned entry (its voltage range and amplifier currents)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["StepCheck"]


@dataclass(frozen=True)
class StepCheck:
    """What preflight measured on one entry: voltage range (V), the peak current (A) and when
    (s from the entry's start), the largest mean ``|i|`` (A) over ``window_s`` and when that window
    ends, and the entry's duration (s)."""

    name: str
    v_min_V: float
    v_max_V: float
    peak_current_A: float
    peak_time_s: float
    mean_current_A: float
    mean_time_s: float
    window_s: float
    duration_s: float
