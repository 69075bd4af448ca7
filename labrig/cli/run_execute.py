"""``labrig run``: preflight, then execute with a progress bar; returns the exit code.

Exit codes: 0 complete; 2 bad input (protocol, rig file, ``--out``, not enough disk space for
the run file), found before anything is energised; 3 a device fault or a full disk during the
run; 128 + signal number when stopped by a signal (SIGINT 130, SIGTERM 143, SIGHUP 129,
SIGQUIT 131); 1 anything unexpected. Every path that energised the output ramped it to 0 V.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from labrig.cli.common import echo_error, plural, to_devnull
from labrig.core.interrupts import STOP_SIGNALS, Interrupted, exit_code_for, interrupt_once
from labrig.core.metadata import RunMetadata
from labrig.protocol.plan import Plan
from labrig.runner.execute import (
    RunOutcome,
    check_resume_of,
    check_run_output,
    default_out_path,
    execute,
    preflight,
)
from labrig.store.resume import ResumePlan


@dataclass
class RunExtras:
    """What ``labrig run`` does besides the run itself: metadata, a resume, the live view."""

    metadata: RunMetadata | None = None
    resume: Path | None = None
    live: bool = False
    live_port: int = 0
    params: Path | None = None
    #: after a run that ended by itself, serve it this long (s); None: until a stop signal
    live_hold: float | None = None


def run_with_progress(
    protocol: Path,
    rig: Path | None,
    out: Path | None,
    seed: int | None,
    realtime: bool,
    overwrite: bool,
    extras: RunExtras | None = None,
) -> int:
    """Preflight and execute ``protocol`` with a progress bar (and the live view of
    ``extras``); the exit code (module docstring)."""
    console = Console(stderr=True)
    extras = extras or RunExtras()
    plan, rig_path = preflight(protocol, rig)
    if extras.resume is not None:
        if out is not None or overwrite:
            echo_error("error: --resume continues FILE in place: give no --out or --overwrite")
            return 2
        if not extras.resume.is_file():
            what = "a folder" if extras.resume.is_dir() else "not a regular file"
            why = f"{what}, not a run file" if extras.resume.exists() else "run file not found"
            echo_error(f"error: --resume {extras.resume}: {why}")
            return 2
    resume = None
    named = out is not None
    if extras.resume is None:
        out = out or default_out_path(plan)
        check_run_output(plan, rig_path, out, overwrite, [extras.params])
    else:  # before anything is shown or energised: damage, another protocol, being written
        resume = check_resume_of(plan, extras.resume)
    where = escape(f"rig {rig_path}") if rig_path else "the simulated rig"
    _say(
        console,
        f"[bold]{escape(plan.name)}[/]: {plural(len(plan.steps), 'entry')}, "
        f"{plan.total_duration_s:.1f} s of protocol time on {where}",
    )
    live = _start_live(console, extras)
    # SIGINT, SIGTERM, SIGHUP and SIGQUIT stop the run once (ramp to 0 V, file closed);
    # repeats, and a first signal after the run ended, are ignored until the outcome is printed
    with interrupt_once() as guard:
        outcome = None
        try:
            outcome = _execute_with_bar(
                console,
                plan,
                rig_path,
                out,
                seed,
                realtime,
                overwrite,
                extras,
                live,
                resume,
                default_name=not named,
            )
        except Interrupted as e:  # before the run file existed: nothing energised or written
            _say(console, f"[red]stopped before the run began[/]: {escape(e.reason)}")
            return e.exit_code
        finally:
            if live is not None:
                with guard.defer():
                    tell_if_live_stopped(console, live, "")
                    live.end(outcome.path if outcome is not None else None)
                    if outcome is None:  # no run to show
                        live.close()
        with guard.defer():
            _report(console, outcome)
    if live is not None:
        serve_finished_run(console, live, outcome, extras.live_hold)
    return outcome.exit_code


def _start_live(console: Console, extras: RunExtras):
    """The live view's server (``--live``), started before the run: its address is printed
    before anything is energised; a bad ``--params`` or a port in use is bad input (exit 2)."""
    if not extras.live:
        return None
    from labrig.live.launch import LiveProcess

    live = LiveProcess(extras.live_port, extras.params)
    _say(console, f"live view: {live.url}")
    return live


def tell_if_live_stopped(console: Console, live, then: str = "; the run goes on") -> None:
    """Say once, on the terminal, that the live view stopped by itself and why
    (:meth:`labrig.live.launch.LiveProcess.stopped`), followed by ``then``; the run is not
    affected (its data come first)."""
    why = live.stopped()
    if why:
        _say(console, f"[yellow]live view stopped[/]: {escape(why)}{then}")


def serve_finished_run(console: Console, live, outcome: RunOutcome, hold: float | None) -> None:
    """After the run: a run that ended by itself (complete, or failed on a device fault or a
    full disk) stays on view, its file complete and closed, until a stop signal (Ctrl-C) or
    ``hold`` seconds; the exit code stays the run's. A run stopped by a signal is not held:
    the view lingers only until an open page has the final state (at most
    ``labrig.live.server.LINGER_S``)."""
    signalled = outcome.exit_code in {exit_code_for(s) for s in STOP_SIGNALS}
    if signalled or hold == 0 or not live.alive:
        live.close()
        return
    until = "until Ctrl-C" if hold is None else f"for {hold:g} s (Ctrl-C to stop sooner)"
    deadline = None if hold is None else time.monotonic() + hold
    with interrupt_once() as guard:
        try:
            # said once the guard is on: a Ctrl-C the moment it is read ends the hold, exit
            # code the run's (before, it met the default handler: exit 130)
            _say(console, f"live view: serving the finished run at {live.url} {until}")
            while live.alive and (deadline is None or time.monotonic() < deadline):
                time.sleep(0.2)
        except Interrupted:
            pass
        finally:
            with guard.defer():
                live.close()
                _say(console, "live view: closed")


def _report(console: Console, outcome: RunOutcome) -> None:
    """The outcome in one line and the run file's path (the last line of stdout)."""
    if outcome.status == "complete":
        done = plural(len(outcome.entries), "entry")
        _say(console, f"run complete: {done} (seed {outcome.seed})")
    else:
        _say(console, f"[red]run {outcome.status}[/]: {escape(outcome.reason)}")
    try:
        typer.echo(str(outcome.path))
    except OSError:  # the terminal closed (SIGHUP), a full or closed output
        to_devnull(sys.stdout)


def _say(console: Console, text: str) -> None:
    """Print to the terminal if it can be written: after SIGHUP (the terminal gone) or on a
    full or closed standard error, what cannot be said is dropped (:func:`to_devnull`); the
    run, its file and its exit code do not depend on it."""
    try:
        console.print(text)
    except OSError:
        to_devnull(console.file)


def _execute_with_bar(
    console: Console,
    plan: Plan,
    rig_path: Path | None,
    out: Path | None,
    seed: int | None,
    realtime: bool,
    overwrite: bool,
    extras: RunExtras,
    live,
    resume: ResumePlan | None = None,
    default_name: bool = False,
) -> RunOutcome:
    """``execute`` under a progress bar (``default_name``: ``out`` was chosen, not given); a
    terminal that disappears during the run (the bar's last redraw fails), or a stop signal
    while the bar closes, does not lose the outcome."""
    done: list = []
    try:
        with Progress(
            TextColumn("[bold]{task.fields[step]}[/] {task.description}"),
            BarColumn(),
            TextColumn("{task.percentage:>5.1f} %"),
            TimeRemainingColumn(),
            console=console,
            transient=False,
        ) as bar:
            task = bar.add_task("", total=plan.total_duration_s, step="")
            started: list[float] = []

            def progress(k: int, n: int, name: str, frac: float, left: float) -> None:
                if live is not None:
                    tell_if_live_stopped(console, live)
                if not started:  # a resume plays only the entries it has left
                    started.append(left)
                    bar.update(task, total=left)
                bar.update(
                    task,
                    completed=started[0] - left,
                    step=f"step {k + 1}/{n}",
                    description=escape(name),
                )

            done.append(
                execute(
                    plan, rig_path, out, seed, realtime, progress, overwrite,
                    metadata=extras.metadata, resume=resume,
                    on_file=live.follow if live is not None else None, inputs=[extras.params],
                    default_name=default_name,
                )
            )  # fmt: skip
    except OSError:  # the bar's last drawing (stderr gone or full): the run is recorded
        if not done:
            raise
        to_devnull(console.file)
    except Interrupted:
        if not done:  # the run had not begun (see run_with_progress)
            raise
        # the run has ended and is recorded: a signal while the bar closes changes nothing
    return done[0]
