"""``labrig sim``: the simulated bench's instrument simulators, standalone."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    friendly,
    json_option,
    json_text,
    out_dir_option,
    plural,
)
from labrig.cli.typer_app import LabrigTyper
from labrig.core.seeds import MAX_SEED

sim_app = LabrigTyper(
    help="The simulated bench: run its instrument simulators standalone; simulate a fleet."
)


@sim_app.command("serve")
@friendly
def serve(
    rig: Path | None = typer.Option(
        None, "--rig", metavar="FILE", help="Rig file (default: built-in sim rig)."
    ),
) -> None:
    """Start the simulated amplifier (GCS) and conditioner (Modbus) servers; Ctrl-C stops."""
    from labrig.drivers.sim.serve import serve as serve_rig

    serve_rig(rig)


@sim_app.command("fleet")
@friendly
def fleet(
    n: int = typer.Argument(..., min=1, help="Number of actuators (at most 100 000)."),
    out: Path = out_dir_option("the run files and truth.json", required=True),
    seed: int = typer.Option(
        0,
        "--seed",
        min=0,
        max=MAX_SEED,
        help="Random seed of the fleet (spread, defects, runs; 0 to 2^63-1).",
    ),
    defects: float = typer.Option(
        0.05, "--defects", min=0.0, max=1.0, help="Fraction of defective actuators (0-1)."
    ),
    protocol: Path = typer.Option(
        Path("paper"),
        "--protocol",
        metavar="FILE",
        help="Protocol each actuator runs: a file or a shipped example's name.",
    ),
    as_json: bool = json_option("the files written"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Simulate N actuators with a manufacturing spread and a few defects (docs/fleet.md)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from labrig.fleet.simfleet import MAX_FLEET, write_fleet

    if n > MAX_FLEET:
        raise typer.BadParameter(f"{n}: at most {MAX_FLEET:,} actuators", param_hint="N")
    err = Console(stderr=True)
    bar = Progress(
        "simulating", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=err
    )
    task = bar.add_task("fleet", total=n)
    try:  # the bar shows once the options are checked (a refusal is one line, no bar)
        paths = write_fleet(
            n,
            out,
            protocol,
            seed=seed,
            defect_fraction=defects,
            overwrite=overwrite,
            progress=lambda _a: bar.advance(task),
            checked=bar.start,
        )
    finally:
        if bar.live.is_started:
            bar.stop()
    if as_json:
        typer.echo(json_text({"files": [str(p) for p in paths], "truth": str(out / "truth.json")}))
    else:
        typer.echo(f"{plural(len(paths), 'run file')} and truth.json in {out}")
