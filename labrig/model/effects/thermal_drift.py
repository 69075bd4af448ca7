"""The ``thermal_drift`` effect: self-heating changes the piezo gain (:class:`ThermalDrift`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Context, Effect, Param, fmt3, plus_minus
from labrig.model.modal import first_order_filter

__all__ = ["ThermalDrift"]


class ThermalDrift(Effect):
    """Self-heating changes the piezo gain: ``S -> S (1 + k theta)``.

    Physics: dielectric loss ``P ~ pi f C tan(delta) Vpp^2 / 4`` heats the stack (tens of kelvin
    at 40 Hz, full amplitude); the piezo coefficient rises with temperature (about 0.1-0.5 %/K).
    Acts on the operator's output (a slowly varying gain).

    - With a temperature channel: ``theta = T - T_ref`` (K), ``T_ref`` the campaign's first
      temperature sample (:attr:`Context.temperature_ref`, common to all its sequences, so the
      gain of a hot entry is compared with a cool one), one parameter ``k_per_K``.
    - Without: ``theta`` is a first-order thermal state driven by each entry's mean loss power
      ``P_e ~ mean |dV/dt (V - mean V)|`` (zero during rests), normalised to 1 for the most
      lossy entry: parameters ``k_rel`` (gain change at that entry's steady temperature) and
      ``tau_th_s`` (thermal time constant).

    Signature: a gain error that grows through the hot (high ``f A^2``) entries and depends on
    the run order; correlates with the temperature channel. Null: ``k = 0``.
    """

    name = "thermal_drift"
    where = "output"
    acts_on = "operator gain"
    params_doc = "`k_per_K` (0) with a temperature channel; else `k_rel` (0), `tau_th_s`"
    form = (
        "`S (1 + k theta)`, `theta = T - T_ref` with `T_ref` the campaign's first temperature "
        "sample (one reference for every entry, chained or not), or a first-order thermal state "
        "driven by each entry's mean loss power `~ mean |dV/dt (V - mean V)|`"
    )
    physics = "self-heating (dielectric loss ~ f C V^2) changes the piezo gain"
    signature = "slowly growing gain error, worst after high f*A^2 entries, follows temperature"
    confusable = ("creep", "offset_drift")
    tell_apart = "repeat a low-frequency reference entry after the hot entries; read a thermocouple"

    def __init__(self, temperature: bool):
        self.temperature = temperature
        if temperature:
            self.params = (Param("k_per_K", "1/K", 0.0, -0.02, 0.05, 1e-3, sign=+1),)
        else:
            self.params = (
                Param("k_rel", "", 0.0, -0.5, 1.0, 0.01, sign=+1),
                Param("tau_th_s", "s", 30.0, 1.0, 5000.0, 30.0, log=True, starts=(3.0, 300.0)),
            )

    def probes(self, contexts):
        if self.temperature:
            return [{"k_per_K": k} for k in (0.001, 0.003, 0.01)]
        return [{"k_rel": 0.01, "tau_th_s": tau} for tau in (3.0, 30.0, 300.0)]

    def theta(self, ctx: Context, tau_s: float | None = None) -> NDArray:
        if self.temperature:
            T = ctx.temperature
            ref = T[0] if ctx.temperature_ref is None else ctx.temperature_ref
            return ctx.cached(("theta_T",), lambda: T - ref)
        a = float(np.exp(-1.0 / (ctx.rate_hz * tau_s)))
        power = _entry_power(ctx)
        return ctx.cached(
            ("theta_P", tau_s), lambda: first_order_filter([0.0, 1.0 - a], [1.0, -a], power)
        )

    def apply(self, x, ctx, p):
        if self.temperature:
            return x * (1.0 + p["k_per_K"] * self.theta(ctx))
        return x * (1.0 + p["k_rel"] * self.theta(ctx, p["tau_th_s"]))

    def describe(self, p, sd):
        if self.temperature:
            k, s = 100 * p["k_per_K"], sd.get("k_per_K")
            return plus_minus("k", k, None if s is None else 100 * s, "%/K")
        k, s = 100 * p["k_rel"], sd.get("k_rel")
        return (
            plus_minus(
                "gain change at the hottest entry's steady state",
                k,
                None if s is None else 100 * s,
                "%",
            )
            + f", tau_th = {fmt3(p['tau_th_s'])} s"
        )


def _entry_power(ctx: Context) -> NDArray:
    """Per-sample loss-power proxy: each entry's mean ``|dV/dt (V - mean V)|``, normalised."""
    key = ("power",)
    if key not in ctx.cache:
        p = np.zeros(ctx.n)
        for sl in ctx.entries.values():
            v = ctx.v[sl]
            if v.size > 2:
                p[sl] = np.mean(np.abs(np.diff(v) * (v[1:] - v.mean()))) * ctx.rate_hz
        m = float(p.max())
        ctx.cache[key] = p / m if m > 0 else p
    return ctx.cache[key]
