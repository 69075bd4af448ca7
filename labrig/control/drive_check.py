"""Is a drive within the rig? Voltage range, peak and mean amplifier current.

:func:`check_drive` measures a drive with the protocol preflight's measurement into the same
record (:func:`labrig.rig.drive_load.measure_load`, a :class:`~labrig.rig.drive_load.DriveLoad`:
peak current ``C_eff dV/dt`` on a grid finer than the rate, with the drive linear between its
samples and at rest at 0 V before them; mean ``|i|`` over one command period, or 1 s; the voltage
range of the drive's samples), compares it with a rig's :class:`~labrig.rig.limits.RigLimits`
as the preflight does, and raises :class:`InfeasibleCommandError` (a ``ValueError``)
saying what the command needs and what the rig gives. Compensation asks for negative voltages (to
cancel the drift, the paper's Fig. 17): within ``v_min_V`` they are allowed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from labrig.rig.drive_load import (
    OVERSAMPLE,
    DriveLoad,
    averaging_window_s,
    measure_load,
    window_points,
)
from labrig.rig.limits import RigLimits

__all__ = ["InfeasibleCommandError", "check_drive"]


class InfeasibleCommandError(ValueError):
    """The drive a command needs is beyond the rig (voltage range or amplifier current).

    ``kind`` is ``"voltage"``, ``"peak_current"`` or ``"mean_current"``; ``needed`` and
    ``limit`` are in V or A; ``time_s`` is where in the command it happens.
    """

    def __init__(self, message: str, kind: str, needed: float, limit: float, time_s: float):
        super().__init__(message)
        self.kind, self.needed, self.limit, self.time_s = kind, needed, limit, time_s


def check_drive(
    v: ArrayLike,
    rate_hz: float,
    limits: RigLimits,
    frequency_hz: float | None = None,
    what: str = "the drive",
) -> DriveLoad:
    """Check a drive (V, sampled at ``rate_hz``) against ``limits`` like the protocol preflight;
    return what it asks of the amplifier (times in s from its first sample; its voltage range
    that of its samples) or raise :class:`InfeasibleCommandError` naming what is needed and what
    the rig gives."""
    v = np.asarray(v, dtype=np.float64)
    if v.size == 0:
        return DriveLoad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, name=what)
    dt = 1.0 / rate_hz
    # the drive starts from rest at 0 V (the step to v[0] counts); bringing the output back to
    # 0 V afterwards is the player's business (the protocol adds an edge ramp at its slew)
    vv = np.concatenate(([0.0], v))
    fine = np.interp(np.arange((vv.size - 1) * OVERSAMPLE + 1) / OVERSAMPLE, np.arange(vv.size), vv)
    fine_rate = rate_hz * OVERSAMPLE
    # no cap on the window here (the preflight caps it at MAX_WINDOW_POINTS)
    w = window_points(averaging_window_s(frequency_hz), fine_rate, cap=None)
    # fine point j is at (j / OVERSAMPLE - 1) dt from the drive's first sample (0: the rest)
    load = measure_load(
        lambda lo, hi: fine[lo:hi],
        fine.size,
        fine_rate,
        limits,
        w,
        chunk=None,
        duration_s=v.size * dt,
        time_s=lambda j: (j / OVERSAMPLE - 1) * dt,
        name=what,
    )
    # the drive's own range (its samples, not the rest at 0 V before it), for the message's time
    vmin_i, vmax_i = int(np.argmin(v)), int(np.argmax(v))
    chk = replace(load, v_min_V=float(v[vmin_i]), v_max_V=float(v[vmax_i]))
    peak, peak_t = chk.peak_current_A, chk.peak_time_s
    mean, mean_t = chk.mean_current_A, chk.mean_time_s
    outside = chk.beyond_range(limits)
    if outside is not None:
        hi, bad = outside
        at = vmax_i if hi else vmin_i
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
    if chk.over_peak(limits):
        raise InfeasibleCommandError(
            f"{what} needs {peak:.3g} A peak at t = {peak_t:.4g} s; the amplifier gives "
            f"{limits.i_peak_A:g} A (C_eff dV/dt with C_eff = "
            f"{limits.effective_capacitance_F * 1e6:.3g} uF; lower the amplitude or frequency)",
            "peak_current",
            peak,
            limits.i_peak_A,
            peak_t,
        )
    if chk.over_mean(limits):
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
