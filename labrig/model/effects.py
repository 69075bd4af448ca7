"""The effect library: physical extensions of the dynamic model for ``labrig diagnose``.

Pure numerics (no I/O). Each effect is a small, physical extension of
``V -> G_t G_d -> quasi-static operator -> S`` with few parameters; it acts in one of three
places:

- ``"voltage"``: on the driving voltage before the model (amplifier and actuator input effects:
  ``amplifier_current_limit``, ``quadratic_term``);
- ``"output"``: on the modelled strain of a whole simulated sequence (operator gain and creep:
  ``thermal_drift``, ``creep``; the measuring chain: ``sensor_lowpass``, ``time_delay``); every
  output effect is *linear* in the strain it receives;
- ``"operator"``: an additive strain term computed from the operator's input ``V*`` (hysteresis
  the seed's operator cannot hold: ``remanence``); fitted like the output effects, and the
  compensation controller inverts it with the operator;
- ``"nuisance"``: additive per-entry terms that are linear in per-entry nuisance parameters
  (``mains_pickup``, ``offset_drift``). These are not fitted as global parameters: they are
  eliminated per entry by least squares (variable projection), and on a held-out entry they are
  fitted on its first half and scored on its second half.

Every effect has a *null value* of its parameters where it equals the base model (the
``null`` of each :class:`Param`), physical bounds, an expected sign (``sign``: +1 when only
values above the null are physical, 0 when either sign is), the residual signature that points
at it, the effects it is confusable with and the experiment that tells them apart (used in the
diagnosis report).

An effect sees the simulated sequence through a :class:`Context`: the sampling rate, the time,
the driving voltage, the entries' sample ranges and, when the run recorded them, the amplifier's
measured output voltage and a temperature channel (over the whole sequence; rests between
entries filled in by :class:`Context`'s builder).

Forms deliberately differ from the simulated bench's (``drivers/sim/effects.py``) where the
physics allows: a fitted first-order low-pass here against the bench's Butterworth, a pure slew
limit against the bench's peak/average fold-back, an exact logarithmic kernel with a fixed
``t0 = 0.05 s`` against the bench's mode bank from 0.01 s, a heating state driven by each entry's
mean loss power against the bench's instantaneous power.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from labrig.model.bouc_wen import bouc_wen_exact

__all__ = [
    "CREEP_EFFECTS",
    "EFFECT_NAMES",
    "STRUCTURAL_EFFECT_NAMES",
    "AmplifierCurrentLimit",
    "Context",
    "Creep",
    "Effect",
    "MainsPickup",
    "OffsetDrift",
    "Param",
    "QuadraticTerm",
    "Remanence",
    "SensorLowpass",
    "ThermalDrift",
    "TimeDelay",
    "ViscoelasticCreep",
    "kelvin_voigt_filter",
    "library",
]


@dataclass(frozen=True)
class Param:
    """One physical parameter of an effect (native units in ``unit``)."""

    name: str
    unit: str
    null: float  # the value where the effect vanishes
    lo: float
    hi: float
    init: float  # a start for the fit (near the null, on the physical side)
    sign: int = 0  # +1: only values above ``null`` are physical; 0: either sign
    log: bool = False  # fit in log coordinates (then ``null`` is never reached)
    expect: int = 0  # +1: values below ``null`` are possible but suspicious (reported)
    check_bounds: bool = True  # a fit ending on a bound makes the effect unphysical
    starts: tuple[float, ...] = ()  # further starts of a refit (other orders of magnitude)


@dataclass
class Context:
    """What an effect sees of one simulated sequence (a record or a chained run).

    ``entries`` maps each entry name to its ``slice`` in the sequence; samples outside every
    entry are rests at 0 V. ``amplifier_voltage`` and ``temperature`` span the whole sequence
    (``None`` when the run did not record them).
    """

    rate_hz: float
    v: NDArray[np.float64]
    entries: dict[str, slice]
    amplifier_voltage: NDArray[np.float64] | None = None
    temperature: NDArray[np.float64] | None = None
    cache: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        return int(self.v.size)

    @property
    def t(self) -> NDArray[np.float64]:
        return np.arange(self.n) / self.rate_hz

    def cached(self, key: tuple, make: Callable[[], Any]) -> Any:
        """``make()`` computed once per ``key``; keys that carry a fitted parameter come and go
        during a fit, so the cache is emptied when it holds more than 64 of them."""
        if key not in self.cache:
            if len(self.cache) > 64:
                self.cache.clear()
            self.cache[key] = make()
        return self.cache[key]


class Effect:
    """Base class; see the module docstring. Subclasses set the class attributes and implement
    :meth:`apply` (voltage/output effects) or :meth:`columns` (nuisance effects)."""

    name: str = ""
    where: str = ""  # "voltage" | "operator" | "output" | "nuisance"
    physics: str = ""
    signature: str = ""
    confusable: tuple[str, ...] = ()
    tell_apart: str = ""
    params: tuple[Param, ...] = ()

    def apply(self, x: NDArray, ctx: Context, p: Mapping[str, float]) -> NDArray:
        """The voltage (``where == "voltage"``) or the strain (``"output"``) with the effect;
        for ``"operator"``, the strain term (ue) it adds, ``x`` being the operator's input."""
        raise NotImplementedError

    def columns(self, t: NDArray, rate_hz: float) -> NDArray:
        """Nuisance regressors of one entry (``len(t) x k``), ``t`` the entry's time (s)."""
        raise NotImplementedError

    @property
    def null(self) -> dict[str, float]:
        return {q.name: q.null for q in self.params}

    @property
    def init(self) -> dict[str, float]:
        return {q.name: q.init for q in self.params}

    def refit_starts(self, start: Mapping[str, float]) -> list[dict[str, float]]:
        """Starts of a refit: ``start``, then ``start`` with one parameter moved to each of its
        :attr:`Param.starts` (orders of magnitude where a local optimum may hide)."""
        out = [dict(start)]
        for q in self.params:
            for v in q.starts:
                alt = {**start, q.name: min(max(v, q.lo), q.hi)}
                if alt not in out:
                    out.append(alt)
        return out

    def probes(self, contexts: list[Context]) -> list[dict[str, float]]:
        """Parameter values where the effect's direction is probed for ranking (the score
        test): by default its start, close to the null on the physical side."""
        return [self.init] if self.params else [{}]

    def caveats(self, p: Mapping[str, float], span_s: float) -> list[str]:
        """What makes fitted parameters ``p`` doubtful on data ``span_s`` long (the longest
        simulated sequence, s) although they passed: plain sentences; none by default."""
        return []

    def physical(self, p: Mapping[str, float]) -> dict[str, float]:
        """Reported parameters (derived units, e.g. a cutoff in Hz instead of a time constant)."""
        return {k: float(v) for k, v in p.items()}

    def describe(self, p: Mapping[str, float], sd: Mapping[str, float | None]) -> str:
        """``"fc = 118 +- 4 Hz"``-style text of the fitted parameters."""
        parts = []
        for q in self.params:
            v, s = p[q.name], sd.get(q.name)
            parts.append(_pm(q.name, v, s, q.unit))
        return ", ".join(parts)


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def _pm(name: str, v: float, s: float | None, unit: str) -> str:
    u = f" {unit}" if unit else ""
    if s is None or not np.isfinite(s):
        return f"{name} = {_fmt(v)}{u}"
    return f"{name} = {_fmt(v)} +- {_fmt(s)}{u}"


# -- operator / gain ---------------------------------------------------------------------------


class ThermalDrift(Effect):
    """Self-heating changes the piezo gain: ``S -> S (1 + k theta)``.

    Physics: dielectric loss ``P ~ pi f C tan(delta) Vpp^2 / 4`` heats the stack (tens of kelvin
    at 40 Hz, full amplitude); the piezo coefficient rises with temperature (about 0.1-0.5 %/K).
    Acts on the operator's output (a slowly varying gain).

    - With a temperature channel: ``theta = T - T(0)`` (K), one parameter ``k_per_K``.
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
            return ctx.cached(("theta_T",), lambda: T - T[0])
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
            return _pm("k", k, None if s is None else 100 * s, "%/K")
        k, s = 100 * p["k_rel"], sd.get("k_rel")
        return (
            _pm(
                "gain change at the hottest entry's steady state",
                k,
                None if s is None else 100 * s,
                "%",
            )
            + f", tau_th = {_fmt(p['tau_th_s'])} s"
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

    def apply(self, x, ctx, p):
        c = p["c_per_decade"]
        if c == 0.0:
            return x
        ds = np.diff(x, prepend=0.0)
        return x + c * signal.fftconvolve(ds, self.kernel(ctx, p["t0_s"]))[: x.size]

    def describe(self, p, sd):
        s, s0 = sd.get("c_per_decade"), sd.get("t0_s")
        return (
            _pm("c", 100 * p["c_per_decade"], None if s is None else 100 * s, "% per decade")
            + ", "
            + _pm("t0", 1e3 * p["t0_s"], None if s0 is None else 1e3 * s0, "ms")
        )


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
        return _pm("c", 100 * p["c"], None if sd.get("c") is None else 100 * sd["c"], "%") + (
            _pm(", tau", p["tau_s"], sd.get("tau_s"), "s")
        )


class Remanence(Effect):
    """Remanent strain: a Bouc-Wen element beside the seed's operator,
    ``S = H[V*] - h[V*]`` with ``dh = A dV* - beta |dV*| h - gamma dV* |h|`` (``n = 1``,
    :mod:`labrig.model.bouc_wen`; ``gamma = gamma_ratio * beta``, ``|gamma_ratio| <= 1`` keeps it
    bounded).

    Physics: part of the ceramic's domain switching is not undone when the voltage returns, so a
    loop need not close where it started; the strain left at 0 V after an excursion depends on
    the last swings and stays (it does not relax). The seed's operator closes every loop at its
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


# -- driving voltage ---------------------------------------------------------------------------


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
        return _pm("slew limit", rate, srate, "V/ms")


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
    confusable = ("hysteresis shape",)
    tell_apart = "a branch test: first-order reversal curves at several amplitudes"
    params = (Param("c2", "", 0.0, -0.5, 0.5, 0.01, expect=+1),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def apply(self, x, ctx, p):
        return x + p["c2"] * x * x / self.v_ref

    def describe(self, p, sd):
        s = sd.get("c2")
        label = f"c2 (relative at {self.v_ref:.3g} V)"
        return _pm(label, 100 * p["c2"], None if s is None else 100 * s, "%")


# -- measuring chain -------------------------------------------------------------------------


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
        return _pm("fc", fc, None if s is None else fc * s / tau, "Hz") + _pm(
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
        return _pm("delay", 1e3 * p["delay_s"], None if s is None else 1e3 * s, "ms")


# -- nuisance ----------------------------------------------------------------------------------


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


#: the library's names (the order is the order of the report)
EFFECT_NAMES: tuple[str, ...] = (
    "thermal_drift",
    "amplifier_current_limit",
    "sensor_lowpass",
    "mains_pickup",
    "offset_drift",
    "creep",
    "time_delay",
    "quadratic_term",
)

#: in the library but not default ``diagnose`` candidates: structural effects of the actuator
#: (path-dependent; ``labrig diagnose --also NAME`` or ``labrig fit --effect NAME``). On the
#: hybrid bench with the seed's campaign they are what the model lacks (docs/diagnose.md).
STRUCTURAL_EFFECT_NAMES: tuple[str, ...] = ("remanence", "viscoelastic_creep")
#: the effects that make the strain creep on after a step (part of the model's creep figure)
CREEP_EFFECTS: tuple[str, ...] = ("creep", "viscoelastic_creep")


def library(
    temperature: bool = False,
    amplifier_voltage: bool = False,
    mains_hz: float = 50.0,
    v_ref: float = 100.0,
) -> dict[str, Effect]:
    """The effects, configured for what a run recorded (temperature channel, amplifier monitor),
    its mains frequency and its full-scale voltage."""
    effects: list[Effect] = [
        ThermalDrift(temperature),
        AmplifierCurrentLimit(amplifier_voltage),
        SensorLowpass(),
        MainsPickup(mains_hz),
        OffsetDrift(),
        Creep(),
        ViscoelasticCreep(),
        Remanence(),
        TimeDelay(),
        QuadraticTerm(v_ref),
    ]
    return {e.name: e for e in effects}
