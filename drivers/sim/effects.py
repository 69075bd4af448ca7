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
========================  ============================================  ==========================
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy import signal


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


Effect = Annotated[
    SelfHeating | AmplifierCurrentLimit | ConditionerLowpass | MainsPickup | OffsetDrift | LogCreep,
    Field(discriminator="name"),
]

EFFECT_NAMES = (
    "self_heating",
    "amplifier_current_limit",
    "conditioner_lowpass",
    "mains_pickup",
    "offset_drift",
    "log_creep",
)


# -- runtime processors (stateful, block by block) ------------------------------------------


class ButterLowpass:
    """Continuous Butterworth low-pass sampled with the first-order hold (any cutoff, even above
    Nyquist), run with ``lfilter`` state. ``cutoff_hz <= 0`` means off (identity)."""

    def __init__(self, cutoff_hz: float, order: int, rate_hz: float):
        self.cutoff_hz, self.order = float(cutoff_hz), int(order)
        self.on = self.cutoff_hz > 0
        if self.on:
            b, a = signal.butter(self.order, 2 * math.pi * self.cutoff_hz, analog=True)
            bd, ad, _ = signal.cont2discrete((b, a), 1.0 / rate_hz, method="foh")
            self.b = np.atleast_1d(np.squeeze(bd)) / ad[0]
            self.a = np.asarray(ad, dtype=float) / ad[0]
            self.zi: NDArray | None = None

    def process(self, x: NDArray) -> NDArray:
        if not self.on or x.size == 0:
            return x
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
