"""The ``mains_pickup`` effect: mains hum on the gauge cable, per-entry nuisance terms
(:class:`MainsPickup`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect

__all__ = ["MainsPickup"]


class MainsPickup(Effect):
    """Mains hum on the gauge cable: ``sum_h a_h sin(2 pi h f_m t + phi_h)``, ``h = 1, 2, 3``.

    Additive on the measured output, not locked to the drive; amplitudes and phases are per-entry
    nuisance parameters (six per entry). Signature: lines at 50/60 Hz (and harmonics) that are
    not harmonics of the drive, present at 0 V. Null: all amplitudes zero.
    """

    name = "mains_pickup"
    where = "nuisance"
    acts_on = "measured strain (nuisance)"
    params_doc = "per-entry sin/cos at 1, 2, 3 x 50 or 60 Hz"
    form = "additive, not locked to the drive"
    physics = "mains hum picked up by the gauge cable"
    signature = "lines at the mains frequency and its harmonics, not locked to the drive"
    confusable = ("drive harmonics",)
    tell_apart = "a 0 V hold entry (the hum stays); coherence across periods"
    harmonics = (1, 2, 3)

    def __init__(self, mains_hz: float = 50.0):
        #: the mains frequency (Hz)
        self.f_hz = float(mains_hz)

    def columns(self, t, rate_hz):
        cols = []
        for h in self.harmonics:
            f = h * self.f_hz
            if f >= 0.5 * rate_hz:
                continue
            w = 2 * np.pi * f * t
            cols += [np.sin(w), np.cos(w)]
        return np.column_stack(cols) if cols else np.zeros((t.size, 0))

    def describe(self, p, sd):
        return f"f = {self.f_hz:g} Hz and harmonics, per-entry amplitude and phase"
