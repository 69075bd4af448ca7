"""The ``amplifier_bandwidth`` effect: the amplifier's small-signal bandwidth on the actuator's
capacitance, a first-order low-pass on the driving voltage (:class:`AmplifierBandwidth`, its
filter :func:`first_order_lowpass`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["AmplifierBandwidth", "first_order_lowpass"]


def first_order_lowpass(
    tau_s: float, rate_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(b, a)`` (for ``lfilter``) of ``1 / (1 + tau s)`` on sampled data, ``dt = 1 / rate``,
    ``A = exp(-dt / tau)``, ``r = (tau / dt)(1 - A)``:

        y[n] = A y[n-1] + (1 - r) x[n] + (r - A) x[n-1]

    It is exact for both holds of :class:`~labrig.model.effects.base.Context`: for ``x`` linear
    between samples (``"linear"``, a first-order hold) ``y[n]`` is the filter's output at
    ``t_n``; for ``x[n]`` held over an interval (``"zoh"``) it is the mean of the filter's
    output over that interval, which is how the model's relaxors read a held sample (the two
    coincide). DC gain 1; ``y -> x`` as ``tau -> 0`` (``A, r -> 0``).
    """
    dt = 1.0 / rate_hz
    A = float(np.exp(-dt / tau_s))
    r = float(-np.expm1(-dt / tau_s)) * tau_s / dt
    return np.array([1.0 - r, r - A]), np.array([1.0, -A])


class AmplifierBandwidth(Effect):
    """The amplifier's small-signal bandwidth on the capacitive load: ``V -> LP_tau[V]``,
    ``LP = 1 / (1 + tau s)`` (:func:`first_order_lowpass`), ``fc = 1 / (2 pi tau)``.

    Physics: a voltage amplifier driving a stack of capacitance ``C`` through its output
    resistance ``R_o`` (or its feedback loop's own pole) applies a first-order low-pass of the
    command, ``tau ~ R_o C`` (e.g. 10 ohm and 2 uF: 20 us, 8 kHz; a slow high-voltage amplifier
    on a large stack: hundreds of us). Unlike ``amplifier_current_limit`` (a slew limit, large
    signal only) it acts at every amplitude the same way. Acts on the driving voltage, so the
    hysteresis operator sees the lagged voltage (the loop's width is not changed, its phase is).

    Signature: a quadrature residual growing with frequency, the same percentage at every
    amplitude; on a PRBS or a step, a rounded edge of time constant ``tau`` in the strain and in
    the amplifier's monitor voltage. Null: ``tau = 0``. Confusable with ``sensor_lowpass`` and
    ``time_delay`` (the same lag, on the measurement instead of the drive) and the model's own
    ``G_d``; the amplifier's monitor voltage tells them apart (the lag is already in it), and
    through the hysteresis a lag before the operator changes the loop's shape, one after it
    does not.
    """

    name = "amplifier_bandwidth"
    where = "voltage"
    acts_on = "driving voltage"
    params_doc = "`tau_amp_s` (0)"
    form = "first-order low-pass `1/(1 + tau s)` on the voltage (exact sampled form)"
    physics = "amplifier small-signal bandwidth on the capacitive load (R_o C)"
    signature = "quadrature residual growing with frequency, same % at every amplitude"
    confusable = ("sensor_lowpass", "time_delay", "amplifier_current_limit")
    tell_apart = (
        "record the amplifier's monitor voltage: its lag behind the command is this effect; a "
        "lag only in the strain is the sensor's"
    )
    params = (Param("tau_amp_s", "s", 0.0, 0.0, 5e-3, 1e-4, sign=+1, starts=(2e-5, 3e-4, 1e-3)),)

    def apply(self, x, ctx, p):
        tau = p["tau_amp_s"]
        if tau <= 0:
            return x
        b, a = ctx.cached(
            ("amp_lp", tau, ctx.rate_hz), lambda: first_order_lowpass(tau, ctx.rate_hz)
        )
        zi = signal.lfilter_zi(b, a) * x[0]  # at rest at the first sample
        return signal.lfilter(b, a, x, zi=zi)[0]

    def physical(self, p):
        tau = p["tau_amp_s"]
        return {"fc_hz": 1.0 / (2 * np.pi * tau) if tau > 0 else float("inf"), "tau_amp_s": tau}

    def describe(self, p, sd):
        tau, s = p["tau_amp_s"], sd.get("tau_amp_s")
        if tau <= 0:
            return "no amplifier low-pass"
        fc = 1.0 / (2 * np.pi * tau)
        return plus_minus("amplifier bandwidth", fc, None if s is None else fc * s / tau, "Hz")
