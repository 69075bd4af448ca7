"""Effects of the actuator itself: heating, creep, a slow viscoelastic mode, remanence,
electrostriction. Forms differ from the simulated bench's (``drivers/sim/effects.py``) where the
physics allows (module docstring of :mod:`labrig.model.effects`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sp_fft
from scipy import signal

from labrig.model.bouc_wen import bouc_wen_exact
from labrig.model.effects.base import Context, Effect, Param, fmt3, plus_minus

__all__ = [
    "Creep",
    "FieldSaturation",
    "QuadraticTerm",
    "Remanence",
    "ThermalDrift",
    "ViscoelasticCreep",
    "kelvin_voigt_filter",
]


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
        return ctx.cached(
            ("theta_P", tau_s), lambda: signal.lfilter([0.0, 1.0 - a], [1.0, -a], _entry_power(ctx))
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


class Creep(Effect):
    """Logarithmic creep under sustained voltage: ``S -> S + c (k * dS)``, ``k(t) = log10(1 +
    t / t0)``, ``c`` and ``t0`` fitted.

    Physics: slow domain-wall motion keeps the strain rising by a fraction ``c`` (1-2 %) per
    decade of time after every change, from about ``t0`` on. Acts on the output of the operator
    (each strain change creeps on). Signature: slow trend after level changes that scales with
    the amplitude, strain shift after the drive stops; with ``t0`` of milliseconds, also a gain
    and phase that fall slowly with frequency across the sweep. Null: ``c = 0``. Confusable with
    offset drift, thermal drift and the model's own slow relaxor ``G_t``, which follows most of a
    logarithmic creep by itself: what remains is 0.05-0.08 % of the span for 2-4 %/decade
    (docs/diagnose.md), so the effect is found only on a gauge quiet enough to show it.

    ``t0`` is fitted (0.1 ms to 10 s, log scale) because the part of a creep that starts within
    the sweep's periods is what ``G_t`` cannot take. Measured on a noise-free campaign with
    4 %/decade of creep (the bench's mode bank): base alone 0.083 % in-sample NRMSE; with this
    effect and ``t0`` fixed at 0.05 s, 0.079 %; with ``t0`` fitted, 0.016 % (c 3.9 %/decade,
    ``t0`` 1.7 ms, the base back at its creep-free values), the same campaign without creep
    0.014 %.
    """

    name = "creep"
    where = "output"
    physics = "logarithmic creep (domain-wall motion) under sustained voltage"
    signature = "slow trend after level changes, scaling with the amplitude"
    confusable = ("offset_drift", "thermal_drift")
    tell_apart = (
        "a step-and-hold entry at 50 and 100 V (creep scales with the step, drift does not)"
    )
    params = (
        Param("c_per_decade", "", 0.0, -0.05, 0.2, 0.005, sign=+1),
        Param("t0_s", "s", 0.05, 1e-4, 10.0, 0.05, log=True, starts=(0.001, 0.01, 0.1, 1.0)),
    )

    def probes(self, contexts):
        return [{"c_per_decade": 0.005, "t0_s": t0} for t0 in (0.002, 0.05, 1.0)]

    def caveats(self, p, span_s):
        """A log creep seen over less than two decades of time (``t0`` above 1 % of the data's
        span) is not told from one slow mode, and its rate per decade is an extrapolation."""
        t0 = p["t0_s"]
        if p["c_per_decade"] <= 0 or 100.0 * t0 <= span_s:
            return []
        decades = np.log10(span_s / t0)
        seen = f"{decades:.1f} decades" if decades >= 0.1 else "less than a decade"
        return [
            f"creep is seen over {seen} of time only (t0 = {1e3 * t0:.3g} ms, {span_s:.3g} s "
            "simulated at a stretch): one slow mode (viscoelastic_creep) may do as well, and the "
            "rate per decade is an extrapolation"
        ]

    def kernel(self, ctx: Context, t0_s: float) -> NDArray:
        """``log10(1 + t / t0)`` on the context's time base (cached per ``t0``)."""
        return ctx.cached(("creep_kernel", t0_s), lambda: np.log10(1.0 + ctx.t / t0_s))

    def _spectra(self, ctx: Context, t0_s: float) -> tuple[int, NDArray, NDArray]:
        """The FFT length and the spectra of the kernel and of its derivative with respect to
        ``t0`` (``-t / (t0 (t0 + t) ln 10)``), cached per ``t0``: every convolution of a fit's
        evaluation (the strain, each Jacobian column) reuses them."""

        def make() -> tuple[int, NDArray, NDArray]:
            nf = sp_fft.next_fast_len(2 * ctx.n - 1, real=True)
            t = ctx.t
            dk = -t / (t0_s * (t0_s + t) * np.log(10.0))
            return nf, sp_fft.rfft(self.kernel(ctx, t0_s), nf), sp_fft.rfft(dk, nf)

        return ctx.cached(("creep_spectra", t0_s), make)

    def _convolve(self, ds: NDArray, spectrum: NDArray, nf: int) -> NDArray:
        """``ds * kernel`` (causal, the first ``N`` samples), column-wise for a 2-D ``ds``."""
        out = sp_fft.irfft(sp_fft.rfft(ds, nf, axis=0) * _col(spectrum, ds), nf, axis=0)
        return out[: ds.shape[0]]

    def apply(self, x, ctx, p):
        c = p["c_per_decade"]
        if c == 0.0:
            return x
        nf, K, _ = self._spectra(ctx, p["t0_s"])
        return x + c * self._convolve(np.diff(x, axis=0, prepend=0.0), K, nf)

    def tangent_columns(self, x, dX, ctx, p):
        return self.apply(dX, ctx, p)

    def parameter_derivatives(self, x, ctx, p):
        nf, K, dK = self._spectra(ctx, p["t0_s"])
        ds = np.diff(x, prepend=0.0)
        both = self._convolve(np.column_stack([ds, ds]), np.column_stack([K, dK]), nf)
        return {"c_per_decade": both[:, 0], "t0_s": p["c_per_decade"] * both[:, 1]}

    def describe(self, p, sd):
        s, s0 = sd.get("c_per_decade"), sd.get("t0_s")
        return (
            plus_minus("c", 100 * p["c_per_decade"], None if s is None else 100 * s, "% per decade")
            + ", "
            + plus_minus("t0", 1e3 * p["t0_s"], None if s0 is None else 1e3 * s0, "ms")
        )


def _col(spectrum: NDArray, like: NDArray) -> NDArray:
    """``spectrum`` shaped to multiply the FFT of ``like`` (column-wise when ``like`` is 2-D and
    the spectrum one vector)."""
    return spectrum[:, None] if like.ndim == 2 and spectrum.ndim == 1 else spectrum


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
        b, a = kelvin_voigt_filter(c, p["tau_s"], ctx.rate_hz)
        return signal.lfilter(b, a, x)

    def describe(self, p, sd):
        return plus_minus(
            "c", 100 * p["c"], None if sd.get("c") is None else 100 * sd["c"], "%"
        ) + (plus_minus(", tau", p["tau_s"], sd.get("tau_s"), "s"))


class Remanence(Effect):
    """Remanent strain: a Bouc-Wen element beside the paper's operator,
    ``S = H[V*] - h[V*]`` with ``dh = A dV* - beta |dV*| h - gamma dV* |h|`` (``n = 1``,
    :mod:`labrig.model.bouc_wen`; ``gamma = gamma_ratio * beta``, ``|gamma_ratio| <= 1`` keeps it
    bounded).

    Physics: part of the ceramic's domain switching is not undone when the voltage returns, so a
    loop need not close where it started; the strain left at 0 V after an excursion depends on
    the last swings and stays (it does not relax). The paper's operator closes every loop at its
    start (``S_s + F(x) - F(x)``, with either memory rule) and cannot hold it. Acts beside the
    operator, on the relaxed voltage (an actuator effect: the compensation controller inverts
    it). Signature: a constant residual at 0 V after each excursion, its size set by the last
    swing, and minor loops whose ends drift. Null: ``A = 0``. Confusable with ``offset_drift``
    (which drifts with time, not with the excursions) and ``creep`` (which relaxes).
    """

    name = "remanence"
    where = "operator"
    physics = "remanent strain (Bouc-Wen element beside the operator: loops that do not close)"
    signature = "constant residual at 0 V after excursions, set by the last swing"
    confusable = ("offset_drift", "creep")
    tell_apart = (
        "hold 0 V after excursions of different sizes: remanence stays put and scales with the "
        "last swing; offset drift follows the clock, creep relaxes"
    )
    params = (
        Param("A_ue_per_V", "ue/V", 0.0, -2.0, 8.0, 0.5, sign=+1),
        Param(
            "beta_per_V",
            "1/V",
            0.03,
            2e-3,
            0.5,
            0.03,
            log=True,
            check_bounds=False,
            starts=(0.003, 0.3),
        ),
        Param("gamma_ratio", "", 0.3, -1.0, 1.0, 0.3, check_bounds=False),
    )

    def apply(self, x, ctx, p):
        A = p["A_ue_per_V"]
        if A == 0.0:
            return np.zeros(x.size)
        beta = p["beta_per_V"]
        h = bouc_wen_exact(np.concatenate(([0.0], x)), A, beta, p["gamma_ratio"] * beta)
        return -h[1:]


class QuadraticTerm(Effect):
    """Electrostriction: ``V -> V + c2 V^2 / V_ref`` before the dynamics (``V_ref``: the
    run's largest voltage, 100 V by default, so ``c2`` is relative at full scale).

    A quadratic (even) contribution to the strain. Signature: even harmonics, a residual versus
    ``V`` that is single-valued and the same on both branches, four times larger at 100 V than
    at 50 V. Null: ``c2 = 0``. Confusable with an asymmetric hysteresis (branch test).
    """

    name = "quadratic_term"
    where = "voltage"
    physics = "electrostrictive (quadratic) strain"
    signature = "even harmonics, single-valued residual versus V, x4 from 50 to 100 V"
    confusable = ("field_saturation",)
    tell_apart = (
        "drive bipolar and unipolar: an even (quadratic) term changes sign with the voltage's "
        "shape, field saturation (odd) does not; a branch test separates an asymmetric "
        "hysteresis"
    )
    params = (Param("c2", "", 0.0, -0.5, 0.5, 0.01, expect=+1),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def apply(self, x, ctx, p):
        return x + p["c2"] * x * x / self.v_ref

    def describe(self, p, sd):
        s = sd.get("c2")
        label = f"c2 (relative at {self.v_ref:.3g} V)"
        return plus_minus(label, 100 * p["c2"], None if s is None else 100 * s, "%")


class FieldSaturation(Effect):
    """Field saturation of the actuator's gain: ``V -> V (1 - s (V / V_ref)^2)`` before the
    dynamics (``V_ref``: the run's largest ``|V|``, so ``s`` is the relative loss of gain at
    full scale; ``s < 1/3`` keeps the map monotone).

    Physics: at high field the piezo coefficient falls (the extrinsic, domain-wall part of the
    response saturates), so the strain per volt is lower near both ends of a bipolar stroke and
    near the top of a unipolar one; odd about 0 V (zero field). Acts on the driving voltage (the
    field), like ``quadratic_term``.

    Signature: a negative curvature of the residual versus ``V`` near full scale; odd (3rd)
    harmonics under a bipolar drive; on a unipolar drive it is what a ``quadratic_term`` fitted
    with a *negative* coefficient stands for. Null: ``s = 0``; only ``s > 0`` is physical (a gain
    that rises with field is another effect).
    """

    name = "field_saturation"
    where = "voltage"
    physics = "field saturation of the piezo coefficient (gain falling at high field)"
    signature = "negative curvature near full scale, odd about 0 V (3rd harmonics when bipolar)"
    confusable = ("quadratic_term",)
    tell_apart = (
        "drive bipolar and unipolar: saturation (odd about 0 V) lowers the gain at both ends of a "
        "bipolar stroke, an even (quadratic) term raises one end and lowers the other"
    )
    params = (Param("s", "", 0.0, -0.3, 0.3, 0.01, sign=+1),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def probes(self, contexts):
        return [{"s": 0.01}, {"s": 0.05}]

    def apply(self, x, ctx, p):
        u = x / self.v_ref
        return x * (1.0 - p["s"] * u * u)

    def describe(self, p, sd):
        sv = sd.get("s")
        label = f"gain loss at {self.v_ref:.3g} V"
        return plus_minus(label, 100 * p["s"], None if sv is None else 100 * sv, "%")
