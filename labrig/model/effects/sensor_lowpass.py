"""The ``sensor_lowpass`` effect: a low-pass on the measured strain (:class:`SensorLowpass`)."""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus
from labrig.model.sections import foh_section, run_section

__all__ = ["SensorLowpass"]


class SensorLowpass(Effect):
    """A low-pass on the measured strain (conditioner or anti-alias filter): a second-order
    section ``1 / (1 + 2 zeta tau s + (tau s)^2)`` with a fitted cutoff ``fc = 1 / (2 pi tau)``
    and a fitted damping ``zeta`` (0.71: Butterworth, 0.87: Bessel-like, large: first order with
    ``tau_1 = 2 zeta tau``), sampled with a first-order hold and at rest at the first sample
    (:mod:`labrig.model.sections`).

    Acts on the measured output. Signature: a quadrature residual (lagging the strain) growing
    with frequency, the same percentage at 50 and 100 V. Null: ``tau = 0``. Confusable with a
    delay (below the cutoff a Butterworth section *is* a delay of ``sqrt 2 tau`` to first order),
    a load resonance and the model's own ``G_d``.

    Refused (:meth:`refusals`) when the damping ends at its lower end (0.2, a peak of 2.55x, +8
    dB, at 0.96 times the cutoff): a conditioner's filter is not built with such a peak, and a
    fit that wants less damping still is a mechanical resonance (``mechanical_resonance``)
    borrowing the low-pass's form, and its cutoff then means nothing (the structural study's
    resonant stack was taken that way while ``mechanical_resonance`` could not be ranked). The
    upper end (5) is the first-order limit and is not a refusal. An over-damped fit (``zeta >
    1``) is two real poles, and ``fc`` alone then trades against ``zeta`` (poorly determined,
    which is reported as for any parameter known to no better than half its value):
    :meth:`describe` adds the two corners (on the real SmartHysteresis record, fc 59 Hz +- 860 %
    and damping 3.2 are a 9.4 Hz first-order lag, :meth:`real_corners_hz`).
    """

    name = "sensor_lowpass"
    where = "output"
    acts_on = "measured strain"
    params_doc = "`tau_s` (0), `zeta`"
    form = "second-order section, fitted cutoff `fc = 1/(2 pi tau)` and damping"
    physics = "conditioner / anti-alias low-pass on the measured strain"
    signature = "quadrature residual growing with frequency, same % at 50 and 100 V"
    confusable = ("time_delay", "amplifier_current_limit")
    tell_apart = "calibrate the gauge chain with a known step or a multisine"
    params = (
        # cutoffs 16 Hz to 1.6 kHz: the cutoff trades against G_d's order (local optima)
        Param("tau_s", "s", 0.0, 0.0, 0.02, 5e-4, sign=+1, starts=(1e-4, 3e-4, 1e-3, 3e-3, 1e-2)),
        Param("zeta", "", 0.7, 0.2, 5.0, 0.7, check_bounds=False),
    )

    #: a damping within this of its lower bound is "at" it (the fit's own bound test: 1e-6 of
    #: the range; a damping of 0.2005 is already resolved from the bound)
    AT_LOWER_DAMPING = 1e-4

    def refusals(self, p, sd):
        lo = self.params[1].lo
        zeta = p.get("zeta")
        if p.get("tau_s", 0.0) <= 0 or zeta is None or zeta > lo + self.AT_LOWER_DAMPING:
            return []
        fc = 1.0 / (2 * np.pi * p["tau_s"])
        return [
            f"damping = {zeta:.3g} ends at its resonant end ({lo:g}, a peak of "
            f"{1 / (2 * lo * np.sqrt(1 - lo * lo)):.3g}x near the cutoff): a conditioner's filter "
            f"has no such peak, so the fit (fc {fc:.3g} Hz) is a resonance, not a low-pass "
            "(try --also mechanical_resonance)"
        ]

    def apply(self, x, ctx, p):
        tau, zeta = p["tau_s"], p["zeta"]
        if tau <= 0:
            return x
        sec = ctx.cached(
            ("lp2", tau, zeta, ctx.rate_hz),
            lambda: foh_section([1.0], [tau * tau, 2 * zeta * tau, 1.0], ctx.rate_hz),
        )
        return run_section(sec, x)  # at rest at the first sample

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
        text = plus_minus("fc", fc, None if s is None else fc * s / tau, "Hz") + plus_minus(
            ", damping", p["zeta"], sd.get("zeta"), ""
        )
        poles = self.real_corners_hz(p)
        if poles is None:
            return text
        slow, fast = poles
        return (
            f"{text}: over-damped, two real poles at {slow:.3g} and {fast:.3g} Hz (a first-order "
            f"lag of corner {slow:.3g} Hz below {fast:.3g} Hz; fc and the damping trade against "
            "each other along it)"
        )

    def real_corners_hz(self, p) -> tuple[float, float] | None:
        """For a damping of 1 or more, the section's two real poles as corners (Hz), slow first:
        ``1 / (2 pi tau (zeta +- sqrt(zeta^2 - 1)))``; ``None`` below 1 (complex poles)."""
        tau, zeta = p["tau_s"], p["zeta"]
        if tau <= 0 or zeta < 1.0:
            return None
        r = np.sqrt(zeta * zeta - 1.0)
        return (
            float(1.0 / (2 * np.pi * tau * (zeta + r))),
            float(1.0 / (2 * np.pi * tau * (zeta - r))),
        )
