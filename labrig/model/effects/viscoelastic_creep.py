"""The ``viscoelastic_creep`` effect: one Kelvin-Voigt element (:class:`ViscoelasticCreep`,
its filter :func:`kelvin_voigt_filter`, which the compensation controller inverts).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Effect, Param, plus_minus
from labrig.model.modal import first_order_filter

__all__ = ["ViscoelasticCreep", "kelvin_voigt_filter"]


def kelvin_voigt_filter(
    c: float, tau_s: float, rate_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(b, a)`` (for ``lfilter``) of ``y = (1 - c) x + c LP[x]``, ``LP`` the first-order lag
    ``1 / (1 + tau s)`` sampled as ``lp[n] = A lp[n-1] + (1 - A) x[n]``, ``A = exp(-1/(rate tau))``:

        H(z) = ((1 - c A) - (1 - c) A z^-1) / (1 - A z^-1)

    DC gain 1, instantaneous gain ``1 - c A``; a step of ``x`` gives ``y = 1 - c A^(n+1)`` at
    sample ``n``, i.e. ``1 - c exp(-t/tau)`` at ``t = (n + 1) / rate``. Its zero
    ``A (1 - c) / (1 - c A)`` lies inside the unit circle for ``c < 1``, so the inverse
    ``lfilter(a, b, y)`` is causal and stable (what the compensation controller applies).
    """
    A = float(np.exp(-1.0 / (rate_hz * tau_s)))
    b = np.array([1.0 - c * A, -(1.0 - c) * A])
    a = np.array([1.0, -A])
    return b, a


class ViscoelasticCreep(Effect):
    """Linear viscoelastic creep, one Kelvin-Voigt element: ``S -> (1 - c) S + c LP_tau[S]``
    (:func:`kelvin_voigt_filter`), ``c`` the fraction of every strain change that arrives with
    the time constant ``tau``.

    Physics: the stack (ceramic, glue layers, preload spring) behaves as a spring in series with
    a spring-damper, the one-mode form of the creep operators used for piezo stacks (a sum of
    first-order lags); after a voltage step the strain creeps by ``c`` of the step and settles
    within a few ``tau``, unlike the logarithmic ``creep`` which keeps going for decades. Acts on
    the output of the operator (an actuator effect: the compensation controller inverts it).
    Signature: a residual that relaxes with one time constant after each level change and a
    gain that differs between ``f << 1/(2 pi tau)`` and ``f >> 1/(2 pi tau)``. Null: ``c = 0``.
    Confusable with ``creep``, ``offset_drift`` and the model's own slow relaxor ``G_t``.
    """

    name = "viscoelastic_creep"
    where = "output"
    acts_on = "operator output"
    params_doc = "`c` (0), `tau_s`"
    form = "`(1 - c) S + c LP_tau[S]`: one Kelvin-Voigt element"
    physics = "viscoelastic creep (one Kelvin-Voigt element: spring in series with spring-damper)"
    signature = "residual relaxing with one time constant after level changes"
    confusable = ("creep", "offset_drift")
    tell_apart = "a step-and-hold entry: the strain settles within a few tau, log creep does not"
    params = (
        Param("c", "", 0.0, -0.3, 0.5, 0.02, sign=+1),
        Param("tau_s", "s", 0.3, 1e-3, 30.0, 0.3, log=True, check_bounds=False, starts=(0.03, 3.0)),
    )

    def apply(self, x, ctx, p):
        c = p["c"]
        if c == 0.0:
            return x
        # (1 - c) x + c LP[x], the lag's gain 1 - A as -expm1: the same filter as
        # kelvin_voigt_filter's (b, a), whose numerator loses digits when A is near 1 (slow
        # lags at high rates: tau 30 s at 10 kHz leaves 1 - A = 3e-6)
        w = -1.0 / (ctx.rate_hz * p["tau_s"])
        lag = first_order_filter([-np.expm1(w)], [1.0, -np.exp(w)], x)
        return (1.0 - c) * x + c * lag

    def describe(self, p, sd):
        return plus_minus(
            "c", 100 * p["c"], None if sd.get("c") is None else 100 * sd["c"], "%"
        ) + (plus_minus(", tau", p["tau_s"], sd.get("tau_s"), "s"))
