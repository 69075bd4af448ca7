"""The virtual bench as the ``labrig.simulators`` entry point (pyproject.toml): the schema of a
rig file's ``bench`` section, light to import (reading and checking a rig file needs only that),
and how to start the bench and its protocol servers for a simulated rig, which imports the
servers (and pymodbus) only then."""

from __future__ import annotations

from typing import Any

from labrig.drivers.sim.bench import BenchConfig

from labrig.rig.instruments import SimulatorInfo


def start_for_rig(spec: Any, seed: int | None) -> Any:
    """:func:`labrig.drivers.sim.serve.start_for_rig` (imported on first use)."""
    from labrig.drivers.sim.serve import start_for_rig as start

    return start(spec, seed)


SIMULATOR = SimulatorInfo(name="bench", config=BenchConfig, start=start_for_rig)
