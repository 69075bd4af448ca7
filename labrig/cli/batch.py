"""``labrig batch fit|diagnose|report RUN_FILES_OR_GLOBS... --out DIR``: the one-by-one analysis
commands over many run files, on Dask or serially (:func:`labrig.fleet.batch.run_batch`;
docs/fleet.md).

Exit codes: 0 every run succeeded; 4 some runs failed (each is a row of the table with its
error); 2 bad input (no run file matches, an unusable ``--out``, an unreachable scheduler, a
worker with another labrig); 130 interrupted; 1 unexpected.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape

from labrig.cli.common import (
    PEERS,
    PEERS_OPTION,
    Memory,
    Method,
    StructuralEffect,
    choice,
    flag,
    friendly,
    json_option,
    one_of,
    out_dir_option,
    peer_list,
    plural,
)
from labrig.cli.diagnose import ALSO_OPTION, MAINS_HZ_OPTION, MAX_EFFECTS_OPTION
from labrig.cli.typer_app import LabrigTyper, nonempty_paths

batch_app = LabrigTyper(
    help="Analyse many run files at once (one task per file) on a Dask cluster or serially; "
    "one table, per-run outputs and a fleet report (docs/fleet.md).",
    no_args_is_help=True,
)

FILES = typer.Argument(
    ...,
    help="Run files, globs (quote them: 'runs/**/*.h5') or folders.",
    callback=nonempty_paths,
)
OUT = out_dir_option("the table, the fleet report and per-run outputs", required=True)
SCHEDULER = typer.Option(
    None, "--scheduler", help="Address of a running Dask scheduler (tcp://HOST:PORT)."
)
WORKERS = typer.Option(
    None, "--workers", min=1, help="Worker processes of the local cluster (default: the cores)."
)
SERIAL = flag(False, "--serial", help="Analyse the runs one after another in this process.")
JSON = json_option("a summary of the batch")
FORCE = flag(False, "--force", help="Analyse every run again (no skip of unchanged runs).")
METHOD = typer.Option(
    Method.GLOBAL,
    "--method",
    parser=choice(Method, "a fit method"),
    metavar="METHOD",
    help=f"Fit method: {one_of(Method)}.",
)
MEMORY = typer.Option(
    Memory.RETURN_POINT,
    "--memory",
    parser=choice(Memory, "a memory rule"),
    metavar="RULE",
    help=f"The hysteresis operator's memory: {one_of(Memory)}.",
)
HELDOUT = flag(True, "--heldout/--no-heldout", help="Leave-one-entry-out NRMSE of the fit.")


def where_to_run(scheduler: str | None, workers: int | None, serial: bool, err: Console):
    """The :class:`~labrig.fleet.schedule.Where` of the options (notes on ``err``)."""
    from labrig.fleet.schedule import ClusterError, Where, dask_available

    if sum(x is not None and x is not False for x in (scheduler, workers, serial or None)) > 1:
        raise ClusterError("give one of --scheduler, --workers and --serial")
    if serial:
        return Where("serial")
    if not dask_available():
        if scheduler:
            raise ClusterError(
                "--scheduler needs Dask: pip install 'labrig[fleet]' (dask[distributed])"
            )
        err.print(
            "[yellow]note:[/] "
            + escape(
                "Dask is not installed (pip install 'labrig[fleet]'): the runs are analysed "
                "one after another in this process"
            )
        )
        return Where("serial")
    if scheduler:
        return Where("address", address=scheduler)
    return Where("local", workers=workers or os.cpu_count() or 1)


def batch_command(
    command: str,
    run_files: list[str],
    out: Path,
    scheduler: str | None,
    workers: int | None,
    serial: bool,
    as_json: bool,
    force: bool,
    **options,
) -> int:
    """Run the batch and print its summary; returns the exit code."""
    from labrig.fleet.batch import run_batch
    from labrig.fleet.tasks import TaskOptions

    err = Console(stderr=True)
    where = where_to_run(scheduler, workers, serial, err)
    outcome = run_batch(
        command, run_files, out, where, TaskOptions(**options), force=force, console=err
    )
    s = outcome.summary()
    if as_json:
        typer.echo(json.dumps(s, indent=2))
    else:
        con = Console()
        con.print(
            f"{plural(s['runs'], 'run')}: {s['succeeded']} succeeded, {len(s['failed'])} failed, "
            f"{s['skipped']} skipped (unchanged), {len(s['flagged'])} flagged; "
            f"{s['scheduler']} on {plural(s['workers'], 'worker')}, {s['wall_s']:.1f} s"
        )
        for f in s["failed"]:
            con.print(f"[red]failed[/] {escape(f['run_file'])}: {escape(f['error'])}")
        con.print(f"wrote {escape(s['table'])} and {escape(s['report'])}")
    return outcome.exit_code


@batch_app.command("fit")
@friendly
def fit(
    run_files: list[str] = FILES,
    out: Path = OUT,
    scheduler: str | None = SCHEDULER,
    workers: int | None = WORKERS,
    serial: bool = SERIAL,
    as_json: bool = JSON,
    force: bool = FORCE,
    method: Method = METHOD,
    memory: Memory = MEMORY,
    heldout: bool = HELDOUT,
) -> None:
    """`labrig fit` on every run file: parameters with uncertainties and NRMSE in one table."""
    opts = {"method": method.value, "memory": memory.value, "heldout": heldout}
    code = batch_command("fit", run_files, out, scheduler, workers, serial, as_json, force, **opts)
    raise typer.Exit(code)


@batch_app.command("diagnose")
@friendly
def diagnose(
    run_files: list[str] = FILES,
    out: Path = OUT,
    scheduler: str | None = SCHEDULER,
    workers: int | None = WORKERS,
    serial: bool = SERIAL,
    as_json: bool = JSON,
    force: bool = FORCE,
    also: list[StructuralEffect] = ALSO_OPTION,
    max_effects: int = MAX_EFFECTS_OPTION,
    mains_hz: float | None = MAINS_HZ_OPTION,
) -> None:
    """`labrig fit` and `labrig diagnose` on every run file: parameters, effects, verdicts."""
    opts = {
        "also": tuple(dict.fromkeys(a.value for a in also)),
        "max_effects": max_effects,
        "mains_hz": mains_hz,
    }
    code = batch_command(
        "diagnose", run_files, out, scheduler, workers, serial, as_json, force, **opts
    )
    raise typer.Exit(code)


@batch_app.command("report")
@friendly
def report(
    run_files: list[str] = FILES,
    out: Path = OUT,
    scheduler: str | None = SCHEDULER,
    workers: int | None = WORKERS,
    serial: bool = SERIAL,
    as_json: bool = JSON,
    force: bool = FORCE,
    method: Method = METHOD,
    heldout: bool = HELDOUT,
    peers: str = PEERS_OPTION,
) -> None:
    """`labrig fit` and `labrig report` on every run file: parameters, baselines, HTML pages."""
    chosen = peer_list(peers)
    every = set(chosen) == set(PEERS)  # the default: None, the options of earlier batches
    opts = {"method": method.value, "heldout": heldout, "peers": None if every else chosen}
    code = batch_command(
        "report", run_files, out, scheduler, workers, serial, as_json, force, **opts
    )
    raise typer.Exit(code)
