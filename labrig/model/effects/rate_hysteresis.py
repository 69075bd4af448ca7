"""The ``rate_hysteresis`` effect: a rate-dependent Duhem (Bouc-Wen-type) hysteresis term beside
the operator (:class:`RateHysteresis`, its state :func:`rate_hysteresis_state`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from labrig.model.accel import kernels
from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["RateHysteresis", "rate_hysteresis_state"]


def rate_hysteresis_state(
    x: NDArray[np.float64], A: float, beta: float, tau_h: float, rate_hz: float
) -> NDArray[np.float64]:
    """``h`` (ue) of ``dh/dt = A dx/dt - beta |dx/dt| h - h / tau_h`` over ``x`` (V, linear
    between samples), ``h = 0`` at the first sample.

    Exact per sample interval: the rate ``d / dt`` (``d = x[n] - x[n-1]``) is constant there, so
    the equation is linear with constant coefficients and, with ``z = beta |d| + dt / tau_h``,
    ``h[n] = h[n-1] exp(-z) + A d (1 - exp(-z)) / z``. The compiled kernel
    (:func:`labrig.model.compiled.rate_hysteresis_run`) runs it; this loop is its reference and
    the fallback without numba.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    inv = 1.0 / (rate_hz * tau_h)
    k = kernels()
    if k is not None:
        return k.rate_hysteresis_run(x, float(A), float(beta), float(inv))
    h = np.zeros(x.size)
    hk = 0.0
    xs = x.tolist()
    for n in range(1, len(xs)):
        d = xs[n] - xs[n - 1]
        z = beta * abs(d) + inv
        if z > 1e-12:
            hk = hk * math.exp(-z) + A * d * (-math.expm1(-z) / z)
        else:
            hk = hk * (1.0 - z) + A * d * (1.0 - 0.5 * z)
        h[n] = hk
    return h


#: a fitted ``tau_h`` at or above this share of its upper bound is "no relaxation seen"
NO_RELAXATION_SHARE = 0.5


class RateHysteresis(Effect):
    """Rate-dependent hysteresis beside the operator: ``S = H[V*] + h``,

        dh/dt = A dV*/dt - beta |dV*/dt| h - h / tau_h

    (a Duhem model: Bouc-Wen's ``n = 1``, ``gamma = 0`` element with a relaxation ``-h/tau_h``;
    :func:`rate_hysteresis_state`, exact per sample interval).

    Physics: part of the ceramic's domain-wall motion is viscous: it follows the field with a
    lag ``tau_h`` and relaxes back when the field stops. Slow drives (period ``>> tau_h``) let
    ``h`` relax (``h ~ A tau_h dV/dt``: no loop); fast drives leave it no time, and ``h`` becomes
    a Bouc-Wen loop that saturates at ``|h| = |A| / beta``: the loop's width grows with the rate
    around ``f ~ 1 / (2 pi tau_h)`` (tens to hundreds of Hz), which the paper's rate-independent
    operator cannot hold (its ``G_d`` lags the voltage by the same phase at every amplitude).
    Rate-dependent Bouc-Wen and Duhem forms are the usual models of this for piezo stacks (e.g.
    the fractional-order normalised Bouc-Wen model of Kang et al., 2020; the extended Bouc-Wen
    model of Tatebatake and Fujii, 2017). ``A < 0`` (``S = H - |A| ...``, the Bouc-Wen
    convention for piezo stacks) widens the loop the usual way (the strain lags) and lowers the
    gain at high rate. Acts beside the operator, on the relaxed voltage.

    Signature: a quadrature residual whose share grows with frequency above ``~1/(2 pi tau_h)``
    and less than proportionally with amplitude (the term saturates at ``|A| / beta``); the
    loop's width depends on the rate. Null: ``A = 0``. Confusable with ``sensor_lowpass`` and
    ``time_delay`` (a quadrature that is the same percentage at every amplitude), ``remanence``
    (rate independent, stays at 0 V) and the model's own ``G_d``.
    """

    name = "rate_hysteresis"
    where = "operator"
    acts_on = "beside the operator"
    params_doc = "`A_ue_per_V` (0), `beta_per_V` (log), `tau_h_s` (log)"
    form = "`H[V*] + h`, `dh/dt = A dV*/dt - beta |dV*/dt| h - h/tau_h` (Duhem)"
    physics = "rate-dependent (viscous) domain-wall hysteresis: loop width growing with rate"
    signature = "quadrature growing with frequency above 1/(2 pi tau_h), sublinear in amplitude"
    confusable = ("sensor_lowpass", "time_delay", "remanence")
    tell_apart = (
        "sines at one frequency and two amplitudes: a rate hysteresis saturates (its share falls "
        "with amplitude), a low-pass or delay is the same share; hold 0 V after an excursion: "
        "it relaxes with tau_h, remanence stays"
    )
    params = (
        Param("A_ue_per_V", "ue/V", 0.0, -8.0, 8.0, -0.3, starts=(0.3,)),
        Param(
            "beta_per_V",
            "1/V",
            0.02,
            1e-3,
            0.5,
            0.02,
            log=True,
            check_bounds=False,
            starts=(0.003, 0.2),
        ),
        # the upper end is a physical limit, not a failure: a relaxation slower than the
        # records (no relaxation seen) leaves the rate-independent Bouc-Wen element (caveats)
        Param(
            "tau_h_s",
            "s",
            3e-3,
            5e-5,
            1.0,
            3e-3,
            log=True,
            check_bounds=False,
            starts=(3e-4, 3e-2),
        ),
    )

    def probes(self, contexts):
        return [
            {"A_ue_per_V": -0.3, "beta_per_V": 0.02, "tau_h_s": tau} for tau in (3e-4, 3e-3, 3e-2)
        ]

    def caveats(self, p, span_s):
        """A relaxation time beyond the longest sequence (or at its bound): no relaxation is
        seen, and the term is the rate-independent Bouc-Wen element there."""
        tau = p.get("tau_h_s")
        hi = self.params[2].hi
        if tau is None or (tau < span_s and tau < NO_RELAXATION_SHARE * hi):
            return []
        return [
            f"tau_h = {tau:.3g} s is at the slow end of its range (bound {hi:g} s; the longest "
            f"sequence {span_s:.3g} s): no relaxation is resolved, so the term acts as a "
            "rate-independent hysteresis (a Bouc-Wen loop beside the operator's) rather than a "
            "rate-dependent one"
        ]

    def apply(self, x, ctx, p):
        A = p["A_ue_per_V"]
        if A == 0.0:
            return np.zeros(x.size)
        return rate_hysteresis_state(x, A, p["beta_per_V"], p["tau_h_s"], ctx.rate_hz)

    def physical(self, p):
        return {
            **{k: float(v) for k, v in p.items()},
            "f_h_hz": 1.0 / (2 * np.pi * p["tau_h_s"]),
            "h_sat_ue": abs(p["A_ue_per_V"]) / p["beta_per_V"],
        }

    def describe(self, p, sd):
        return (
            plus_minus("A", p["A_ue_per_V"], sd.get("A_ue_per_V"), "ue/V")
            + ", "
            + plus_minus("beta", p["beta_per_V"], sd.get("beta_per_V"), "1/V")
            + ", "
            + plus_minus(
                "tau_h",
                1e3 * p["tau_h_s"],
                None if sd.get("tau_h_s") is None else 1e3 * sd["tau_h_s"],
                "ms",
            )
        )
