"""The ``mechanical_resonance`` effect: the stack's (and sensor's) first mechanical resonance
on the measured strain (:class:`MechanicalResonance`, its filter :func:`resonance_filter`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["MechanicalResonance", "resonance_filter"]


def resonance_filter(
    tau_r: float, zeta: float, rate_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(b, a)`` (for ``lfilter``, ``a[0] = 1``) of ``1 / (1 + 2 zeta tau_r s + (tau_r s)^2)``
    sampled with a first-order hold (the strain is smooth between samples: exact for a strain
    linear between them; ``scipy.signal.cont2discrete``, method ``"foh"``)."""
    bd, ad, _ = signal.cont2discrete(
        ([1.0], [tau_r * tau_r, 2.0 * zeta * tau_r, 1.0]), 1.0 / rate_hz, method="foh"
    )
    b = np.atleast_1d(np.squeeze(bd)).astype(float)
    a = np.asarray(ad, float)
    return b / a[0], a / a[0]


class MechanicalResonance(Effect):
    """The first mechanical resonance of the stack with its load and the sensor's mount:
    ``S -> S / (1 + 2 zeta tau_r s + (tau_r s)^2)``, ``f_r = 1 / (2 pi tau_r)``, damping
    ``zeta`` (0.005-0.5, fitted on a log scale).

    Physics: the stack is a spring of stiffness ``k`` driving its own effective mass and the
    load ``m``; the strain the operator predicts is the free (quasi-static) stroke, the measured
    one follows ``m x'' + c x' + k x = k x_free``, a second-order low-pass with ``f_r =
    sqrt(k/m) / (2 pi)`` (kHz for a bare stack, hundreds of Hz with a heavy load) and a small
    damping (``zeta`` 0.01-0.2). Sine sweeps far below ``f_r`` barely see it; a PRBS, a
    triangle's corners and steps excite it (ringing at ``f_r``). Acts on the measured output
    (linear in the strain).

    Signature: ringing at ``f_r`` after every edge (PRBS, triangle corners, steps), a residual
    spectrum peaked at ``f_r``, a gain that *rises* towards ``f_r`` (peak ``~ 1 / (2 zeta)`` at
    ``f_r``) with a quadrature part growing with frequency below it. Null: ``tau_r = 0``.
    Confusable with ``sensor_lowpass``, which has the same form with a well-damped
    ``zeta >= 0.2`` (a conditioner's Butterworth/Bessel filter): told apart by the damping
    (below ``zeta = 1/sqrt 2`` the gain peaks above 1, a conditioner's filter never rings) and
    by the experiment: a resonance moves with the load (a mass added lowers ``f_r`` as
    ``1 / sqrt(m)``), a conditioner's cutoff does not and shows in a calibration of the gauge
    chain alone.
    """

    name = "mechanical_resonance"
    where = "output"
    acts_on = "measured strain (mechanics)"
    params_doc = "`tau_r_s` (0), `zeta` (0.005-0.5, log)"
    form = "`1/(1 + 2 zeta tau_r s + (tau_r s)^2)`, `f_r = 1/(2 pi tau_r)`, lightly damped"
    physics = "stack + load + sensor mount resonance (second-order, lightly damped)"
    signature = "ringing at f_r after edges (PRBS, triangle corners), gain rising towards f_r"
    confusable = ("sensor_lowpass", "time_delay")
    tell_apart = (
        "add a known mass to the load: a mechanical resonance moves as 1/sqrt(m), a "
        "conditioner's low-pass does not; a step rings (zeta < 0.5), a conditioner does not"
    )
    params = (
        # f_r from 32 Hz up: below that a resonance is not a stack's
        Param("tau_r_s", "s", 0.0, 0.0, 5e-3, 1e-4, sign=+1, starts=(3e-5, 3e-4, 1e-3)),
        Param("zeta", "", 0.1, 0.005, 0.5, 0.1, log=True, starts=(0.02, 0.3)),
    )

    def _filter(self, ctx, tau, zeta):
        return ctx.cached(
            ("resonance", tau, zeta, ctx.rate_hz), lambda: resonance_filter(tau, zeta, ctx.rate_hz)
        )

    def apply(self, x, ctx, p):
        tau = p["tau_r_s"]
        if tau <= 0:
            return x
        b, a = self._filter(ctx, tau, p["zeta"])
        zi = signal.lfilter_zi(b, a)  # at rest at the first sample
        if x.ndim == 2:
            return signal.lfilter(b, a, x, axis=0, zi=zi[:, None] * x[0][None, :])[0]
        return signal.lfilter(b, a, x, zi=zi * x[0])[0]

    def tangent_columns(self, x, dX, ctx, p):
        return self.apply(dX, ctx, p)  # linear: every column in one call

    def physical(self, p):
        tau = p["tau_r_s"]
        return {
            "f_r_hz": 1.0 / (2 * np.pi * tau) if tau > 0 else float("inf"),
            "zeta": p["zeta"],
            "tau_r_s": tau,
        }

    def describe(self, p, sd):
        tau, s = p["tau_r_s"], sd.get("tau_r_s")
        if tau <= 0:
            return "no resonance"
        f = 1.0 / (2 * np.pi * tau)
        return plus_minus("f_r", f, None if s is None else f * s / tau, "Hz") + plus_minus(
            ", damping", p["zeta"], sd.get("zeta"), ""
        )
