"""Is a drive within the rig? Voltage range, peak and mean amplifier current.

:func:`check_drive` measures a drive with the protocol preflight's measurement
(:func:`labrig.rig.drive_load.measure_load`: peak current ``C_eff dV/dt`` on a grid finer than the
rate, with the drive linear between its samples and at rest at 0 V before them; mean ``|i|`` over
one command period, or 1 s), compares it and the drive's voltage range with a rig's
:class:`~labrig.rig.limits.RigLimits`, and raises :class:`InfeasibleCommandError` (a ``ValueError``)
saying what the command needs and what the rig gives. Compensation asks for negative voltages (to
cancel the drift, the paper's Fig. 17): within ``v_min_V`` they are allowed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from labrig.rig.drive_load import OVERSAMPLE, averaging_window_s, measure_load, window_points
from labrig.rig.limits import RigLimits

__all__ = ["DriveCheck", "InfeasibleCommandError", "check_drive"]


class InfeasibleCommandError(ValueError):
    """The drive a command needs is beyond the rig (voltage range or amplifier current).

    ``kind`` is ``"voltage"``, ``"peak_current"`` or ``"mean_current"``; ``needed`` and
    ``limit`` are in V or A; ``time_s`` is where in the command it happens.
    """

    def __init__(self, message: str, kind: str, needed: float, limit: float, time_s: float):
        super().__init__(message)
        self.kind, self.needed, self.limit, self.time_s = kind, needed, limit, time_s


@dataclass(frozen=True)
class DriveCheck:
    """What :func:`check_drive` measured on a drive."""

    v_min_V: float
    v_max_V: float
    peak_current_A: float
    peak_time_s: float
    mean_current_A: float
    mean_time_s: float
    window_s: float


def check_drive(
    v: ArrayLike,
    rate_hz: float,
    limits: RigLimits,
    frequency_hz: float | None = None,
    what: str = "the drive",
) -> DriveCheck:
    """Check a drive against ``limits`` like the protocol preflight; raise
    :class:`InfeasibleCommandError` naming what is needed and what the rig gives."""
    v = np.asarray(v, dtype=np.float64)
    if v.size == 0:
        return DriveCheck(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    dt = 1.0 / rate_hz
    # the drive starts from rest at 0 V (the step to v[0] counts); bringing the output back to
    # 0 V afterwards is the player's business (the protocol adds an edge ramp at its slew)
    vv = np.concatenate(([0.0], v))
    fine = np.interp(np.arange((vv.size - 1) * OVERSAMPLE + 1) / OVERSAMPLE, np.arange(vv.size), vv)
    fine_rate = rate_hz * OVERSAMPLE
    # no cap on the window here (the preflight caps it at MAX_WINDOW_POINTS)
    w = window_points(averaging_window_s(frequency_hz), fine_rate, cap=None)
    load = measure_load(lambda lo, hi: fine[lo:hi], fine.size, fine_rate, limits, w, chunk=None)
    # fine point j is at (j / OVERSAMPLE - 1) dt from the drive's first sample
    peak, peak_t = load.peak_current_A, (load.peak_index / OVERSAMPLE - 1) * dt
    mean, mean_t = load.mean_current_A, (load.mean_index / OVERSAMPLE - 1) * dt
    # the drive's own range (its samples, not the rest at 0 V before it), for the message's time
    vmin_i, vmax_i = int(np.argmin(v)), int(np.argmax(v))
    chk = DriveCheck(float(v[vmin_i]), float(v[vmax_i]), peak, peak_t, mean, mean_t, w / fine_rate)
    tol = 1e-9
    if chk.v_max_V > limits.v_max_V + tol or chk.v_min_V < limits.v_min_V - tol:
        hi = chk.v_max_V > limits.v_max_V + tol
        bad, at = (chk.v_max_V, vmax_i) if hi else (chk.v_min_V, vmin_i)
        lim = limits.v_max_V if hi else limits.v_min_V
        raise InfeasibleCommandError(
            f"{what} needs {bad:.4g} V at t = {at * dt:.4g} s; the rig allows "
            f"{limits.v_min_V:g} to {limits.v_max_V:g} V (lower the strain amplitude"
            + (
                ", or its frequency: compensation goes below 0 V to cancel the drift)"
                if not hi
                else ")"
            ),
            "voltage",
            bad,
            lim,
            at * dt,
        )
    if not peak <= limits.i_peak_A * (1 + 1e-6):
        raise InfeasibleCommandError(
            f"{what} needs {peak:.3g} A peak at t = {peak_t:.4g} s; the amplifier gives "
            f"{limits.i_peak_A:g} A (C_eff dV/dt with C_eff = "
            f"{limits.effective_capacitance_F * 1e6:.3g} uF; lower the amplitude or frequency)",
            "peak_current",
            peak,
            limits.i_peak_A,
            peak_t,
        )
    if not mean <= limits.i_avg_A * (1 + 1e-6):
        raise InfeasibleCommandError(
            f"{what} draws {mean:.3g} A on average over {chk.window_s:.3g} s (around "
            f"t = {mean_t:.4g} s); the amplifier's average limit is {limits.i_avg_A:g} A "
            "(lower the amplitude or frequency)",
            "mean_current",
            mean,
            limits.i_avg_A,
            mean_t,
        )
    return chk
