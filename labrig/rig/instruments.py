"""The three device roles (DAQ, amplifier, conditioner) and the :class:`Rig` that joins them.

Drivers live in ``labrig.drivers`` (the repository's ``drivers/``) and are found through the
``labrig.drivers`` entry-point group: each entry point names a :class:`DriverInfo` (role, the
pydantic model of its rig-file section, and a factory). :func:`labrig.runner.rigfile.open_rig` reads
a rig file, starts the simulators when the rig is simulated, creates the drivers and returns a
:class:`Rig`.

Units: V, s, Hz, ue (microstrain). Raw DAQ data are volts at the DAQ input; the Rig's helpers
convert them (``gauge_to_strain``, ``monitor_to_volts``, ``temperature_to_degC``).

Safety contract: a driver never steps the output on its own: on a fault it raises a
:class:`~labrig.core.errors.DeviceError` and leaves the output where it is. Bringing the actuator to
0 V is the :class:`Rig`'s job, always by a ramp within the amplifier's current limit
(:mod:`labrig.rig.ramp`): :meth:`Rig.ramp_to_zero` / :meth:`Rig.safe_zero` (never raise),
:meth:`Rig.check` before it raises, :meth:`Rig.zero_on_error` and :meth:`Rig.close`. The ramp
goes through the DAQ's analog output; if the DAQ cannot be written, through the amplifier's
digital setpoint (optional amplifier methods ``take_digital_control(volts)`` and
``set_setpoint(volts)``); only if neither works is the amplifier told to hold 0 V at once.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel

from labrig.core.errors import DeviceError
from labrig.rig.limits import RigLimits
from labrig.rig.ramp import RampRecord, paced_ramp, ramp_rate_V_per_s

log = logging.getLogger("labrig.rig.instruments")

Role = Literal["daq", "amplifier", "conditioner"]

#: conversion of the optional ``temperature`` AI channel: degC = volts / TEMPERATURE_V_PER_DEGC
#: (an LM35-style sensor, 10 mV/degC, 0 V at 0 degC)
TEMPERATURE_V_PER_DEGC = 0.01
#: an input sample at this fraction of the DAQ's input range or beyond is taken as clipped (a
#: 16-bit converter's last codes are 0.99997 of its range)
CLIP_FRACTION = 0.9999


def converter_step_V(range_V: float, bits: int) -> float:
    """Volts of one code of a bipolar converter of ``bits`` bits over +-``range_V`` V:
    ``2 range_V / 2**bits`` (an ADC's or a DAC's least significant bit)."""
    return 2.0 * range_V / 2**bits


@dataclass
class AcquiredBlock:
    """One block of a playback: AI volts per channel name, samples ``start .. start+len-1``."""

    start: int
    channels: dict[str, NDArray[np.float64]]

    def __len__(self) -> int:
        return len(next(iter(self.channels.values()))) if self.channels else 0


@dataclass(frozen=True)
class AmplifierStatus:
    """Amplifier fault state. ``overflow``: output clipped or current-limited (latched until
    read); ``over_temperature``: output stage shut down; ``error_code``: the device's last
    error (0 = none); ``online``: digital control (analog input ignored) when True."""

    overflow: bool
    over_temperature: bool
    error_code: int = 0
    online: bool | None = None
    detail: str = ""

    @property
    def ok(self) -> bool:
        return not (self.overflow or self.over_temperature or self.error_code)

    def problems(self) -> list[str]:
        out = []
        if self.over_temperature:
            out.append("over-temperature: the output stage shut down")
        if self.overflow:
            out.append("overflow: the output was clipped or current-limited")
        if self.error_code:
            out.append(f"device error code {self.error_code}")
        return out


@dataclass(frozen=True)
class ConditionerStatus:
    """Conditioner fault state (see the register map in docs/instruments.md)."""

    over_range: bool
    excitation_fault: bool
    balance_failed: bool
    error_code: int = 0
    filter_on: bool = False
    detail: str = ""

    @property
    def ok(self) -> bool:
        return not (
            self.over_range or self.excitation_fault or self.balance_failed or self.error_code
        )

    def problems(self) -> list[str]:
        out = []
        if self.excitation_fault:
            out.append("bridge excitation fault (open or shorted gauge)")
        if self.over_range:
            out.append("input over range")
        if self.balance_failed:
            out.append("zero balance failed (imbalance beyond the balance range)")
        if self.error_code:
            out.append(f"device error code {self.error_code}")
        return out


@runtime_checkable
class DAQ(Protocol):
    """Hardware-timed AO playback with synchronised AI (one AI sample per AO sample).

    Optional: ``abort_playback()`` ends a playback with the AO holding its present value (the
    ramp to 0 V starts from there), ``ao_level()`` the AO volts last output (used when the
    amplifier cannot report its output voltage), ``ao_step_V()`` the volts of one code of the
    AO converter (``None``: unknown; see :meth:`Rig.volts_to_ao`).
    """

    def identify(self) -> str: ...
    def configure(self, rate_hz: float, ai_channels: list[str]) -> None: ...
    def ai_channel_names(self) -> list[str]: ...
    def play(self, ao_volts: NDArray, block_size: int) -> Iterator[AcquiredBlock]: ...
    def write_static(self, volts: float) -> None: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...


@runtime_checkable
class Amplifier(Protocol):
    """Piezo amplifier: gain, limits, enable (analog control) / disable (held at 0 V).

    ``safe_zero`` holds the output at 0 V at once: the Rig calls it after the ramp, when the
    output is already at 0 V. Optional, for the ramp when the DAQ fails:
    ``take_digital_control(volts)`` (hold ``volts`` from the digital setpoint, ignoring the
    analog input) and ``set_setpoint(volts)``.
    """

    gain: float

    def identify(self) -> str: ...
    def output_limits(self) -> tuple[float, float]: ...
    def enable(self) -> None: ...
    def disable(self) -> None: ...
    def read_voltage(self) -> float: ...
    def read_current(self) -> float | None: ...
    def status(self) -> AmplifierStatus: ...
    def safe_zero(self) -> None: ...
    def close(self) -> None: ...


@runtime_checkable
class Conditioner(Protocol):
    """Strain-gauge conditioner: excitation, gain, filter, balance, calibration."""

    def identify(self) -> str: ...
    def configure(self, excitation_V: float, gain: float, filter_hz: float) -> None: ...
    def zero(self) -> None: ...
    def status(self) -> ConditionerStatus: ...
    def sensitivity_mV_per_ue(self) -> float: ...
    def gain(self) -> float: ...
    def close(self) -> None: ...


# -- driver registry ----------------------------------------------------------------------------


@dataclass
class DriverContext:
    """What :func:`labrig.runner.rigfile.open_rig` hands a driver factory.

    ``endpoints`` maps simulator kinds (``"gcs"``, ``"modbus_tcp"``, ``"modbus_rtu"``) to the
    address of the simulator started for this rig; a rig-file address ``sim`` resolves to it.
    """

    limits: RigLimits
    bench: Any = None
    endpoints: dict[str, str] = field(default_factory=dict)
    seed: int | None = None

    def resolve(self, kind: str, address: str) -> str:
        if address != "sim":
            return address
        if kind not in self.endpoints:
            raise DeviceError(kind, "open", "address 'sim' but no simulator of this kind runs")
        return self.endpoints[kind]


@dataclass(frozen=True)
class Package:
    """A Python package a driver needs: the name it is imported as, the distribution that
    provides it (what ``pip`` installs) and the command that installs it."""

    module: str
    distribution: str
    install: str


@dataclass(frozen=True)
class DriverInfo:
    """A driver as registered under the ``labrig.drivers`` entry-point group: its role, the
    pydantic model of its rig-file section, its factory, a one-line summary, the Python
    packages it needs and, in words, what else it needs that only opening it can check (a
    vendor's runtime)."""

    name: str
    role: Role
    settings: type[BaseModel]
    create: Callable[[Any, DriverContext], Any]
    summary: str = ""
    packages: tuple[Package, ...] = ()
    runtime: str = ""


@dataclass(frozen=True)
class SimulatorInfo:
    """The virtual bench as registered under the ``labrig.simulators`` entry-point group: the
    pydantic model of a rig file's ``bench`` section, and ``start(spec, seed)``, which starts the
    bench and its protocol servers for a validated simulated rig (a
    :class:`~labrig.rig.rigspec.RigSpec`) and returns them running (``stop()`` ends them)."""

    name: str
    config: type[BaseModel]
    start: Callable[[Any, int | None], Any]


# -- the rig ------------------------------------------------------------------------------------


def _describe(dev: Any) -> dict:
    fn = getattr(dev, "describe", None)
    if callable(fn):
        try:
            return fn()
        except Exception as e:  # describing must never break a run
            return {"error": str(e)}
    return {"class": type(dev).__name__}


@dataclass
class Rig:
    """A DAQ, an amplifier and a conditioner with the rig's limits and calibrations.

    ``closers`` are called by :meth:`close` after the devices (simulators started for this rig);
    ``sim`` gives tests access to the running simulators (``None`` on a real rig).
    """

    name: str
    daq: DAQ
    amplifier: Amplifier
    conditioner: Conditioner
    limits: RigLimits
    rate_limits: tuple[float, float]
    rig_text: str
    monitor_V_per_V: float = 0.05
    seed: int | None = None
    sim: Any = None
    closers: list[Callable[[], None]] = field(default_factory=list)
    _closed: bool = field(default=False, repr=False)
    _said: set[str] = field(default_factory=set, repr=False)

    # -- calibrations --------------------------------------------------------------------------
    def volts_to_ao(self, v_actuator: ArrayLike) -> NDArray[np.float64]:
        """DAQ analog-output volts for the actuator voltage ``v_actuator`` (V): divide by the
        gain. The converter rounds each sample to one of its codes, by up to half a code: a
        sample asked for at the rig's limit (``limits.v_min_V`` / ``v_max_V``, which the
        amplifier is set to) could come out just past it, and the amplifier would clamp and
        report an overflow. Samples within one code (``ao_step_V()`` of the DAQ, when it says)
        of a limit are drawn in to one code inside it; every other sample is as asked."""
        gain = float(self.amplifier.gain)
        ao = np.asarray(v_actuator, dtype=float) / gain
        step_fn = getattr(self.daq, "ao_step_V", None)
        step = step_fn() if callable(step_fn) else None
        if step:
            lo = self.limits.v_min_V / gain + step
            hi = self.limits.v_max_V / gain - step
            if lo < hi:
                ao = np.clip(ao, lo, hi)
        return ao

    def clipped_input(self, channels: Mapping[str, NDArray[np.float64]]) -> str | None:
        """Why the block ``channels`` (AI channel -> raw volts) is clipped, or None: a sample
        of a channel at the end of the DAQ's input range (``ai_range_V()`` of the DAQ, when it
        says), within :data:`CLIP_FRACTION` of it. A converter driven past its range returns
        its last code: the record would show a flat top where the signal went on."""
        range_fn = getattr(self.daq, "ai_range_V", None)
        if not callable(range_fn):
            return None
        lo, hi = range_fn()
        for name, raw in channels.items():
            values = np.asarray(raw, dtype=float)
            at_end = (values <= lo * CLIP_FRACTION) | (values >= hi * CLIP_FRACTION)
            if at_end.any():
                i = int(np.argmax(at_end))
                return (
                    f"the {name} input reached {values[i]:.6g} V, the end of the DAQ's input "
                    f"range ({lo:g} to {hi:g} V), {int(at_end.sum())} times in a block: the "
                    "signal is clipped and the record would be wrong (lower the conditioner's "
                    "gain or the drive, or widen the DAQ's input range)"
                )
        return None

    def ao_to_volts(self, ao: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(ao, dtype=float) * float(self.amplifier.gain)

    def strain_scale_V_per_ue(self) -> float:
        """Gauge-channel volts per ue: sensitivity (mV/ue at gain 1) x conditioner gain."""
        return self.conditioner.sensitivity_mV_per_ue() * 1e-3 * float(self.conditioner.gain())

    def gauge_to_strain(self, raw_volts: ArrayLike) -> NDArray[np.float64]:
        """Strain (ue) from the ``gauge`` channel's volts."""
        return np.asarray(raw_volts, dtype=float) / self.strain_scale_V_per_ue()

    def monitor_to_volts(self, raw_volts: ArrayLike) -> NDArray[np.float64]:
        """Actuator voltage (V) from the ``amp_monitor`` channel (``monitor_V_per_V`` V/V)."""
        return np.asarray(raw_volts, dtype=float) / self.monitor_V_per_V

    @staticmethod
    def temperature_to_degC(raw_volts: ArrayLike) -> NDArray[np.float64]:
        """Temperature (degC) from the ``temperature`` channel (10 mV/degC, 0 V at 0 degC)."""
        return np.asarray(raw_volts, dtype=float) / TEMPERATURE_V_PER_DEGC

    def convert(self, channel: str, raw_volts: ArrayLike) -> tuple[NDArray[np.float64], str]:
        """A channel's values in physical units and the unit: gauge -> ue, amp_monitor -> V,
        temperature -> degC, anything else stays V."""
        if channel == "gauge":
            return self.gauge_to_strain(raw_volts), "ue"
        if channel == "amp_monitor":
            return self.monitor_to_volts(raw_volts), "V"
        if channel == "temperature":
            return self.temperature_to_degC(raw_volts), "degC"
        return np.asarray(raw_volts, dtype=float), "V"

    # -- logging -------------------------------------------------------------------------------
    def describe(self) -> dict:
        """Identity and settings of every device (for the run file's NXinstrument groups)."""
        out: dict[str, Any] = {
            "name": self.name,
            "seed": self.seed,
            "simulated": self.sim is not None,
            "limits": self.limits.model_dump(),
            "calibration": {
                "amplifier_gain_V_per_V": float(self.amplifier.gain),
                "monitor_V_per_V": self.monitor_V_per_V,
                "temperature_V_per_degC": TEMPERATURE_V_PER_DEGC,
            },
            "daq": _describe(self.daq),
            "amplifier": _describe(self.amplifier),
            "conditioner": _describe(self.conditioner),
        }
        try:
            out["calibration"]["sensitivity_mV_per_ue"] = self.conditioner.sensitivity_mV_per_ue()
            out["calibration"]["conditioner_gain"] = float(self.conditioner.gain())
        except DeviceError as e:
            out["calibration"]["error"] = str(e)
        if self.sim is not None:
            out["bench"] = self.sim.describe()
        return out

    # -- health and safety ---------------------------------------------------------------------
    def check(self) -> None:
        """Raise :class:`DeviceError` if the amplifier or the conditioner reports a fault (the
        output is ramped to 0 V first)."""
        amp = self.amplifier.status()
        if not amp.ok:
            self.safe_zero()
            raise DeviceError("amplifier", "status check", "; ".join(amp.problems()))
        cond = self.conditioner.status()
        if not cond.ok:
            self.safe_zero()
            raise DeviceError("conditioner", "status check", "; ".join(cond.problems()))

    def output_now(self) -> tuple[float, str]:
        """The actuator voltage now (V) and where it came from: the amplifier's read-back,
        else the DAQ's last output times the gain, else 0 V ("unknown")."""
        try:
            v = float(self.amplifier.read_voltage())
            if math.isfinite(v):
                return v, "amplifier read-back"
        except Exception as e:
            self._error_once(f"ramp: cannot read the amplifier's output voltage: {e}")
        level = getattr(self.daq, "ao_level", None)
        if callable(level):
            try:
                v = float(self.ao_to_volts(level()))
                if math.isfinite(v):
                    return v, "DAQ output level"
            except Exception as e:
                self._error_once(f"ramp: cannot read the DAQ's output level: {e}")
        return 0.0, "unknown"

    def ramp_to_zero(self) -> RampRecord:
        """Ramp the actuator from its present voltage to 0 V within the current limit, paced by
        the wall clock (:func:`labrig.rig.ramp.paced_ramp`), then hold 0 V (DAQ stopped at 0 V,
        amplifier at 0 V and disabled). Never raises; what happened is in the record."""
        abort = getattr(self.daq, "abort_playback", None)
        if callable(abort):  # a suspended playback holds the AO; end it without moving it
            try:
                abort()
            except Exception as e:
                self._error_once(f"ramp: ending the DAQ playback failed: {e}")
        start, source = self.output_now()
        rec = RampRecord(start, source, ramp_rate_V_per_s(self.limits))
        try:
            paced_ramp(self._write_ao, start, rec.rate_V_per_s, rec)
            rec.path = "daq"
        except Exception as e:
            rec.errors.append(f"DAQ: {e}")
            self._error_once(f"ramp: the DAQ failed ({e}); ramping the amplifier's setpoint")
            self._ramp_setpoint(rec)
        self._hold_zero()
        return rec

    def _write_ao(self, volts: float) -> None:
        self.daq.write_static(float(self.volts_to_ao(volts)))

    def _ramp_setpoint(self, rec: RampRecord) -> None:
        take = getattr(self.amplifier, "take_digital_control", None)
        setpoint = getattr(self.amplifier, "set_setpoint", None)
        if not (callable(take) and callable(setpoint)):
            rec.errors.append("amplifier: no digital setpoint to ramp")
            return
        start = rec.volts[-1] if rec.volts else rec.start_V
        try:
            start = float(self.amplifier.read_voltage())
        except Exception as e:
            self._error_once(f"ramp: no read-back before the setpoint ramp: {e}")
        if rec.volts:  # the record keeps the ramp that brought the output down
            rec.errors.append(f"DAQ ramp stopped after {len(rec.volts)} writes at {start:g} V")
            rec.times_s.clear()
            rec.volts.clear()
        try:
            take(start)
            paced_ramp(setpoint, start, rec.rate_V_per_s, rec)
            rec.path = "amplifier setpoint"
        except Exception as e:
            rec.errors.append(f"amplifier: {e}")
            self._error_once(f"ramp: the amplifier setpoint ramp failed: {e}")

    def _error_once(self, message: str) -> None:
        """Log ``message`` as an error unless this rig logged it already (a failing device
        fails the same way at every ramp: the run's end and the close)."""
        if message not in self._said:
            self._said.add(message)
            log.error("%s", message)

    def _hold_zero(self) -> None:
        try:
            self.daq.stop()
        except Exception as e:
            self._error_once(f"safe_zero: DAQ stop failed: {e}")
        try:
            self.amplifier.safe_zero()
        except Exception as e:  # safe_zero must not raise, but be sure
            self._error_once(f"safe_zero: amplifier safe_zero failed: {e}")

    def safe_zero(self) -> None:
        """Ramp to 0 V and hold it there (:meth:`ramp_to_zero`); best effort, never raises."""
        self.ramp_to_zero()

    @contextmanager
    def zero_on_error(self) -> Iterator[Rig]:
        """``with rig.zero_on_error(): ...`` brings the output to 0 V on any exception."""
        try:
            yield self
        except BaseException:
            self.safe_zero()
            raise

    def close(self) -> None:
        """Ramp the output to 0 V, close the devices, then stop the simulators this rig
        started."""
        if self._closed:
            return
        self._closed = True
        self.safe_zero()
        for dev in (self.daq, self.amplifier, self.conditioner):
            try:
                dev.close()
            except Exception as e:
                log.error("close: %s: %s", type(dev).__name__, e)
        for fn in reversed(self.closers):
            try:
                fn()
            except Exception as e:
                log.error("close: stopping a simulator failed: %s", e)

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
