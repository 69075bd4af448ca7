"""The ``amplifier_current_limit`` effect: the amplifier's current limit makes the applied
voltage slew (:class:`AmplifierCurrentLimit`, with :func:`slew_limit` and
:func:`measured_voltage`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Context, Effect, Param, plus_minus

__all__ = ["AmplifierCurrentLimit", "measured_voltage", "slew_limit"]


class AmplifierCurrentLimit(Effect):
    """The amplifier's output current ``i = C dV/dt`` is limited: the applied voltage slews at
    most at ``I / C``.

    Acts on the driving voltage. With the amplifier's measured output voltage in the run
    (``amplifier_voltage=True``) the model is simply driven by it (no parameter): if the residual
    vanishes the error is the amplifier's, not the actuator's. Without it, a pure slew limit with
    a fitted rate ``1 / inv_slew`` (parameter ``inv_slew_ms_per_V``, null 0: no limit).

    Signature: error at the largest ``dV/dt``, only above a threshold ``f A``, odd harmonics, a
    lag that grows with the amplitude at a fixed frequency. Confusable with a sensor low-pass
    and a delay; the monitor voltage tells them apart.
    """

    name = "amplifier_current_limit"
    where = "voltage"
    acts_on = "driving voltage"
    params_doc = (
        "none when the run has `amplifier_voltage` (the model is driven by it where it departs "
        "from the command by more than 5 noise sigma); else `inv_slew_ms_per_V` (0)"
    )
    form = "pure slew limit `|dV/dt| <= I/C`"
    physics = "amplifier current limit: the applied voltage slews at most at I/C"
    signature = "error at the largest dV/dt, only above a threshold f*A, odd harmonics"
    confusable = ("sensor_lowpass", "time_delay")
    tell_apart = "record the amplifier's monitor voltage and compare it with the command"

    def __init__(self, amplifier_voltage: bool):
        #: the run recorded the amplifier's output voltage: the model is driven by it
        self.measured = amplifier_voltage
        self.params = (
            ()
            if amplifier_voltage
            else (Param("inv_slew_ms_per_V", "ms/V", 0.0, 0.0, 5.0, 0.1, sign=+1),)
        )

    def probes(self, contexts):
        if self.measured:
            return [{}]
        top = max(float(np.max(np.abs(np.diff(c.v)))) * c.rate_hz for c in contexts)  # V/s
        if not top > 0:
            return [self.init]
        return [{"inv_slew_ms_per_V": 1e3 / (frac * top)} for frac in (0.9, 0.7, 0.5)]

    def apply(self, x, ctx, p):
        if self.measured:
            return measured_voltage(ctx)
        inv = p["inv_slew_ms_per_V"]
        if inv <= 0:
            return x
        return slew_limit(x, 1e3 / inv, ctx.rate_hz)

    def physical(self, p):
        if self.measured:
            return {"source": "measured amplifier_voltage"}  # type: ignore[dict-item]
        inv = p["inv_slew_ms_per_V"]
        return {"slew_V_per_ms": (1.0 / inv) if inv > 0 else float("inf"), **dict(p)}

    def describe(self, p, sd):
        if self.measured:
            return "model driven by the measured amplifier voltage"
        inv, s = p["inv_slew_ms_per_V"], sd.get("inv_slew_ms_per_V")
        if inv <= 0:
            return "no slew limit"
        rate = 1.0 / inv
        srate = None if s is None else rate * s / inv
        return plus_minus("slew limit", rate, srate, "V/ms")


def measured_voltage(ctx: Context) -> NDArray:
    """The command where the measured amplifier voltage agrees with it to within its noise
    (5 robust sigma), the measurement where it departs: monitor noise fed to the operator makes
    a reversal at every sample (a tiny minor loop each with return-point memory; with the
    single-memory rule it would forget the whole history every sample)."""
    key = ("measured_v",)
    if key not in ctx.cache:
        m = ctx.amplifier_voltage
        d = m - ctx.v
        # noise from the quietest tenth of the sample-to-sample changes (|N(0, s)| has its
        # 10th percentile at 0.1257 s), robust when most of the record departs
        sigma = float(np.percentile(np.abs(np.diff(d)), 10)) / 0.1257 / np.sqrt(2.0)
        ctx.cache[key] = np.where(np.abs(d) > 5.0 * sigma + 1e-12, m, ctx.v)
    return ctx.cache[key]


def slew_limit(v: NDArray, rate_V_per_s: float, rate_hz: float) -> NDArray:
    """``v`` with its per-sample change limited to ``rate / rate_hz`` (from 0 V at rest)."""
    step = rate_V_per_s / rate_hz
    d = np.diff(v, prepend=0.0)
    if float(np.max(np.abs(d))) <= step:
        return v
    out = np.empty_like(v)
    y = 0.0
    # the loop only runs where the limit can act; elsewhere the output follows the input
    for i, x in enumerate(v.tolist()):
        dd = x - y
        if dd > step:
            y += step
        elif dd < -step:
            y -= step
        else:
            y = x
        out[i] = y
    return out
