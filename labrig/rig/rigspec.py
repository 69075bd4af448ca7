"""Rig files: which driver per role, addresses, calibrations, limits, and the simulated bench.

A rig file is YAML validated by pydantic (errors name the file, the line and the field). Top
level keys::

    name: sim                      # required
    description: ...               # optional, free text
    daq:         {driver: sim_daq, ...driver settings}
    amplifier:   {driver: pi_e503, url: sim, gain_V_per_V: 10, ...}
    conditioner: {driver: strain_modbus, transport: tcp, address: sim, ...}
    limits:      {v_min_V: -20, v_max_V: 100, capacitance_F: 6e-6, ...}   (rig.limits.RigLimits)
    bench:       {truth: ..., amplifier: ..., gauge: ..., daq: ..., effects: [...]}  (simulated)
    simulator:   {seed: null, gcs_port: 0, modbus_tcp_port: 0, modbus_rtu_port: 0}

Each role's keys besides ``driver`` are that driver's settings (its pydantic model). Drivers are
found through the ``labrig.drivers`` entry-point group, the virtual bench through
``labrig.simulators``.
A rig is *simulated* when it has a ``bench`` section, uses the ``sim_daq`` driver, or gives the
address ``sim``: :func:`labrig.runner.rigfile.open_rig` then starts the virtual bench and its
protocol servers on 127.0.0.1 and the real drivers talk to them over their transports. Full
reference: ``docs/instruments.md``.

This module reads and validates (it opens nothing and starts nothing); :mod:`labrig.runner.rigfile`
opens a rig. The simulators (:mod:`labrig.drivers.sim.serve`) read rig files from here, so
imports run one way: ``rigfile -> drivers.sim.serve -> rigspec``.
"""

from __future__ import annotations

import functools
import importlib
import logging
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model

from labrig.core.errors import DeviceError, InputFileError, InputIssue
from labrig.core.numbers import beyond, exact
from labrig.core.seeds import MAX_SEED
from labrig.core.yamlio import issues_from_validation, line_index, read_yaml
from labrig.rig.instruments import DriverInfo, SimulatorInfo
from labrig.rig.limits import RigLimits

log = logging.getLogger("labrig.rig.rigspec")

ENTRY_POINT_GROUP = "labrig.drivers"
#: the entry-point group of the virtual bench (its ``bench`` section and its simulators)
SIMULATOR_GROUP = "labrig.simulators"
ROLES = ("daq", "amplifier", "conditioner")

#: how to install the packages the built-in drivers import when they are loaded (a driver whose
#: package is missing cannot say so itself: its module does not import)
INSTALL_HINTS = {
    "serial": "pip install pyserial",
    "pymodbus": "pip install 'pymodbus>=3.16,<3.17'",
    "nidaqmx": "pip install 'labrig[nidaq]'",
}

DEFAULT_RIG_NAME = "<built-in default rig: experiments/rigs/sim.yaml>"

#: the default simulated rig (kept identical to experiments/rigs/sim.yaml; a test checks)
DEFAULT_RIG_YAML = """\
# The default simulated rig: the paper's bench on the virtual bench.
# A PI E-503 (gain 10) drives a P-888.51-class stack (6 uF, 0-100 V); a 120 ohm foil gauge on a
# DH3840-class conditioner (1.085 mV/ue) feeds a 16-bit DAQ. The simulators start on 127.0.0.1
# and the real drivers talk to them over their transports (address "sim").
name: sim
description: Virtual bench with the paper's instruments (paper truth, realistic noise)

daq:
  driver: sim_daq
  realtime: false

amplifier:
  driver: pi_e503
  url: sim                   # pyserial URL of the GCS link; sim = the simulated amplifier
  timeout_s: 1.0              # simulators share the CPU: a loaded machine delays answers
  axis: A
  channel: "1"
  gain_V_per_V: 10.0         # calibration: actuator volts per DAQ AO volt
  monitor_V_per_V: 0.05      # amp_monitor channel volts per actuator volt
  apply_voltage_limits: true # set the amplifier's VMI/VMA to limits.v_min_V/v_max_V

conditioner:
  driver: strain_modbus
  transport: tcp             # tcp (address host:port) or rtu (serial port or pyserial URL)
  address: sim
  unit: 1
  timeout_s: 1.0              # simulators share the CPU: a loaded machine delays answers
  excitation_V: 2.0
  gain: 1
  filter_hz: 0               # conditioner low-pass, 0 = off
  sensitivity_mV_per_ue: 1.085   # calibration at gain 1
  zero_on_open: true

limits:
  v_min_V: -20.0
  v_max_V: 100.0
  capacitance_F: 6.0e-6
  large_signal_factor: 1.7
  i_peak_A: 0.18
  i_avg_A: 0.12
  rate_min_hz: 10.0
  rate_max_hz: 100000.0

bench:
  truth:
    preset: paper            # paper (labrig.model with a preset) or hybrid (the paper's section 4)
    paper_params: PAPER_TABLE1
  amplifier:
    gain_V_per_V: 10.0
    out_min_V: -30.0
    out_max_V: 130.0
    current_limit: true      # peak/average current from limits (i_peak_A, i_avg_A)
    monitor_V_per_V: 0.05
  gauge:
    sensitivity_mV_per_ue: 1.085
    noise_ue: 2.0
    bridge_offset_ue: 40.0
  daq:
    ai_range_V: 10.0
    ai_bits: 16
    ao_range_V: 10.0
    ao_bits: 16
  effects: []                # e.g. [{name: self_heating}, {name: mains_pickup, amplitude_mV: 3}]
"""


class _Role(BaseModel):
    model_config = ConfigDict(extra="allow")

    driver: str = Field(description="driver name (labrig.drivers entry point)")


class SimulatorSettings(BaseModel):
    """Seed and ports of the simulators (0 = a free port)."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    seed: int | None = Field(
        None, ge=0, le=MAX_SEED, description="bench RNG seed when open_rig is given none"
    )
    gcs_port: int = Field(0, ge=0, le=65535)
    modbus_tcp_port: int = Field(0, ge=0, le=65535)
    modbus_rtu_port: int = Field(0, ge=0, le=65535)


def simulator(name: str = "bench") -> SimulatorInfo:
    """The virtual bench registered as ``name`` in the ``labrig.simulators`` entry points
    (looked up once per process: each look-up reads every installed package's entry points,
    tens of milliseconds; a failed look-up is not kept)."""
    return _simulator(name)


@functools.cache
def _simulator(name: str) -> SimulatorInfo:
    try:
        eps = metadata.entry_points(group=SIMULATOR_GROUP, name=name)
    except Exception as e:  # a broken installation
        raise DeviceError("simulator", "find the virtual bench", str(e)) from None
    for ep in eps:
        info = ep.load()
        if isinstance(info, SimulatorInfo):
            return info
    raise DeviceError(
        "simulator",
        "find the virtual bench",
        f"no {name!r} entry point in the {SIMULATOR_GROUP!r} group: reinstall labrig "
        "(pip install -e .)",
    )


def _bench_model() -> type[BaseModel]:
    return simulator().config


def _outline() -> type[BaseModel]:
    return create_model(
        "RigFileOutline",
        __config__=ConfigDict(extra="forbid", strict=True),
        name=(str, Field(min_length=1)),
        description=(str, ""),
        daq=(_Role, ...),
        amplifier=(_Role, ...),
        conditioner=(_Role, ...),
        limits=(RigLimits, RigLimits()),
        # the bench's model is made at run time: its optional type is a runtime union
        bench=(_bench_model() | None, None),  # type: ignore[arg-type]
        simulator=(SimulatorSettings, SimulatorSettings()),
    )


def reach_issues(resolved: Any, name: str, lines: dict) -> list[InputIssue]:
    """The rig's voltage limits against what its instruments can drive: the DAQ's AO range
    (its section's ``ao_range_V``, or the simulated bench's ``bench.daq.ao_range_V``) times the
    amplifier's ``gain_V_per_V``, and the simulated amplifier's output range
    (``bench.amplifier.out_min_V`` / ``out_max_V``), where the rig file gives them. A limit
    beyond them passed the preflight and failed at the run's start (the amplifier refusing
    the limit, or the DAQ the waveform)."""
    bench = resolved.bench
    gain = getattr(resolved.amplifier, "gain_V_per_V", None)
    ao_range = getattr(resolved.daq, "ao_range_V", None)
    if ao_range is None:  # the simulated DAQ's range is the bench's (None: no bench)
        ao_range = getattr(getattr(bench, "daq", None), "ao_range_V", None)
    spans: list[tuple[float, float, str]] = []
    if isinstance(gain, float) and isinstance(ao_range, float):
        what = f"the DAQ's +-{ao_range:g} V output times the amplifier's gain of {gain:g}"
        spans.append((-ao_range * gain, ao_range * gain, what))
    amp = getattr(bench, "amplifier", None)
    if amp is not None and isinstance(getattr(amp, "out_max_V", None), float):
        what = "the simulated amplifier's output range (bench.amplifier.out_min_V..out_max_V)"
        spans.append((amp.out_min_V, amp.out_max_V, what))
    limits = resolved.limits
    issues = []
    for lo, hi, what in spans:
        for key, value, ok in (
            ("v_min_V", limits.v_min_V, limits.v_min_V >= lo),
            ("v_max_V", limits.v_max_V, limits.v_max_V <= hi),
        ):
            if not ok:
                line = lines.get(("limits", key), lines.get(("limits",)))
                msg = (
                    f"{beyond(value, hi if key == 'v_max_V' else lo)} V is beyond what the rig "
                    f"can drive: {what} is {exact(lo)} to {exact(hi)} V; give a limit within it"
                )
                issues.append(InputIssue(name, line, f"limits.{key}", msg))
    return issues


# -- driver registry ------------------------------------------------------------------------


def _load_ref(ref: str) -> DriverInfo:
    mod, _, attr = ref.partition(":")
    return getattr(importlib.import_module(mod), attr)


@dataclass(frozen=True)
class DriverEntry:
    """One ``labrig.drivers`` entry point: the driver's ``name``, its ``module:object``
    reference and the installed distribution that registers it (``name version``, ``?`` if
    unknown)."""

    name: str
    ref: str
    provided_by: str


def driver_entries() -> tuple[DriverEntry, ...]:
    """The ``labrig.drivers`` entry points, read once per process (each read goes through
    every installed package's entry points: about 12 ms, and a ``check`` or ``run`` needs the
    list four times). A read that raises (a broken installation) is not kept: the next call
    reads again."""
    return _driver_entries()


@functools.cache
def _driver_entries() -> tuple[DriverEntry, ...]:
    out = []
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        dist = getattr(ep, "dist", None)
        provided_by = f"{dist.name} {dist.version}" if dist is not None else "?"
        out.append(DriverEntry(ep.name, ep.value, provided_by))
    return tuple(out)


def driver_names() -> dict[str, str]:
    """Driver name -> ``module:object`` reference, from the ``labrig.drivers`` entry points
    (labrig's own drivers are registered there too, by its installation)."""
    try:
        return {e.name: e.ref for e in driver_entries()}
    except Exception as e:  # a broken installation: say so; the caller finds no driver
        log.warning("reading the %s entry points failed: %s", ENTRY_POINT_GROUP, e)
        return {}


def missing_package(role: str, driver: str, e: ModuleNotFoundError) -> DeviceError:
    """The device fault (exit 3) of a driver whose module needs a package that is not
    installed: the role and driver, the operation (loading it), the package and how to
    install it."""
    module = (e.name or "").split(".")[0] or "?"
    hint = INSTALL_HINTS.get(module, f"install the package that provides {module!r}")
    return DeviceError(
        f"{role} ({driver} driver)",
        "load driver",
        f"the Python package {module!r} is not installed ({hint})",
    )


def get_driver(name: str, names: dict[str, str] | None = None) -> DriverInfo:
    """The :class:`DriverInfo` registered as ``name`` (KeyError if there is none; the
    ``ModuleNotFoundError`` of a package its module needs)."""
    ref = (names or driver_names()).get(name)
    if ref is None:
        raise KeyError(name)
    info = _load_ref(ref)
    if not isinstance(info, DriverInfo):
        raise TypeError(f"entry point {name!r} ({ref}) is not a labrig DriverInfo")
    return info


# -- loading --------------------------------------------------------------------------------


@dataclass
class RigSpec:
    """A validated rig file: settings per role and their drivers."""

    name: str
    source: str
    text: str
    description: str
    limits: RigLimits
    drivers: dict[str, DriverInfo]
    settings: dict[str, BaseModel]
    bench_config: Any
    simulator: SimulatorSettings

    @property
    def simulated(self) -> bool:
        addr = [getattr(s, k, None) for s in self.settings.values() for k in ("url", "address")]
        return (
            self.bench_config is not None or self.drivers["daq"].name == "sim_daq" or "sim" in addr
        )

    @property
    def seed_hint(self) -> int | None:
        return self.simulator.seed

    @property
    def sim_ports(self) -> dict[str, int]:
        s = self.simulator
        return {"gcs": s.gcs_port, "modbus_tcp": s.modbus_tcp_port, "modbus_rtu": s.modbus_rtu_port}


def _parse_text(text: str, name: str) -> tuple[Any, dict]:
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)(text)
    try:
        node = loader.get_single_node()
        data = loader.construct_document(node) if node is not None else None
    except yaml.YAMLError as e:
        raise InputFileError([InputIssue(name, None, "", f"YAML error: {e}")]) from e
    finally:
        loader.dispose()
    return data, (line_index(node) if node is not None else {})


def load_rig(path: Path | str | None = None) -> RigSpec:
    """Read and validate a rig file (None: the built-in default rig) without opening anything."""
    if path is None:
        name, text = DEFAULT_RIG_NAME, DEFAULT_RIG_YAML
        data, lines = _parse_text(text, name)
    else:
        name = str(path)
        data, lines, text = read_yaml(path)
    if not isinstance(data, dict):
        what = "empty" if data is None else f"a {type(data).__name__}"
        line = lines.get((), 1)
        raise InputFileError([InputIssue(name, line, "", f"expected a YAML mapping, got {what}")])
    outline_model = _outline()
    try:
        outline = outline_model.model_validate(data)
    except ValidationError as e:
        raise InputFileError(issues_from_validation(name, e, lines)) from e
    # resolve the drivers, then validate each role section against its driver's settings
    issues: list[InputIssue] = []
    drivers: dict[str, DriverInfo] = {}
    names = driver_names()
    for role in ROLES:
        drv = getattr(outline, role).driver
        line = lines.get((role, "driver"))
        try:
            info = get_driver(drv, names)
        except KeyError:
            known = ", ".join(sorted(names))
            issues.append(
                InputIssue(
                    name, line, f"{role}.driver", f"unknown driver {drv!r}; known drivers: {known}"
                )
            )
            continue
        except ModuleNotFoundError as e:  # a package the driver needs: a device fault, exit 3
            raise missing_package(role, drv, e) from None
        except Exception as e:
            issues.append(InputIssue(name, line, f"{role}.driver", f"driver {drv!r} fails: {e}"))
            continue
        if info.role != role:
            issues.append(
                InputIssue(
                    name,
                    line,
                    f"{role}.driver",
                    f"driver {drv!r} is a {info.role} driver, not a {role} one",
                )
            )
            continue
        drivers[role] = info
    if issues:
        raise InputFileError(issues)
    fields: dict[str, Any] = {role: (drivers[role].settings, ...) for role in ROLES}
    full = create_model("RigFileResolved", __base__=outline_model, **fields)
    try:
        # a model made at run time: its fields are known to the checker as Any
        resolved: Any = full.model_validate(data)
    except ValidationError as e:
        raise InputFileError(issues_from_validation(name, e, lines)) from e
    reach = reach_issues(resolved, name, lines)
    if reach:
        raise InputFileError(reach)
    return RigSpec(
        name=resolved.name,
        source=name,
        text=text,
        description=resolved.description,
        limits=resolved.limits,
        drivers=drivers,
        settings={role: getattr(resolved, role) for role in ROLES},
        bench_config=resolved.bench,
        simulator=resolved.simulator,
    )
