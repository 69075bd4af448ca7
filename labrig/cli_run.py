"""``labrig run``: preflight, then execute with a progress bar; returns the exit code."""

from __future__ import annotations

import signal
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from labrig.runner import execute, preflight


def _sigterm_as_interrupt(signum, frame):  # pragma: no cover - exercised by subprocess tests
    raise KeyboardInterrupt


def run_with_progress(
    protocol: Path,
    rig: Path | None,
    out: Path | None,
    seed: int | None,
    realtime: bool,
    overwrite: bool,
) -> int:
    console = Console(stderr=True)
    plan, rig_path = preflight(protocol, rig)
    if out is not None and out.exists() and not overwrite:
        typer.echo(f"error: {out} exists; choose another --out or pass --overwrite", err=True)
        return 2
    console.print(
        f"[bold]{plan.name}[/]: {len(plan.steps)} entries, {plan.total_duration_s:.1f} s of "
        f"protocol time on {'rig ' + str(rig_path) if rig_path else 'the simulated rig'}"
    )
    signal.signal(signal.SIGTERM, _sigterm_as_interrupt)
    with Progress(
        TextColumn("[bold]{task.fields[step]}[/] {task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>5.1f} %"),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    ) as bar:
        task = bar.add_task("", total=plan.total_duration_s, step="")

        def progress(k: int, n: int, name: str, frac: float, left: float) -> None:
            bar.update(
                task,
                completed=plan.total_duration_s - left,
                step=f"step {k + 1}/{n}",
                description=name,
            )

        outcome = execute(plan, rig_path, out, seed, realtime, progress, overwrite)
    if outcome.status == "complete":
        console.print(f"run complete: {len(outcome.entries)} entries (seed {outcome.seed})")
    else:
        console.print(f"[red]run {outcome.status}[/]: {outcome.reason}")
    typer.echo(str(outcome.path))
    return outcome.exit_code
