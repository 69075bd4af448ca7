"""``labrig sim``: the simulated bench's instrument simulators, standalone."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import flag, friendly

sim_app = typer.Typer(
    help="The simulated bench: run its instrument simulators standalone; simulate a fleet."
)


@sim_app.command("serve")
@friendly
def serve(
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (default: built-in sim rig)."),
) -> None:
    """Start the simulated amplifier (GCS) and conditioner (Modbus) servers; Ctrl-C stops."""
    from labrig.drivers.sim.serve import serve as serve_rig

    serve_rig(rig)


@sim_app.command("fleet")
@friendly
def fleet(
    n: int = typer.Argument(..., min=1, help="Number of actuators."),
    out: Path = typer.Option(..., "--out", help="Folder for the run files and truth.json."),
    seed: int = typer.Option(0, "--seed", help="Random seed of the fleet (spread, defects, runs)."),
    defects: float = typer.Option(
        0.05, "--defects", min=0.0, max=1.0, help="Fraction of defective actuators (0-1)."
    ),
    protocol: Path = typer.Option(
        Path("experiments/paper.yaml"), "--protocol", help="Protocol each actuator runs."
    ),
    overwrite: bool = flag(False, "--overwrite", help="Replace the files of an earlier fleet."),
) -> None:
    """Simulate N actuators with a manufacturing spread and a few defects (docs/fleet.md)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from labrig.fleet.simfleet import write_fleet

    err = Console(stderr=True)
    with Progress(
        "simulating", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=err
    ) as bar:
        task = bar.add_task("fleet", total=n)
        paths = write_fleet(
            n,
            out,
            protocol,
            seed=seed,
            defect_fraction=defects,
            overwrite=overwrite,
            progress=lambda _a: bar.advance(task),
        )
    typer.echo(f"{len(paths)} run files and truth.json in {out}")
