"""Effects of the electronics around the actuator: the amplifier's current limit, the measuring
chain's low-pass and delay, mains pickup, a drifting offset.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from labrig.model.effects.base import Context, Effect, Param, plus_minus

__all__ = [
    "AmplifierCurrentLimit",
    "MainsPickup",
    "OffsetDrift",
    "SensorLowpass",
    "TimeDelay",
    "measured_voltage",
    "slew_limit",
]


class AmplifierCurrentLimit(Effect):
    """The amplifier's output current ``i = C dV/dt`` is limited: the applied voltage slews at
    most at ``I / C``.

    Acts on the driving voltage. With the amplifier's measured output voltage in the run
    (``measured=True``) the model is simply driven by it (no parameter): if the residual vanishes
    the error is the amplifier's, not the actuator's. Without it, a pure slew limit with a fitted
    rate ``1 / inv_slew`` (parameter ``inv_slew_ms_per_V``, null 0: no limit).

    Signature: error at the largest ``dV/dt``, only above a threshold ``f A``, odd harmonics, a
    lag that grows with the amplitude at a fixed frequency. Confusable with a sensor low-pass
    and a delay; the monitor voltage tells them apart.
    """

    name = "amplifier_current_limit"
    where = "voltage"
    physics = "amplifier current limit: the applied voltage slews at most at I/C"
    signature = "error at the largest dV/dt, only above a threshold f*A, odd harmonics"
    confusable = ("sensor_lowpass", "time_delay")
    tell_apart = "record the amplifier's monitor voltage and compare it with the command"

    def __init__(self, measured: bool):
        self.measured = measured
        self.params = (
            () if measured else (Param("inv_slew_ms_per_V", "ms/V", 0.0, 0.0, 5.0, 0.1, sign=+1),)
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


class SensorLowpass(Effect):
    """A low-pass on the measured strain (conditioner or anti-alias filter): a second-order
    section ``1 / (1 + 2 zeta tau s + (tau s)^2)`` with a fitted cutoff ``fc = 1 / (2 pi tau)``
    and a fitted damping ``zeta`` (0.71: Butterworth, 0.87: Bessel-like, large: first order with
    ``tau_1 = 2 zeta tau``).

    Acts on the measured output. Signature: a quadrature residual (lagging the strain) growing
    with frequency, the same percentage at 50 and 100 V. Null: ``tau = 0``. Confusable with a
    delay (below the cutoff a Butterworth section *is* a delay of ``sqrt 2 tau`` to first order),
    a load resonance and the model's own ``G_d``.
    """

    name = "sensor_lowpass"
    where = "output"
    physics = "conditioner / anti-alias low-pass on the measured strain"
    signature = "quadrature residual growing with frequency, same % at 50 and 100 V"
    confusable = ("time_delay", "amplifier_current_limit")
    tell_apart = "calibrate the gauge chain with a known step or a multisine"
    params = (
        # cutoffs 16 Hz to 1.6 kHz: the cutoff trades against G_d's order (local optima)
        Param("tau_s", "s", 0.0, 0.0, 0.02, 5e-4, sign=+1, starts=(1e-4, 3e-4, 1e-3, 3e-3, 1e-2)),
        Param("zeta", "", 0.7, 0.2, 5.0, 0.7, check_bounds=False),
    )

    def apply(self, x, ctx, p):
        tau, zeta = p["tau_s"], p["zeta"]
        if tau <= 0:
            return x

        def design():
            bd, ad, _ = signal.cont2discrete(
                ([1.0], [tau * tau, 2 * zeta * tau, 1.0]), 1.0 / ctx.rate_hz, method="foh"
            )
            return np.atleast_1d(np.squeeze(bd)) / ad[0], np.asarray(ad, float) / ad[0]

        b, a = ctx.cached(("lp2", tau, zeta, ctx.rate_hz), design)
        zi = signal.lfilter_zi(b, a) * x[0]
        return signal.lfilter(b, a, x, zi=zi)[0]

    def physical(self, p):
        tau = p["tau_s"]
        return {
            "fc_hz": 1.0 / (2 * np.pi * tau) if tau > 0 else float("inf"),
            "zeta": p["zeta"],
            "tau_s": tau,
        }

    def describe(self, p, sd):
        tau, s = p["tau_s"], sd.get("tau_s")
        if tau <= 0:
            return "no low-pass"
        fc = 1.0 / (2 * np.pi * tau)
        return plus_minus("fc", fc, None if s is None else fc * s / tau, "Hz") + plus_minus(
            ", damping", p["zeta"], sd.get("zeta"), ""
        )


class TimeDelay(Effect):
    """A pure delay ``S(t - d)`` between drive and measurement (DAQ/conditioner latency).

    Acts on the measured output (fractional delay by linear interpolation). Signature: a
    quadrature residual proportional to frequency with no amplitude change. Null: ``d = 0``.
    Confusable with a low-pass (first order, they are indistinguishable at low frequency).
    """

    name = "time_delay"
    where = "output"
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


class MainsPickup(Effect):
    """Mains hum on the gauge cable: ``sum_h a_h sin(2 pi h f_m t + phi_h)``, ``h = 1, 2, 3``.

    Additive on the measured output, not locked to the drive; amplitudes and phases are per-entry
    nuisance parameters (six per entry). Signature: lines at 50/60 Hz (and harmonics) that are
    not harmonics of the drive, present at 0 V. Null: all amplitudes zero.
    """

    name = "mains_pickup"
    where = "nuisance"
    physics = "mains hum picked up by the gauge cable"
    signature = "lines at the mains frequency and its harmonics, not locked to the drive"
    confusable = ("drive harmonics",)
    tell_apart = "a 0 V hold entry (the hum stays); coherence across periods"
    harmonics = (1, 2, 3)

    def __init__(self, f_hz: float = 50.0):
        self.f_hz = float(f_hz)

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


class OffsetDrift(Effect):
    """Slow drift of the gauge zero: a per-entry offset and slope (nuisance parameters).

    Additive on the measured output, independent of the voltage. Signature: a trend independent
    of ``V``, present at 0 V. Null: zero offset and slope. Confusable with creep.
    """

    name = "offset_drift"
    where = "nuisance"
    physics = "drift of the strain gauge / bridge zero"
    signature = "a trend independent of the voltage, present at 0 V"
    confusable = ("creep", "thermal_drift")
    tell_apart = "a 0 V hold entry: drift continues, creep does not"

    def columns(self, t, rate_hz):
        tm = t - t.mean()
        return np.column_stack([np.ones_like(t), tm])

    def describe(self, p, sd):
        return "per-entry offset and slope"
