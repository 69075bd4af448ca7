"""Open a rig: the drivers of a rig file, and the simulators when the rig is simulated.

Reading and validating rig files is :mod:`labrig.rig.rigspec` (re-exported here: ``load_rig``,
``RigSpec``, ``DEFAULT_RIG_YAML``, the driver registry). :func:`open_rig` starts the virtual
bench and its protocol servers on 127.0.0.1 for a simulated rig, creates the drivers and
returns a :class:`~labrig.rig.instruments.Rig`. Full reference: ``docs/instruments.md``.
"""

from __future__ import annotations

import logging
import secrets
from pathlib import Path

from labrig.core.errors import DeviceError
from labrig.rig.instruments import DriverContext, Rig
from labrig.rig.rigspec import (
    DEFAULT_RIG_NAME,
    DEFAULT_RIG_YAML,
    ENTRY_POINT_GROUP,
    ROLES,
    RigSpec,
    SimulatorSettings,
    driver_names,
    get_driver,
    load_rig,
    simulator,
)

log = logging.getLogger("labrig.runner.rigfile")


# -- opening --------------------------------------------------------------------------------


def open_rig(path: Path | str | None = None, seed: int | None = None) -> Rig:
    """Open the rig of ``path`` (None: the built-in default simulated rig).

    For a simulated rig the virtual bench (RNG seeded with ``seed``; else the file's
    ``simulator.seed``; else a fresh random seed, reported as ``rig.seed``) and its GCS and
    Modbus servers start on 127.0.0.1 and are stopped by ``rig.close()``. Raises
    :class:`InputFileError` for a bad file and :class:`DeviceError` when a device fails.
    """
    spec = load_rig(path)
    if seed is None:
        seed = spec.simulator.seed
    if seed is None and spec.simulated:
        seed = secrets.randbits(63)
    ctx = DriverContext(limits=spec.limits, seed=seed)
    sims = None
    opened: list = []
    try:
        if spec.simulated:
            sims = start_simulators(spec, seed)
            ctx.bench, ctx.endpoints = sims.bench, sims.endpoints
        devices = {}
        for role in ROLES:
            devices[role] = spec.drivers[role].create(spec.settings[role], ctx)
            opened.append(devices[role])
    except BaseException:
        for dev in reversed(opened):
            try:
                if hasattr(dev, "safe_zero"):
                    dev.safe_zero()
                dev.close()
            except Exception as e:
                log.error("closing after a failed open: %s", e)
        if sims is not None:
            sims.stop()
        raise
    lim = spec.limits
    return Rig(
        name=spec.name,
        daq=devices["daq"],
        amplifier=devices["amplifier"],
        conditioner=devices["conditioner"],
        limits=lim,
        rate_limits=(lim.rate_min_hz, lim.rate_max_hz),
        rig_text=spec.text,
        monitor_V_per_V=float(getattr(spec.settings["amplifier"], "monitor_V_per_V", 0.05)),
        seed=seed,
        sim=sims,
        closers=[sims.stop] if sims is not None else [],
    )


def start_simulators(spec: RigSpec, seed: int | None):
    """Start the virtual bench and its servers for a simulated rig (through the
    ``labrig.simulators`` entry point); a simulator port that cannot be bound is an
    :class:`InputFileError` naming the rig file's field (exit 2)."""
    return simulator().start(spec, seed)


__all__ = [
    "DEFAULT_RIG_NAME",
    "DEFAULT_RIG_YAML",
    "ENTRY_POINT_GROUP",
    "ROLES",
    "DeviceError",
    "RigSpec",
    "SimulatorSettings",
    "driver_names",
    "get_driver",
    "load_rig",
    "open_rig",
    "start_simulators",
]
