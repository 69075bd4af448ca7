"""The ramp to 0 V: how every exit path brings the actuator down within the current limit.

The current into the stack is ``i = C_eff dV/dt``; the ramp runs at ``RAMP_CURRENT_FRACTION``
of the amplifier's peak current, so its slope is::

    rate = RAMP_CURRENT_FRACTION * i_peak_A / C_eff        (V/s; C_eff = C * large_signal_factor)

The ramp is paced by the wall clock, not by how fast a driver writes: the value written at
time ``t`` after the start is ``max(|V0| - rate * t, 0)`` (with the sign of ``V0``), and one
write never moves the output more than ``rate * RAMP_STEP_S`` beyond the previous one. A fast
link therefore writes small steps along the line; a slow one (each write taking longer than
``RAMP_STEP_S``) makes the ramp slower, never steeper. The written values and their times are
returned as a :class:`RampRecord` (the runner stores it in the run file).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from labrig.rig.limits import RigLimits

#: ramp-down current as a fraction of the amplifier's peak current
RAMP_CURRENT_FRACTION = 0.5
#: time between two writes of the ramp (s): the step is at most ``rate * RAMP_STEP_S`` volts
RAMP_STEP_S = 0.25e-3


def ramp_rate_V_per_s(limits: RigLimits) -> float:
    """Slope of the ramp to 0 V (V/s): ``RAMP_CURRENT_FRACTION * i_peak_A / C_eff``."""
    return RAMP_CURRENT_FRACTION * limits.i_peak_A / limits.effective_capacitance_F


@dataclass
class RampRecord:
    """One ramp to 0 V: where it started, how, and every value written with its time.

    ``times_s`` are wall-clock seconds since the ramp began (taken just before each write),
    ``volts`` the actuator voltages written (V), completed writes only. ``path`` is ``"daq"``
    (the DAQ's analog output), ``"amplifier setpoint"`` (the amplifier's digital setpoint, when
    the DAQ failed) or ``"none"`` (neither could be written; the amplifier was told to hold 0 V
    at once).
    """

    start_V: float
    start_source: str
    rate_V_per_s: float
    path: str = "none"
    times_s: list[float] = field(default_factory=list)
    volts: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.times_s[-1] if self.times_s else 0.0

    @property
    def reached_zero(self) -> bool:
        return bool(self.volts) and self.volts[-1] == 0.0


def paced_ramp(
    write: Callable[[float], None],
    from_V: float,
    rate_V_per_s: float,
    record: RampRecord | None = None,
    step_s: float = RAMP_STEP_S,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> None:
    """Write a linear ramp from ``from_V`` to exactly 0 V with ``write(volts)``, paced by
    ``clock`` (see the module docstring). Appends each completed write to ``record`` if given
    (its time taken just before the write); a failing ``write`` raises."""
    if not (math.isfinite(from_V) and math.isfinite(rate_V_per_s) and rate_V_per_s > 0):
        raise ValueError(f"cannot ramp from {from_V} V at {rate_V_per_s} V/s")
    sign = 1.0 if from_V >= 0 else -1.0
    v0 = abs(from_V)
    max_step = rate_V_per_s * step_s
    t0 = clock()
    level = v0
    now = t0
    while True:
        value = sign * level if level > 0 else 0.0
        write(value)
        if record is not None:
            record.times_s.append(now - t0)
            record.volts.append(value)
        if level <= 0:
            return
        due = now + step_s
        now = clock()
        if now < due:
            sleep(due - now)
            now = clock()
        # the line through (t0, V0) at the ramp's rate, but never more than one step per write
        level = max(v0 - rate_V_per_s * (now - t0), level - max_step, 0.0)
