"""The ramp to 0 V keeps its pace on its own clock: :func:`labrig.rig.ramp.paced_ramp` driven by
a clock and a sleep the test owns (no wall clock, so machine load cannot change the outcome).
Writes that take less than a step: the ramp is done in ``V0 / rate`` (within a step), never
faster; every written level is on or above the line ``V0 - rate t``. (Writes slower than a step
pace the ramp by design, one step of ``rate * step`` per write: the integration test in
``test_safety_ramp.py`` counts the writes against that plan.)"""

from __future__ import annotations

import pytest

from labrig.rig.ramp import RAMP_STEP_S, RampRecord, paced_ramp


class FakeClock:
    """Seconds that move only when the ramp writes (``write_s`` each) or sleeps."""

    def __init__(self, write_s: float) -> None:
        self.t = 0.0
        self.write_s = write_s
        self.written: list[tuple[float, float]] = []

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        assert seconds >= 0
        self.t += seconds

    def write(self, volts: float) -> None:
        self.written.append((self.t, volts))
        self.t += self.write_s


@pytest.mark.parametrize("write_steps", [0.0, 0.5, 0.99])
@pytest.mark.parametrize("v0", [80.0, -37.5])
def test_the_ramp_takes_v0_over_rate_when_writes_are_quick(write_steps, v0):
    rate = 880.0  # V/s
    clock = FakeClock(write_steps * RAMP_STEP_S)
    rec = RampRecord(v0, "test", rate)
    paced_ramp(clock.write, v0, rate, rec, clock=clock.now, sleep=clock.sleep)
    t_end, v_end = clock.written[-1]
    assert v_end == 0.0 and rec.reached_zero
    ideal = abs(v0) / rate
    assert ideal - RAMP_STEP_S <= t_end <= ideal + 2 * RAMP_STEP_S, (t_end, ideal)
    for t, v in clock.written:  # never below the line: the current limit holds
        assert abs(v) >= abs(v0) - rate * t - 1e-9, (t, v)
        assert v == 0.0 or (v > 0) == (v0 > 0)


def test_a_ramp_slower_than_its_line_fails_the_check():
    """The check above can fail: a ramp sleeping twice its step between writes ends late."""
    rate, v0 = 880.0, 80.0
    clock = FakeClock(0.0)
    paced_ramp(clock.write, v0, rate, None, step_s=2 * RAMP_STEP_S, clock=clock.now,
               sleep=lambda s: clock.sleep(2 * s))  # fmt: skip
    assert clock.written[-1][0] > v0 / rate + 2 * RAMP_STEP_S
