"""The ``offset_drift`` effect: a drifting gauge zero, per-entry nuisance terms
(:class:`OffsetDrift`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect

__all__ = ["OffsetDrift"]


class OffsetDrift(Effect):
    """Slow drift of the gauge zero: a per-entry offset and slope (nuisance parameters).

    Additive on the measured output, independent of the voltage. Signature: a trend independent
    of ``V``, present at 0 V. Null: zero offset and slope. Confusable with creep.
    """

    name = "offset_drift"
    where = "nuisance"
    acts_on = "measured strain (nuisance)"
    params_doc = "per-entry offset and slope"
    form = "additive"
    physics = "drift of the strain gauge / bridge zero"
    signature = "a trend independent of the voltage, present at 0 V"
    confusable = ("creep", "thermal_drift")
    tell_apart = "a 0 V hold entry: drift continues, creep does not"

    def columns(self, t, rate_hz):
        tm = t - t.mean()
        return np.column_stack([np.ones_like(t), tm])

    def describe(self, p, sd):
        return "per-entry offset and slope"
