"""``labrig sim``: the simulated bench's instrument simulators, standalone."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import friendly

sim_app = typer.Typer(help="The simulated bench: run its instrument simulators standalone.")


@sim_app.command("serve")
@friendly
def serve(
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (default: built-in sim rig)."),
) -> None:
    """Start the simulated amplifier (GCS) and conditioner (Modbus) servers; Ctrl-C stops."""
    from labrig.drivers.sim.serve import serve as serve_rig

    serve_rig(rig)
