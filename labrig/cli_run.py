"""``labrig run``: preflight, then execute with a progress bar; returns the exit code."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from labrig.runner import execute, interrupt_once, preflight


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
    if out is not None and out.is_dir():
        example = out / "run.h5"
        typer.echo(
            f"error: --out {out} is a directory; give a file name such as {example}", err=True
        )
        return 2
    if out is not None and out.exists() and not overwrite:
        typer.echo(f"error: {out} exists; choose another --out or pass --overwrite", err=True)
        return 2
    where = escape(f"rig {rig_path}") if rig_path else "the simulated rig"
    console.print(
        f"[bold]{escape(plan.name)}[/]: {len(plan.steps)} entries, "
        f"{plan.total_duration_s:.1f} s of protocol time on {where}"
    )
    # Ctrl-C and SIGTERM stop the run once (0 V, file closed); repeats are ignored until the
    # outcome is printed
    with interrupt_once():
        outcome = _execute_with_bar(console, plan, rig_path, out, seed, realtime, overwrite)
        if outcome.status == "complete":
            console.print(f"run complete: {len(outcome.entries)} entries (seed {outcome.seed})")
        else:
            console.print(f"[red]run {outcome.status}[/]: {escape(outcome.reason)}")
        typer.echo(str(outcome.path))
    return outcome.exit_code


def _execute_with_bar(console, plan, rig_path, out, seed, realtime, overwrite):
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
                description=escape(name),
            )

        return execute(plan, rig_path, out, seed, realtime, progress, overwrite)
