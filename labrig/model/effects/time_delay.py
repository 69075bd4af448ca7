"""The ``time_delay`` effect: latency between the drive and the measured strain
(:class:`TimeDelay`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["TimeDelay"]


class TimeDelay(Effect):
    """A pure delay ``S(t - d)`` between drive and measurement (DAQ/conditioner latency).

    Acts on the measured output (fractional delay by linear interpolation). Signature: a
    quadrature residual proportional to frequency with no amplitude change. Null: ``d = 0``.
    Confusable with a low-pass (first order, they are indistinguishable at low frequency).
    """

    name = "time_delay"
    where = "output"
    acts_on = "measured strain"
    params_doc = "`delay_s` (0)"
    form = "`S(t - d)`, fractional"
    physics = "latency between the drive and the measured strain"
    signature = "quadrature residual proportional to frequency, no amplitude change"
    confusable = ("sensor_lowpass",)
    tell_apart = "a DAQ loopback (AO into AI) measures the latency directly"
    params = (Param("delay_s", "s", 0.0, 0.0, 0.02, 2e-4, sign=+1),)

    def apply(self, x, ctx, p):
        d = p["delay_s"] * ctx.rate_hz
        if d <= 0:
            return x
        k = int(np.floor(d))
        f = d - k
        y = np.empty_like(x)
        # x before the sequence: its first value (at rest)
        xs = np.concatenate([np.full(k + 1, x[0]), x])
        n = x.size
        y[:] = (1 - f) * xs[1 : n + 1] + f * xs[0:n]
        return y

    def describe(self, p, sd):
        s = sd.get("delay_s")
        return plus_minus("delay", 1e3 * p["delay_s"], None if s is None else 1e3 * s, "ms")
