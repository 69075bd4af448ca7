"""Optional physical effects of the virtual bench, switched on by name in the rig file.

These make data with an effect the fitted model lacks, so each has a physical form and physical
default sizes (spec ``residuals.md``, "Signatures of the usual suspects"). They act where the
physics acts:

========================  ============================================  ==========================
name                      form                                          acts on
========================  ============================================  ==========================
``self_heating``          loss power ``P = (pi/2) tan_d |i (v - v_lp)|``  strain gain
                          (equals ``pi f C tan_d Vpp^2 / 4`` for a      ``1 + k (T - T_amb)``;
                          sine), first-order thermal RC ``C_th dT/dt =  adds the AI channel
                          P - (T - T_amb)/R_th``                        ``temperature``
``amplifier_current_limit``  the amplifier's true peak/average current   amplifier output (slew
                          (weaker than the rig file claims)             ``I/C`` and fold-back)
``conditioner_lowpass``   an undeclared Butterworth low-pass in the      gauge signal
                          conditioner (not the configured filter)
``mains_pickup``          ``a sin(2 pi f t + p1) + a r3 sin(3 (2 pi f    DAQ gauge input (V)
                          t) + p3)`` on the gauge cable, not locked to
                          the drive
``offset_drift``          ``rate t + random walk`` (ue at the bridge)    gauge signal
``log_creep``             ``c`` per decade of time after each change:    strain
                          ``S + (c/m) sum_i LP_tau_i[S]``, ``tau_i``
                          log-spaced, ``m`` per decade (a bank of
                          first-order modes whose summed step response
                          is ``c log10(t/t0) + const`` on
                          ``t0 << t << t_max``)
``field_saturation``      ``u = V_s tanh(v / V_s)``: the actuator's      the drive the truth
                          gain falls at high field, odd about 0 V;      sees (before it)
                          secant gain ``u/v`` at 150 V 5.0 % below the
                          small-signal one, local slope ``sech^2``
                          14.4 % below, with the default V_s 375.5 V
``viscoelastic_mode``     a standard-linear-solid (Zener) retardation   the drive the truth
                          of the drive: ``u = (1 - sum c_k) v + sum     sees (after
                          c_k x_k``, ``tau_k dx_k/dt = v - x_k``; step  ``field_saturation``)
                          response ``1 - sum c_k exp(-t/tau_k)``;
                          default one mode, c 6 %, tau 0.3 s (a second
                          mode optional)
``cubic_term``            ``S + c3 (v / V_ref)^3``, c3 > 0 by default   strain (after the
                          (gain rising with field, a hardening no       truth, before
                          library effect has): 20 ue at V_ref 100 V     ``log_creep``)
========================  ============================================  ==========================

The structural effects (``amplifier_output_rc``, ``depoling``, ``viscous_slip``,
``stack_resonance``, ``gauge_warmup``) are in :mod:`labrig.drivers.sim.structural`, with their
table.

The actuator effects differ in form from the fitted library's on purpose (the model's effects
live in ``labrig/model/effects/``): saturation is a tanh of the drive, not a polynomial softening
of the strain; the viscoelastic mode retards the drive before the hysteresis and the model's
relaxors, not the strain after them; the cubic term has no library counterpart. The strain
terms use the voltage held over the previous sample interval, as the truth does (the strain
sampled at ``n`` has seen ``v[0..n-1]``).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from labrig.drivers.sim.structural import (
    STRUCTURAL_BENCH_EFFECTS,
    AmplifierOutputRC,
    Depoling,
    GaugeWarmup,
    StackResonance,
    ViscousSlip,
)
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator


class _Effect(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class SelfHeating(_Effect):
    """Dielectric loss heats the stack; the piezo coefficient rises with temperature."""

    name: Literal["self_heating"]
    tan_delta: float = Field(0.05, ge=0, le=0.5, description="large-signal loss factor")
    thermal_resistance_K_per_W: float = Field(100.0, gt=0, description="stack to ambient")
    heat_capacity_J_per_K: float = Field(5.0, gt=0, description="stack heat capacity")
    ambient_degC: float = Field(23.0, description="ambient (and initial) temperature")
    strain_coeff_per_K: float = Field(0.002, description="relative strain change per kelvin")
    sensor_noise_degC: float = Field(0.05, ge=0, description="temperature channel noise (rms)")


class AmplifierCurrentLimit(_Effect):
    """The amplifier can deliver less current than the rig file (and preflight) assume."""

    name: Literal["amplifier_current_limit"]
    i_peak_A: float = Field(0.06, gt=0, description="true peak output current")
    i_avg_A: float = Field(0.04, gt=0, description="true average output current")


class ConditionerLowpass(_Effect):
    """An undeclared low-pass in the gauge chain (not visible in the conditioner's settings)."""

    name: Literal["conditioner_lowpass"]
    cutoff_hz: float = Field(150.0, gt=0, description="-3 dB frequency")
    order: int = Field(2, ge=1, le=4, description="Butterworth order")


class MainsPickup(_Effect):
    """Mains hum picked up by the gauge cable, added at the DAQ input."""

    name: Literal["mains_pickup"]
    amplitude_mV: float = Field(2.0, ge=0, description="fundamental amplitude at the DAQ input")
    frequency_hz: float = Field(50.0, gt=0, description="mains frequency")
    third_harmonic_ratio: float = Field(0.3, ge=0, description="3rd harmonic / fundamental")


class OffsetDrift(_Effect):
    """Slow drift of the bridge/conditioner offset (ue-equivalent at the bridge)."""

    name: Literal["offset_drift"]
    rate_ue_per_s: float = Field(0.05, description="linear drift rate")
    random_walk_ue_per_sqrt_s: float = Field(0.1, ge=0, description="random-walk intensity")


class LogCreep(_Effect):
    """Logarithmic creep of the strain: ``per_decade`` relative increase per decade of time."""

    name: Literal["log_creep"]
    per_decade: float = Field(0.015, ge=0, le=0.2, description="relative creep per decade")
    t0_s: float = Field(0.01, gt=0, description="shortest creep time constant")
    t_max_s: float = Field(1e4, gt=0, description="longest creep time constant")
    modes_per_decade: int = Field(2, ge=1, le=8)


#: the default ``field_saturation`` V_s (V): ``V_s tanh(150 / V_s) / 150 = 0.950``
DEFAULT_SATURATION_V = 375.5


class FieldSaturation(_Effect):
    """Field saturation of the actuator's gain: the truth is driven by ``V_s tanh(v / V_s)``.

    Odd about 0 V: the strain per volt falls towards both ends of a bipolar stroke; on a
    unipolar or biased drive the strain curves down towards the end of the stroke farthest from
    0 V. The secant gain at ``v`` is ``tanh(x)/x``, the local one ``sech^2(x)``, ``x = v / V_s``.
    """

    name: Literal["field_saturation"]
    saturation_V: float = Field(
        DEFAULT_SATURATION_V, gt=0, description="V_s (the default: 5 % less strain at 150 V)"
    )


class ViscoelasticMode(_Effect):
    """Slow linear viscoelastic retardation of the drive (a standard linear solid per mode).

    ``u = (1 - c1 - c2) v + c1 x1 + c2 x2``, ``tau_k dx_k/dt = v - x_k``: a step of ``v`` gives
    ``u(t) = v (1 - c1 exp(-t/tau1) - c2 exp(-t/tau2))``. The second mode is off by default.
    """

    name: Literal["viscoelastic_mode"]
    fraction: float = Field(0.06, ge=0, lt=1, description="c1: share of the gain that lags")
    tau_s: float = Field(0.3, gt=0, description="tau1: its retardation time (s)")
    second_fraction: float = Field(0.0, ge=0, lt=1, description="c2 (0: one mode)")
    second_tau_s: float = Field(1.0, gt=0, description="tau2 (s)")

    @model_validator(mode="after")
    def _total_below_one(self) -> ViscoelasticMode:
        if self.fraction + self.second_fraction >= 1:
            raise ValueError("fraction + second_fraction must be below 1")
        return self

    def modes(self) -> list[tuple[float, float]]:
        """``(fraction, tau_s)`` of each mode that is on."""
        pairs = [(self.fraction, self.tau_s), (self.second_fraction, self.second_tau_s)]
        return [(c, tau) for c, tau in pairs if c > 0]


class CubicTerm(_Effect):
    """A strain term cubic in the voltage, ``c3 (v / V_ref)^3``: with ``c3 > 0`` (the default)
    the gain rises with field (a hardening no effect of the fitted library describes)."""

    name: Literal["cubic_term"]
    c3_ue: float = Field(20.0, description="strain added at v = V_ref (ue)")
    v_ref_V: float = Field(100.0, gt=0, description="V_ref (V)")


Effect = Annotated[
    SelfHeating
    | AmplifierCurrentLimit
    | ConditionerLowpass
    | MainsPickup
    | OffsetDrift
    | LogCreep
    | FieldSaturation
    | ViscoelasticMode
    | CubicTerm
    | AmplifierOutputRC
    | Depoling
    | ViscousSlip
    | StackResonance
    | GaugeWarmup,
    Field(discriminator="name"),
]

EFFECT_NAMES = (
    "self_heating",
    "amplifier_current_limit",
    "conditioner_lowpass",
    "mains_pickup",
    "offset_drift",
    "log_creep",
    "field_saturation",
    "viscoelastic_mode",
    "cubic_term",
    *STRUCTURAL_BENCH_EFFECTS,
)


# -- runtime processors (stateful, block by block) ------------------------------------------


class ButterLowpass:
    """Continuous Butterworth low-pass sampled with the first-order hold (any cutoff, even above
    Nyquist), run with ``lfilter`` state. ``cutoff_hz <= 0`` means off (identity)."""

    def __init__(self, cutoff_hz: float, order: int, rate_hz: float):
        self.cutoff_hz, self.order = float(cutoff_hz), int(order)
        self.on = self.cutoff_hz > 0
        if self.on:  # scipy.signal only when on: a second of import CPU
            from scipy import signal

            b, a = signal.butter(self.order, 2 * math.pi * self.cutoff_hz, analog=True)
            bd, ad, _ = signal.cont2discrete((b, a), 1.0 / rate_hz, method="foh")
            self.b = np.atleast_1d(np.squeeze(bd)) / ad[0]
            self.a = np.asarray(ad, dtype=float) / ad[0]
            self.zi: NDArray | None = None

    def process(self, x: NDArray) -> NDArray:
        if not self.on or x.size == 0:
            return x
        from scipy import signal

        if self.zi is None:  # start in steady state with the first value
            self.zi = signal.lfilter_zi(self.b, self.a) * x[0]
        y, self.zi = signal.lfilter(self.b, self.a, x, zi=self.zi)
        return y


class Thermal:
    """Stack temperature from the loss power (see the module table)."""

    def __init__(self, cfg: SelfHeating, rate_hz: float):
        self.cfg = cfg
        self.T = cfg.ambient_degC
        self.set_rate(rate_hz)
        self.v_lp = 0.0

    def set_rate(self, rate_hz: float) -> None:
        self.dt = 1.0 / rate_hz
        tau = self.cfg.thermal_resistance_K_per_W * self.cfg.heat_capacity_J_per_K
        self.a_th = math.exp(-self.dt / tau)
        self.a_lp = math.exp(-self.dt / 0.5)  # reference level of v: 0.5 s low-pass

    def process(self, v: NDArray, i: NDArray) -> NDArray:
        """Temperature (degC) at each sample, for output voltage ``v`` and current ``i``."""
        from scipy import signal

        c = self.cfg
        v_lp, _zf = signal.lfilter([1 - self.a_lp], [1, -self.a_lp], v, zi=[self.a_lp * self.v_lp])
        self.v_lp = float(v_lp[-1])
        p = 0.5 * math.pi * c.tan_delta * np.abs(i * (v - v_lp))
        # exact for p held over each sample: dT' = a dT + (1 - a) R p
        drive = (1 - self.a_th) * c.thermal_resistance_K_per_W * p
        dT, _ = signal.lfilter(
            [1.0], [1, -self.a_th], drive, zi=[self.a_th * (self.T - c.ambient_degC)]
        )
        T = c.ambient_degC + dT
        self.T = float(T[-1])
        return T

    def gain(self, T: NDArray) -> NDArray:
        return 1.0 + self.cfg.strain_coeff_per_K * (T - self.cfg.ambient_degC)


class Creep:
    """Log creep as a bank of first-order modes on the strain (see the module table)."""

    def __init__(self, cfg: LogCreep, rate_hz: float):
        self.cfg = cfg
        decades = math.log10(cfg.t_max_s / cfg.t0_s)
        k = math.ceil(decades * cfg.modes_per_decade) + 1
        self.tau = cfg.t0_s * 10.0 ** (np.arange(k) / cfg.modes_per_decade)
        self.weight = cfg.per_decade / cfg.modes_per_decade
        self.x = np.zeros(k)
        self.set_rate(rate_hz)

    def set_rate(self, rate_hz: float) -> None:
        self.a = np.exp(-1.0 / (rate_hz * self.tau))

    def process(self, s: NDArray) -> NDArray:
        from scipy import signal

        if s.size == 0:
            return s
        total = np.zeros_like(s)
        for j, a in enumerate(self.a):
            # x' = (S - x)/tau with S held over each sample interval: x[n] = a x[n-1] + (1-a) S[n-1]
            y, zf = signal.lfilter([0.0, 1 - a], [1, -a], s, zi=self.x[j : j + 1])
            total += y
            self.x[j] = zf[0]
        return s + self.weight * total


class Drift:
    """Offset drift in ue at the bridge: linear rate plus a random walk."""

    def __init__(self, cfg: OffsetDrift, rng: np.random.Generator):
        self.cfg, self.rng = cfg, rng
        self.walk = 0.0

    def process(self, t: NDArray, dt: float) -> NDArray:
        c = self.cfg
        steps = self.rng.standard_normal(t.size) * c.random_walk_ue_per_sqrt_s * math.sqrt(dt)
        walk = self.walk + np.cumsum(steps)
        if t.size:
            self.walk = float(walk[-1])
        return c.rate_ue_per_s * t + walk


class Mains:
    """Mains pickup in volts at the DAQ input."""

    def __init__(self, cfg: MainsPickup, rng: np.random.Generator):
        self.cfg = cfg
        self.p1, self.p3 = rng.uniform(0, 2 * math.pi, 2)

    def process(self, t: NDArray) -> NDArray:
        c = self.cfg
        w = 2 * math.pi * c.frequency_hz * t
        a = c.amplitude_mV * 1e-3
        return a * np.sin(w + self.p1) + a * c.third_harmonic_ratio * np.sin(3 * w + self.p3)


def saturated_drive(v: NDArray, cfg: FieldSaturation) -> NDArray:
    """``V_s tanh(v / V_s)`` (V): the drive of a field-saturated actuator."""
    return cfg.saturation_V * np.tanh(v / cfg.saturation_V)


def cubic_strain(v_held: NDArray, cfg: CubicTerm) -> NDArray:
    """``c3 (v / V_ref)^3`` (ue) for the voltage ``v_held`` on the actuator at each sample."""
    return cfg.c3_ue * (v_held / cfg.v_ref_V) ** 3


class Retardation:
    """The ``viscoelastic_mode`` effect on a drive held over each sample interval.

    Each mode's state ``x`` follows ``tau dx/dt = v - x`` exactly for ``v`` held:
    ``x[n+1] = a x[n] + (1 - a) v[n]``, ``a = exp(-dt/tau)``; the drive played over interval
    ``n`` is the interval's mean, ``v - c (v - x[n]) g`` with ``g = (tau/dt)(1 - a)``.
    Starts at rest (every ``x`` at 0 V).
    """

    def __init__(self, cfg: ViscoelasticMode, rate_hz: float):
        dt = 1.0 / rate_hz
        modes = cfg.modes()
        self.c = np.array([c for c, _ in modes])
        tau = np.array([t for _, t in modes])
        self.a = np.exp(-dt / tau)
        self.g = tau / dt * -np.expm1(-dt / tau)
        self.x = np.zeros(len(modes))

    def process(self, v: NDArray) -> NDArray:
        from scipy import signal

        if v.size == 0:
            return v
        u = np.array(v, dtype=float)
        for j, (c, a, g) in enumerate(zip(self.c, self.a, self.g, strict=True)):
            x, zf = signal.lfilter([0.0, 1 - a], [1, -a], v, zi=self.x[j : j + 1])
            self.x[j] = zf[0]
            u -= c * g * (v - x)
        return u
