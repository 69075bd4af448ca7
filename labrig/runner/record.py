"""How a run ended, written into its run file: status and cause, exit code, the ramp to 0 V and
the amplifier's voltage after it (layout: docs/runfile.md, "How a run ended")."""

from __future__ import annotations

import logging
import math

import numpy as np

from labrig.rig.instruments import Rig
from labrig.rig.ramp import RAMP_CURRENT_FRACTION, RampRecord
from labrig.store import RunWriter

log = logging.getLogger("labrig.runner.execute")

#: the ramp record keeps at most this many points (evenly spaced writes, first and last kept)
RAMP_RECORD_POINTS = 4096


def record_end(
    writer: RunWriter, rig: Rig, ramp: RampRecord, status: str, reason: str, exit_code: int
) -> list[str]:
    """Write the run's end: ``status`` / ``status_reason`` (the run and a running entry),
    ``/run/exit_code``, ``/run/final_amplifier_voltage_V`` (read back now, after the ramp) and
    ``/run/ramp_to_zero``. Most important first; each part on its own, so a part that cannot
    be written (disk full) does not stop the others. Never raises: returns what failed."""
    problems: list[str] = []
    parts = (
        lambda: writer.finish(status, reason or None),
        lambda: writer.set_run_value(
            "exit_code", int(exit_code), long_name="exit code of labrig run for this run"
        ),
        lambda: _final_voltage(writer, rig),
        lambda: _ramp(writer, ramp),
    )
    for part in parts:
        try:
            part()
        except Exception as e:
            log.info("recording the run's end: %s", e)
            problems.append(str(e) or type(e).__name__)
    return list(dict.fromkeys(problems))


def _final_voltage(writer: RunWriter, rig: Rig) -> None:
    try:
        volts, err = float(rig.amplifier.read_voltage()), ""
    except Exception as e:
        volts, err = float("nan"), str(e) or type(e).__name__
    extra = {"error": err} if err else {}
    writer.set_run_value(
        "final_amplifier_voltage_V",
        volts,
        units="V",
        long_name="amplifier output voltage read back after the output was ramped to 0 V",
        **extra,
    )


def _ramp(writer: RunWriter, ramp: RampRecord) -> None:
    t = np.asarray(ramp.times_s, dtype=float)
    v = np.asarray(ramp.volts, dtype=float)
    if t.size > RAMP_RECORD_POINTS:
        keep = np.unique(np.linspace(0, t.size - 1, RAMP_RECORD_POINTS).round().astype(int))
        t, v = t[keep], v[keep]
    start = ramp.start_V if math.isfinite(ramp.start_V) else 0.0
    writer.add_run_collection(
        "ramp_to_zero",
        {
            "time": (t, "s", "wall-clock time since the ramp began, just before each write"),
            "voltage": (v, "V", "actuator voltage written"),
        },
        rate_limit_V_per_s=float(ramp.rate_V_per_s),
        current_fraction=float(RAMP_CURRENT_FRACTION),
        start_voltage_V=float(start),
        start_source=ramp.start_source,
        path=ramp.path,
        duration_s=float(ramp.duration_s),
        writes=len(ramp.times_s),
        errors="; ".join(ramp.errors),
    )
