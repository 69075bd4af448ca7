"""``labrig check`` and ``labrig run``: a protocol against the rig's limits, then on the rig
(:mod:`labrig.runner`; the progress bar and exit code of a run: :mod:`labrig.cli_run`)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import RIG_OPTION_HELP, flag, friendly, plural


@friendly
def check(
    protocol: Path = typer.Argument(..., help="Protocol file (YAML)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_OPTION_HELP),
) -> None:
    """Validate a protocol and preflight it against the rig's limits; touches no hardware."""
    from rich.console import Console

    from labrig.protocol.check import format_plan
    from labrig.runner import preflight

    plan, _ = preflight(protocol, rig)
    Console().print(format_plan(plan))
    typer.echo(f"{protocol}: OK, {plural(len(plan.steps), 'entry')}, {plan.total_duration_s:.1f} s")


@friendly
def run(
    protocol: Path = typer.Argument(..., help="Protocol file (YAML)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_OPTION_HELP),
    out: Path | None = typer.Option(
        None, "--out", help="Run file to write (default: runs/NAME-DATE-TIME.h5)."
    ),
    seed: int | None = typer.Option(None, "--seed", help="Random seed of the simulated rig."),
    realtime: bool = flag(False, "--realtime", help="Pace a simulated rig to the clock."),
    overwrite: bool = flag(False, "--overwrite", help="Replace an existing --out file."),
) -> None:
    """Preflight a protocol, run it on the rig, and log every step to an HDF5 run file."""
    from labrig.cli_run import run_with_progress

    code = run_with_progress(protocol, rig, out, seed, realtime, overwrite)
    raise typer.Exit(code)
