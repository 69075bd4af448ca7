"""The virtual bench: the physics behind the three simulators (DAQ, amplifier, conditioner).

One :class:`VirtualBench` holds the whole signal chain of the paper's bench and is shared by the
simulated DAQ (in-process), the GCS responder (amplifier, over a socket) and the Modbus server
(conditioner, over TCP or RTU framing). Per sample interval ``n`` (rate ``fs``)::

    AO[n] --DAC(range, bits)--> amplifier: u = gain AO (OFFLINE) | SVA (ONLINE) | 0 (over-temp)
          --clip [max(out_min, VMI), min(out_max, VMA)]--> current limit |C_eff dv/dt| <= I
          --> v[n] (actuator voltage, held over interval n; also the amp_monitor channel)
    v --[amplifier_output_rc]--[depoling]--[field_saturation]--[viscoelastic_mode]--> u
          --truth (paper | hybrid)--> strain --[+ cubic_term]--[+ viscous_slip]--[log_creep]
          --[self_heating gain]--[stack_resonance]--> S[n] (ue) --[gauge_warmup]-->
    S + bridge offset [+ offset_drift] + noise (ue at the bridge)
          --x sensitivity (mV/ue, scaled by excitation) [conditioner_lowpass] [filter setting]
          --x gain - balance--> conditioner output (V, clipped at +-10.5 V) [+ mains_pickup]
          --ADC(range, bits)--> "gauge"

Conventions shared with :mod:`labrig.model`: the truth runs on the sequence ``v`` with the
zero-order hold (``S[n]`` depends on ``v[0..n-1]``: the DAC updates at the instant the ADC
samples), so with every non-ideality off the gauge record is exactly
``DynamicHysteresisModel(params).predict(gain * AO, fs, method="fast")`` times the sensitivity.

Amplifier current limit: the current into the stack is ``i = C_eff dv/dt`` with
``C_eff = capacitance_F * large_signal_factor``; the per-sample voltage step is limited to
``I_lim / (C_eff fs)``. ``I_lim`` is the peak current until the exponential average of ``|i|``
(time constant ``avg_tau_s``) exceeds the average-current rating; the amplifier then folds back
to the average rating until that average falls below 90 % of it. Any clipping or limiting sets
the overflow flag (GCS ``OVF?``, latched until read).

Simulation time advances only while samples are computed (DAQ playback, and ``settle_s`` after
a static change when nothing plays), so runs are deterministic for a given seed; changing the
sample rate rebuilds the discretised physics with the actuator at rest.
"""

from __future__ import annotations

import functools
import math
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from labrig.drivers.sim.effects import (
    AmplifierCurrentLimit,
    ButterLowpass,
    ConditionerLowpass,
    Creep,
    CubicTerm,
    Drift,
    Effect,
    FieldSaturation,
    LogCreep,
    Mains,
    MainsPickup,
    OffsetDrift,
    Retardation,
    SelfHeating,
    Thermal,
    ViscoelasticMode,
    cubic_strain,
    saturated_drive,
)
from labrig.drivers.sim.hybrid import HybridParams
from labrig.drivers.sim.structural import (
    AmplifierOutputRC,
    Depoling,
    GaugeWarmup,
    OutputRC,
    Resonance,
    StackResonance,
    ViscousSlip,
    ViscousSlipElements,
    depoled_drive,
    warmup,
)
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from labrig.model.accel import stream_engine
from labrig.rig.instruments import TEMPERATURE_V_PER_DEGC, converter_step_V
from labrig.rig.limits import RigLimits

if TYPE_CHECKING:
    from labrig.model.modal import DiscreteBank

# -- configuration (the rig file's ``bench:`` section) ---------------------------------------


class _Cfg(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class TruthConfig(_Cfg):
    """The actuator: ``paper`` (the dynamic model with a preset) or ``hybrid`` (the paper's
    section-4 reference plant)."""

    preset: Literal["paper", "hybrid"] = "paper"
    paper_params: str = Field("PAPER_TABLE1", description="a labrig.model.PRESETS name")
    paper_overrides: dict[str, float | str] = Field(
        default_factory=dict, description="ModelParams fields replacing the preset's values"
    )
    hybrid: HybridParams = HybridParams()

    @model_validator(mode="after")
    def _check(self) -> TruthConfig:
        self.model_params()  # raises ValueError with the field at fault
        return self

    def model_params(self):
        from labrig.model.params import PRESETS

        if self.paper_params not in PRESETS:
            raise ValueError(
                f"paper_params must be one of {sorted(PRESETS)}, got {self.paper_params!r}"
            )
        base = PRESETS[self.paper_params]
        return type(base).model_validate({**base.model_dump(), **self.paper_overrides})


class AmplifierPhysics(_Cfg):
    """The E-503-style amplifier driving the stack."""

    gain_V_per_V: float = Field(10.0, gt=0)
    out_min_V: float = Field(-30.0, description="lowest output the amplifier can produce")
    out_max_V: float = Field(130.0, description="highest output the amplifier can produce")
    current_limit: bool = Field(True, description="limit |C_eff dv/dt| to the current ratings")
    i_peak_A: float | None = Field(None, gt=0, description="peak current (None: rig limits)")
    i_avg_A: float | None = Field(None, gt=0, description="average current (None: rig limits)")
    avg_tau_s: float = Field(0.05, gt=0, description="averaging time of the average current")
    capacitance_F: float | None = Field(None, gt=0, description="None: rig limits")
    large_signal_factor: float | None = Field(None, ge=1, description="None: rig limits")
    monitor_V_per_V: float = Field(0.05, gt=0, description="monitor output per output volt")
    monitor_noise_V: float = Field(0.0005, ge=0, description="monitor noise at the DAQ (rms)")

    @model_validator(mode="after")
    def _range(self) -> AmplifierPhysics:
        if self.out_min_V >= self.out_max_V:
            raise ValueError("out_min_V must be below out_max_V")
        return self


class GaugePhysics(_Cfg):
    """Strain gauge, bridge and conditioner front end."""

    sensitivity_mV_per_ue: float = Field(1.085, gt=0, description="at gain 1, cal. excitation")
    calibration_excitation_V: float = Field(2.0, gt=0)
    noise_ue: float = Field(2.0, ge=0, description="white noise (rms, ue) at the DAQ rate")
    bridge_offset_ue: float = Field(40.0, description="bridge imbalance before zeroing")
    excitation_V: float = Field(2.0, gt=0, description="power-on excitation setting")
    gain: int = Field(1, ge=1, description="power-on gain setting")
    filter_hz: int = Field(0, ge=0, description="power-on filter setting (0 = off)")


class DaqPhysics(_Cfg):
    """DAQ converters: +-range and resolution (None: ideal, no quantisation)."""

    ai_range_V: float = Field(10.0, gt=0)
    ai_bits: int | None = Field(16, ge=8, le=24)
    ao_range_V: float = Field(10.0, gt=0)
    ao_bits: int | None = Field(16, ge=8, le=24)


class BenchConfig(_Cfg):
    """The rig file's ``bench:`` section (simulated rigs only)."""

    truth: TruthConfig = TruthConfig()
    amplifier: AmplifierPhysics = AmplifierPhysics()
    gauge: GaugePhysics = GaugePhysics()
    daq: DaqPhysics = DaqPhysics()
    effects: list[Effect] = Field(default_factory=list)
    settle_s: float = Field(0.02, ge=0, description="simulated time after a static change")

    @field_validator("effects")
    @classmethod
    def _unique(cls, v: list) -> list:
        names = [e.name for e in v]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"effect listed more than once: {', '.join(dup)}")
        return v

    def effect(self, kind: type):
        return next((e for e in self.effects if isinstance(e, kind)), None)

    def filters(self, conditioner_filter_hz: float = 0.0) -> bool:
        """Whether this bench runs scipy.signal's filters: with an effect on, a truth other than
        the paper's model, or the conditioner's low-pass on at power-on or set to
        ``conditioner_filter_hz`` later. The paper's truth with none of them needs none."""
        return (
            bool(self.effects)
            or self.truth.preset != "paper"
            or self.gauge.filter_hz > 0
            or conditioner_filter_hz > 0
        )

    @classmethod
    def ideal(cls, truth: str = "paper") -> BenchConfig:
        """Every non-ideality off: no noise, offset, quantisation, current limit or filter."""
        return cls(
            truth=TruthConfig(preset=truth),
            amplifier=AmplifierPhysics(current_limit=False, monitor_noise_V=0.0),
            gauge=GaugePhysics(noise_ue=0.0, bridge_offset_ue=0.0),
            daq=DaqPhysics(ai_bits=None, ao_bits=None),
        )


# -- runtime state -----------------------------------------------------------------------------


@dataclass
class AmplifierState:
    online: bool = False  # E-517 ONLINE: output from the digital setpoint (SVA), analog ignored
    sva_V: float = 0.0
    vmi_V: float = -30.0
    vma_V: float = 130.0
    v_out: float = 0.0
    i_out: float = 0.0
    i_avg: float = 0.0
    folded: bool = False
    limiting: bool = False  # clipped or current-limited at the latest sample
    overflow_latch: bool = False
    over_temperature: bool = False
    forced_overload: bool = False  # injected fault: the overload flag stays set


@dataclass
class ConditionerState:
    excitation_V: float = 2.0
    gain: int = 1
    filter_hz: int = 0
    balance_ue: float = 0.0
    over_range: bool = False
    excitation_fault: bool = False
    balance_failed: bool = False
    error_code: int = 0
    output_V: float = 0.0


BALANCE_RANGE_UE = 5000.0  # the conditioner can null bridge imbalances up to this size


@dataclass
class _Chain:
    """Rate-dependent parts, rebuilt when the sample rate changes."""

    rate_hz: float
    truth: object
    hidden_lp: ButterLowpass | None
    filt: ButterLowpass
    creep: Creep | None
    thermal: Thermal | None
    retardation: Retardation | None = None
    extra: dict = field(default_factory=dict)


@functools.lru_cache(maxsize=8)
def average_current_bank(k: float) -> DiscreteBank:
    """The amplifier's average current, ``i_avg[n] = (1 - k) i_avg[n-1] + k |i[n]|``, as one
    first-order mode of the model's modal bank (rather than scipy.signal's ``lfilter``, a
    heavy import). Kept per ``k`` (a rate and an averaging time): the bank keeps the forms
    it derives for its runs, and a run has hundreds of blocks."""
    from labrig.model.modal import DiscreteBank

    return DiscreteBank.from_arrays([1.0 - k], [0.0], [k], [1.0])


class VirtualBench:
    """The shared physics; thread-safe (the GCS and Modbus servers run in their own threads)."""

    def __init__(
        self,
        config: BenchConfig | None = None,
        limits: RigLimits | None = None,
        seed: int | None = None,
        rate_hz: float = 1000.0,
    ):
        self.config = config or BenchConfig()
        self.limits = limits or RigLimits()
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.lock = threading.RLock()
        # fixed for the bench's life: a chain rebuilt at another rate later must not start
        # compiled kernels that the simulators' start did not load (a first block would hold
        # the bench past a driver's answer timeout while they load)
        self._engine = stream_engine()
        c = self.config
        lo, hi = self.allowed_range_V
        self.amp = AmplifierState(vmi_V=lo, vma_V=hi)  # the rig's limits from power-on
        g = c.gauge
        self.cond = ConditionerState(
            excitation_V=g.excitation_V, gain=g.gain, filter_hz=g.filter_hz
        )
        self.ao_level = 0.0
        self.time_s = 0.0
        self.playing = False
        self._last_bridge_ue = g.bridge_offset_ue
        self.last: dict[str, float] = {}
        heat = c.effect(SelfHeating)
        self._drift = Drift(c.effect(OffsetDrift), self.rng) if c.effect(OffsetDrift) else None
        self._mains = Mains(c.effect(MainsPickup), self.rng) if c.effect(MainsPickup) else None
        self._heat_cfg = heat
        self._chain: _Chain | None = None
        self.set_rate(rate_hz)

    # -- derived parameters --------------------------------------------------------------------
    @property
    def engine(self) -> str:
        """The model code the bench runs: ``"numpy"``, or ``"compiled"`` when numba's kernels
        were already loaded in this process when the bench was made
        (:func:`labrig.model.accel.stream_engine`)."""
        return self._engine

    @property
    def allowed_range_V(self) -> tuple[float, float]:
        """Output range the simulated amplifier allows VMI/VMA (and so SVA) within (V): the
        rig's limits, inside the amplifier's hardware range ``out_min_V``..``out_max_V``."""
        a, lim = self.config.amplifier, self.limits
        lo, hi = max(a.out_min_V, lim.v_min_V), min(a.out_max_V, lim.v_max_V)
        return (lo, hi) if lo < hi else (a.out_min_V, a.out_max_V)

    @property
    def c_eff_F(self) -> float:
        a, lim = self.config.amplifier, self.limits
        c = a.capacitance_F or lim.capacitance_F
        return c * (a.large_signal_factor or lim.large_signal_factor)

    @property
    def current_ratings_A(self) -> tuple[float, float]:
        """True (peak, average) current of the simulated amplifier."""
        eff = self.config.effect(AmplifierCurrentLimit)
        if eff is not None:
            return eff.i_peak_A, eff.i_avg_A
        a = self.config.amplifier
        return a.i_peak_A or self.limits.i_peak_A, a.i_avg_A or self.limits.i_avg_A

    @property
    def rate_hz(self) -> float:
        return self._chain.rate_hz

    def sensitivity_V_per_ue(self) -> float:
        """Conditioner sensitivity at gain 1 and the present excitation (V/ue)."""
        g = self.config.gauge
        return g.sensitivity_mV_per_ue * 1e-3 * self.cond.excitation_V / g.calibration_excitation_V

    def ai_channels(self) -> list[str]:
        names = ["gauge", "amp_monitor"]
        if self._heat_cfg is not None:
            names.append("temperature")
        return names

    # -- configuration changes -------------------------------------------------------------------
    def set_rate(self, rate_hz: float) -> None:
        with self.lock:
            if self._chain is not None and self._chain.rate_hz == rate_hz:
                return
            c = self.config
            engine = self._engine
            if c.truth.preset == "paper":
                from labrig.model import DynamicHysteresisModel

                model = DynamicHysteresisModel(c.truth.model_params())
                truth = model.stream(rate_hz, engine=engine)
            else:
                from labrig.drivers.sim.hybrid import HybridPlant

                truth = HybridPlant(c.truth.hybrid, rate_hz, engine=engine)
            lp = c.effect(ConditionerLowpass)
            creep = c.effect(LogCreep)
            mode = c.effect(ViscoelasticMode)
            self._chain = _Chain(
                rate_hz=float(rate_hz),
                truth=truth,
                hidden_lp=ButterLowpass(lp.cutoff_hz, lp.order, rate_hz) if lp else None,
                filt=ButterLowpass(self.cond.filter_hz, 2, rate_hz),
                creep=Creep(creep, rate_hz) if creep else None,
                thermal=Thermal(self._heat_cfg, rate_hz) if self._heat_cfg else None,
                retardation=Retardation(mode, rate_hz) if mode else None,
            )
            self._chain.extra = self._structural_chain(rate_hz)
            if self._chain.thermal is not None and self.last.get("temperature_degC"):
                self._chain.thermal.T = self.last["temperature_degC"]

    def _structural_chain(self, rate_hz: float) -> dict:
        """The rate-dependent processors of the structural effects that are on, at rest."""
        c = self.config
        out: dict[str, OutputRC | ViscousSlipElements | Resonance] = {}
        rc = c.effect(AmplifierOutputRC)
        if rc is not None:
            a, lim = c.amplifier, self.limits
            out["output_rc"] = OutputRC(rc, a.capacitance_F or lim.capacitance_F, rate_hz)
        slip = c.effect(ViscousSlip)
        if slip is not None:
            out["viscous_slip"] = ViscousSlipElements(slip, rate_hz)
        res = c.effect(StackResonance)
        if res is not None:
            out["stack_resonance"] = Resonance(res, rate_hz)
        return out

    def set_filter(self, filter_hz: int) -> None:
        with self.lock:
            self.cond.filter_hz = int(filter_hz)
            self._chain.filt = ButterLowpass(self.cond.filter_hz, 2, self._chain.rate_hz)

    def balance(self) -> bool:
        """Auto-balance: null the present bridge signal; False if out of the balance range."""
        with self.lock:
            target = self._last_bridge_ue
            if abs(target) > BALANCE_RANGE_UE:
                self.cond.balance_failed = True
                self.cond.error_code = 2
                return False
            resid = self.config.gauge.noise_ue / 10.0 * self.rng.standard_normal()
            self.cond.balance_ue = target + resid
            self.cond.balance_failed = False
            return True

    @contextmanager
    def playback(self):
        with self.lock:
            if self.playing:
                raise RuntimeError("the bench is already playing")
            self.playing = True
        try:
            yield self
        finally:
            self.playing = False

    def settle(self, seconds: float | None = None) -> None:
        """Advance simulated time with the output held (not while a playback runs)."""
        with self.lock:
            if self.playing:
                return
            n = math.ceil((self.config.settle_s if seconds is None else seconds) * self.rate_hz)
            if n > 0:
                self.step(np.full(n, self.ao_level))

    # -- the physics -----------------------------------------------------------------------------
    def _quantise(self, x: NDArray, rng_V: float, bits: int | None) -> tuple[NDArray, bool]:
        over = bool(np.any(np.abs(x) > rng_V))
        if bits is None:
            return np.clip(x, -rng_V, rng_V), over
        lsb = converter_step_V(rng_V, bits)
        code = np.clip(np.round(x / lsb), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
        return code * lsb, over

    def _slew(self, cmd: NDArray) -> tuple[NDArray, bool, bool]:
        """Current-limited output; (v, limited anywhere, limited at the last sample)."""
        a, fs = self.amp, self.rate_hz
        if not self.config.amplifier.current_limit:
            return cmd, False, False
        C = self.c_eff_F
        i_pk, i_av = self.current_ratings_A
        k = 1.0 - math.exp(-1.0 / (fs * self.config.amplifier.avg_tau_s))
        i_unl = np.abs(C * fs * np.diff(cmd, prepend=a.v_out))
        if not a.folded and float(np.max(i_unl)) <= i_pk:
            # vectorised when nothing limits: below the peak rating, average never above its own
            from labrig.model.modal import run_bank

            i_avg, _ = run_bank(
                average_current_bank(k), i_unl, state=[np.array([a.i_avg])], engine=self._engine
            )
            if float(np.max(i_avg)) <= i_av:
                a.i_avg = float(i_avg[-1])
                return cmd, False, False
        out = np.empty(cmd.size)
        v, ema, folded, limited, now = a.v_out, a.i_avg, a.folded, False, False
        cfs = C * fs
        step_pk, step_av = i_pk / cfs, i_av / cfs
        for j in range(cmd.size):
            dmax = step_av if folded else step_pk
            d = float(cmd[j]) - v
            now = abs(d) > dmax
            if now:
                d = dmax if d > 0 else -dmax
                limited = True
            v += d
            ema += k * (abs(d) * cfs - ema)
            if not folded and ema > i_av:
                folded = True
            elif folded and ema < 0.9 * i_av:
                folded = False
            out[j] = v
        a.i_avg, a.folded = ema, folded
        return out, limited, now

    def _actuator(self, v: NDArray, v_before: float) -> NDArray:
        """Strain (ue) for the actuator voltage ``v`` held over each sample interval (the
        voltage before the block was ``v_before``), before creep and heating."""
        c, ch = self.config, self._chain
        if "output_rc" in ch.extra:
            v = ch.extra["output_rc"].process(v)
        u = v
        dep = c.effect(Depoling)
        if dep is not None:
            u = depoled_drive(u, dep)
        sat = c.effect(FieldSaturation)
        if sat is not None:
            u = saturated_drive(u, sat)
        if ch.retardation is not None:
            u = ch.retardation.process(u)
        s = ch.truth.process(u)
        cubic = c.effect(CubicTerm)
        if cubic is not None:
            # the voltage on the actuator at each sampling instant: the one held over the
            # interval before it (the strain sampled at n has seen v[0..n-1])
            s = s + cubic_strain(np.concatenate(([v_before], v[:-1])), cubic)
        if "viscous_slip" in ch.extra:
            s = s + ch.extra["viscous_slip"].process(v)
        return s

    def step(self, ao: NDArray) -> dict[str, NDArray]:
        """Advance the bench by ``len(ao)`` samples of analog output; all AI channels (V)."""
        with self.lock:
            return self._step(np.asarray(ao, dtype=float))

    def _step(self, ao: NDArray) -> dict[str, NDArray]:
        c, a, cond, ch = self.config, self.amp, self.cond, self._chain
        n, fs = ao.size, ch.rate_hz
        if n == 0:
            return {k: np.zeros(0) for k in self.ai_channels()}
        t = self.time_s + np.arange(n) / fs
        ao_q, _ = self._quantise(ao, c.daq.ao_range_V, c.daq.ao_bits)
        # amplifier
        if a.over_temperature:
            cmd = np.zeros(n)
        elif a.online:
            cmd = np.full(n, a.sva_V)
        else:
            cmd = c.amplifier.gain_V_per_V * ao_q
        lo = max(c.amplifier.out_min_V, a.vmi_V)
        hi = min(c.amplifier.out_max_V, a.vma_V)
        outside = (cmd < lo) | (cmd > hi)
        cmd = np.clip(cmd, lo, hi)
        v, limited, limited_now = self._slew(cmd)
        i = self.c_eff_F * fs * np.diff(v, prepend=a.v_out)
        # an over-temperature shutdown discharges the stack at the current limit: not overflow
        ok = not a.over_temperature
        a.overflow_latch |= ((bool(outside.any()) or limited) and ok) or a.forced_overload
        a.limiting = ((bool(outside[-1]) or limited_now) and ok) or a.forced_overload
        v_before = a.v_out
        a.v_out, a.i_out = float(v[-1]), float(i[-1])
        s = self._actuator(v, v_before)
        if ch.creep is not None:
            s = ch.creep.process(s)
        temp = None
        if ch.thermal is not None:
            temp = ch.thermal.process(v, i)
            s = s * ch.thermal.gain(temp)
        if "stack_resonance" in ch.extra:
            s = ch.extra["stack_resonance"].process(s)
        # gauge and conditioner
        warm = c.effect(GaugeWarmup)
        if warm is not None:
            zero, span = warmup(t, warm)
            s = s * span + zero
        bridge = s + c.gauge.bridge_offset_ue
        if self._drift is not None:
            bridge = bridge + self._drift.process(t, 1.0 / fs)
        self._last_bridge_ue = float(bridge[-1])
        noisy = bridge - cond.balance_ue
        if c.gauge.noise_ue > 0:
            noisy = noisy + c.gauge.noise_ue * self.rng.standard_normal(n)
        x = noisy * self.sensitivity_V_per_ue()
        if ch.hidden_lp is not None:
            x = ch.hidden_lp.process(x)
        x = ch.filt.process(x) * cond.gain
        if cond.excitation_fault:
            x = np.full(n, 10.5)  # open bridge: the conditioner output sits on its rail
        cond.over_range = bool(np.any(np.abs(x) > 10.0))
        x = np.clip(x, -10.5, 10.5)
        cond.output_V = float(x[-1])
        if self._mains is not None:
            x = x + self._mains.process(t)
        out: dict[str, NDArray] = {}
        out["gauge"], _ = self._quantise(x, c.daq.ai_range_V, c.daq.ai_bits)
        mon = v * c.amplifier.monitor_V_per_V
        if c.amplifier.monitor_noise_V > 0:
            mon = mon + c.amplifier.monitor_noise_V * self.rng.standard_normal(n)
        out["amp_monitor"], _ = self._quantise(mon, c.daq.ai_range_V, c.daq.ai_bits)
        if temp is not None:
            h = self._heat_cfg
            tv = temp * TEMPERATURE_V_PER_DEGC  # the Rig converts back with the same constant
            if h.sensor_noise_degC > 0:
                tv = tv + h.sensor_noise_degC * TEMPERATURE_V_PER_DEGC * self.rng.standard_normal(n)
            out["temperature"], _ = self._quantise(tv, c.daq.ai_range_V, c.daq.ai_bits)
            self.last["temperature_degC"] = float(temp[-1])
        self.last.update(strain_ue=float(s[-1]), v_out=a.v_out, gauge_V=cond.output_V)
        self.time_s += n / fs
        return out

    # -- fault injection (tests) ---------------------------------------------------------------
    def inject(self, fault: str, on: bool = True) -> None:
        """Physical faults: ``overload``, ``over_temperature``, ``excitation_fault``."""
        with self.lock:
            if fault == "overload":
                self.amp.forced_overload = on
                self.amp.overflow_latch |= on
                self.amp.limiting = on
            elif fault == "over_temperature":
                self.amp.over_temperature = on
            elif fault == "excitation_fault":
                self.cond.excitation_fault = on
                self.cond.error_code = 1 if on else 0
            else:
                raise ValueError(f"unknown bench fault {fault!r}")
        if fault == "over_temperature" and on:
            self.settle()

    def describe(self) -> dict:
        return {
            "seed": self.seed,
            "config": self.config.model_dump(mode="json"),
            "c_eff_F": self.c_eff_F,
            "current_ratings_A": list(self.current_ratings_A),
            "model_engine": self._engine,
        }
