"""Structural effects of the virtual bench: the truths behind the structural study.

Each is a physical mechanism switched on by name in a rig file's ``bench: effects:`` list (or a
study campaign), written in a form that differs on purpose from the fitted library's
(``labrig/model/effects/``), so a study that finds them is not circular:

==========================  ==========================================  ========================
name                        form                                        acts on
==========================  ==========================================  ========================
``amplifier_output_rc``     the amplifier's output resistance ``R``     the voltage the stack
                            charging the stack, whose capacitance       sees (first in the
                            grows with the drive: ``R C(v_s) dv_s/dt    chain)
                            = v - v_s``, ``C(v_s) = C0 (1 + rise
                            |v_s| / V_ref)``: a low-pass whose corner
                            ``1 / (2 pi R C)`` falls at large drive
``depoling``                field-dependent ``d33`` on the negative     the drive the truth
                            side: ``d33(w) / d33_0 = 1 / (1 + (w /      sees (after
                            V_c)^2)`` for ``w < 0`` (1 for ``w >= 0``); ``amplifier_output_rc``)
                            the truth is driven by ``u = int_0^v``:
                            ``u = v`` (v >= 0), ``V_c atan(v / V_c)``
``viscous_slip``            Maxwell-slip elements whose slip is         strain (added after the
                            viscous (rate-dependent hysteresis):        truth)
                            element ``i`` follows ``v`` within
                            ``+-r_i``, beyond it ``dz_i/dt = (|v -
                            z_i| - r_i) sign(v - z_i) / tau``; ``S +=
                            -g mean_i (v - z_i)``
``stack_resonance``         the stack (stiffness ``k``, internal        strain (the gauge is on
                            damping ``c``, Kelvin-Voigt) drives a mass  the mass; after creep
                            by its force on the relative motion:        and heating)
                            ``m x'' = k (x_f - x) + c (x_f' - x')``,
                            ``H = (c s + k) / (m s^2 + c s + k)``,
                            ``f_n = sqrt(k/m) / (2 pi)``
``gauge_warmup``            the gauge and conditioner warming after     strain at the bridge
                            power-on: zero ``D (1 - exp(-t/tau))`` and
                            span ``1 + s (1 - exp(-t/tau))``
==========================  ==========================================  ========================

Time ``t`` is the bench's simulated time from power-on; the processors keep their state from
block to block and start at rest (a changed sample rate rebuilds them at rest). Each runs on the
voltage held over each sample interval (the bench's zero-order hold).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = [
    "STRUCTURAL_BENCH_EFFECTS",
    "AmplifierOutputRC",
    "Depoling",
    "GaugeWarmup",
    "OutputRC",
    "Resonance",
    "StackResonance",
    "ViscousSlip",
    "ViscousSlipElements",
    "depoled_drive",
    "warmup",
]


class _Effect(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class AmplifierOutputRC(_Effect):
    """The amplifier's output resistance charging the stack (its bandwidth under load)."""

    name: Literal["amplifier_output_rc"]
    output_resistance_ohm: float = Field(40.0, gt=0, description="R (ohm)")
    capacitance_F: float | None = Field(
        None, gt=0, description="C0, the stack's small-signal capacitance (None: the bench's)"
    )
    capacitance_rise: float = Field(
        0.7, ge=0, description="C grows by this fraction of C0 at |v_s| = v_ref_V"
    )
    v_ref_V: float = Field(100.0, gt=0, description="V_ref (V)")


class Depoling(_Effect):
    """The piezo coefficient falls under negative field (towards depoling)."""

    name: Literal["depoling"]
    coercive_V: float = Field(250.0, gt=0, description="V_c: d33 is halved at v = -V_c (V)")


class ViscousSlip(_Effect):
    """Rate-dependent hysteresis: Maxwell-slip elements with viscous slip."""

    name: Literal["viscous_slip"]
    elements: int = Field(4, ge=1, le=16, description="number of elements")
    r_min_V: float = Field(2.0, ge=0, description="smallest slip threshold r_1 (V)")
    r_max_V: float = Field(20.0, ge=0, description="largest slip threshold r_n (V)")
    tau_s: float = Field(0.002, gt=0, description="slip time constant tau (s)")
    gain_ue_per_V: float = Field(1.0, description="g: strain per volt of mean lag (ue/V)")

    @model_validator(mode="after")
    def _ordered(self) -> ViscousSlip:
        if self.r_max_V < self.r_min_V:
            raise ValueError("r_max_V must not be below r_min_V")
        return self

    def thresholds_V(self) -> NDArray:
        return np.linspace(self.r_min_V, self.r_max_V, self.elements)


class StackResonance(_Effect):
    """The stack drives a mass through its own stiffness and internal (Kelvin-Voigt) damping,
    both acting on the motion of the free stroke relative to the mass; the gauge sees the
    mass's motion. The damping on the relative motion puts a zero at ``-k/c`` in the response
    (a pole pair alone would be a base-excited damper)."""

    name: Literal["stack_resonance"]
    stiffness_N_per_um: float = Field(20.0, gt=0, description="k: the stack's stiffness")
    mass_kg: float = Field(8.0, gt=0, description="m: the moving mass")
    damping_ratio: float = Field(0.05, gt=0, lt=1, description="zeta: c = 2 zeta sqrt(k m) (N s/m)")

    @property
    def resonance_hz(self) -> float:
        """``f_n = sqrt(k / m) / (2 pi)`` (Hz)."""
        return math.sqrt(self.stiffness_N_per_um * 1e6 / self.mass_kg) / (2.0 * math.pi)


class GaugeWarmup(_Effect):
    """The gauge chain warming after power-on: zero and span settle exponentially."""

    name: Literal["gauge_warmup"]
    zero_ue: float = Field(25.0, description="D: zero shift when warm (ue at the bridge)")
    span_fraction: float = Field(0.01, gt=-1, description="s: span change when warm")
    tau_s: float = Field(60.0, gt=0, description="tau: warm-up time constant (s)")


STRUCTURAL_BENCH_EFFECTS = (
    "amplifier_output_rc",
    "depoling",
    "viscous_slip",
    "stack_resonance",
    "gauge_warmup",
)


def depoled_drive(v: NDArray, cfg: Depoling) -> NDArray:
    """``u = v`` for ``v >= 0``, ``V_c atan(v / V_c)`` for ``v < 0`` (V)."""
    v = np.asarray(v, dtype=float)
    vc = cfg.coercive_V
    return np.where(v >= 0, v, vc * np.arctan(np.minimum(v, 0.0) / vc))


def warmup(t: NDArray, cfg: GaugeWarmup) -> tuple[NDArray, NDArray]:
    """``(zero ue, span factor)`` at times ``t`` (s from power-on)."""
    w = -np.expm1(-np.asarray(t, dtype=float) / cfg.tau_s)
    return cfg.zero_ue * w, 1.0 + cfg.span_fraction * w


class OutputRC:
    """``amplifier_output_rc`` on a voltage held over each sample interval.

    Over interval ``n`` the stack voltage relaxes towards ``v[n]`` with ``tau_n = R C(x_n)``
    (``C`` held at its value at the interval's start): ``x_{n+1} = v + (x_n - v) a``, ``a =
    exp(-dt / tau_n)``; what the actuator sees over the interval is its mean, ``v - (v - x_n)
    g``, ``g = (tau_n / dt)(1 - a)``. Starts at 0 V.
    """

    def __init__(self, cfg: AmplifierOutputRC, c0_F: float, rate_hz: float):
        self.r = cfg.output_resistance_ohm
        self.c0 = cfg.capacitance_F or c0_F
        self.rise, self.v_ref = cfg.capacitance_rise, cfg.v_ref_V
        self.dt = 1.0 / rate_hz
        self.x = 0.0

    def process(self, v: NDArray) -> NDArray:
        out = np.empty(v.size)
        x, dt, r, c0, k = self.x, self.dt, self.r, self.c0, self.rise / self.v_ref
        for n, vn in enumerate(np.asarray(v, dtype=float).tolist()):
            tau = r * c0 * (1.0 + k * abs(x))
            a = math.exp(-dt / tau)
            g = tau / dt * (1.0 - a)
            out[n] = vn - (vn - x) * g
            x = vn + (x - vn) * a
        self.x = x
        return out


class ViscousSlipElements:
    """``viscous_slip``: the elements' states ``z_i`` (V), exact for ``v`` held over each
    interval: beyond the threshold the excess ``|v - z| - r`` decays as ``exp(-dt / tau)``.

    :meth:`process` returns the strain term at each sample ``n``: ``-g mean_i (v[n-1] -
    z_i[n])`` (the element states after the interval before the sample, as the truth's strain at
    ``n`` has seen ``v[0..n-1]``). Starts at rest (every ``z`` at 0 V).
    """

    def __init__(self, cfg: ViscousSlip, rate_hz: float):
        self.r = cfg.thresholds_V().tolist()
        self.a = math.exp(-1.0 / (rate_hz * cfg.tau_s))
        self.g = cfg.gain_ue_per_V
        self.z = [0.0] * len(self.r)
        self.v_last = 0.0

    def process(self, v: NDArray) -> NDArray:
        out = np.empty(v.size)
        z, r, a, m = self.z, self.r, self.a, len(self.r)
        v_prev = self.v_last
        for n, vn in enumerate(np.asarray(v, dtype=float).tolist()):
            out[n] = -self.g * sum(v_prev - zi for zi in z) / m
            for i in range(m):
                e = vn - z[i]
                if e > r[i]:
                    z[i] = vn - (r[i] + (e - r[i]) * a)
                elif e < -r[i]:
                    z[i] = vn + (r[i] + (-e - r[i]) * a)
            v_prev = vn
        self.v_last = v_prev
        return out


class Resonance:
    """``stack_resonance``: ``x'' + 2 zeta w (x' - x_f') + w^2 (x - x_f) = 0`` (strain units;
    ``c / m = 2 zeta w``, ``k / m = w^2``), the free strain ``x_f`` taken as piecewise linear
    between samples (first-order hold), run with ``lfilter`` state; starts at rest."""

    def __init__(self, cfg: StackResonance, rate_hz: float):
        from scipy import signal

        w = 2.0 * math.pi * cfg.resonance_hz
        two_zw = 2.0 * cfg.damping_ratio * w
        b, a = [two_zw, w * w], [1.0, two_zw, w * w]
        bd, ad, _ = signal.cont2discrete((b, a), 1.0 / rate_hz, method="foh")
        self.b = np.atleast_1d(np.squeeze(bd)) / ad[0]
        self.a = np.asarray(ad, dtype=float) / ad[0]
        self.zi = np.zeros(max(len(self.a), len(self.b)) - 1)

    def process(self, s: NDArray) -> NDArray:
        from scipy import signal

        if s.size == 0:
            return s
        y, self.zi = signal.lfilter(self.b, self.a, s, zi=self.zi)
        return y
