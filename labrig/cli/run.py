"""``labrig run``: a protocol on the rig
(:mod:`labrig.runner.execute`; the progress bar, the live view and the exit code of a run:
:mod:`labrig.cli.run_execute`)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import RIG_OPTION_HELP, flag, friendly
from labrig.core.seeds import MAX_SEED

META_HELP = (
    "KEY=VALUE recorded with the run (/run/metadata; repeatable), e.g. actuator_model=P-888.51, "
    "actuator_serial=123 (run: wins over the protocol's metadata:)."
)
OPERATOR_HELP = "Who runs it (NXuser name; same as --meta operator=NAME)."
SAMPLE_HELP = "The sample (actuator) id, e.g. 'P-888 #3' (NXsample name; --meta sample=ID)."
#: the longest ``--live-hold`` (s): a day; longer, or until Ctrl-C, is the option left out
LIVE_HOLD_MAX_S = 86400.0


def checked_meta(values: list[str]) -> list[str]:
    """``--meta`` values that are KEY=VALUE with a valid key (a usage error otherwise)."""
    from labrig.core.metadata import MetadataError, parse_assignment

    for v in values:
        try:
            parse_assignment(v)
        except MetadataError as e:
            raise typer.BadParameter(str(e)) from None
    return values


def checked_live_hold(value: float | None) -> float | None:
    """``--live-hold``: seconds from 0 to :data:`LIVE_HOLD_MAX_S`; anything else (negative,
    ``nan``, ``inf``, longer) is a usage error naming the option and the range."""
    import math

    if value is None or (math.isfinite(value) and 0 <= value <= LIVE_HOLD_MAX_S):
        return value
    raise typer.BadParameter(
        f"{value:g}: must be a number of seconds from 0 to {LIVE_HOLD_MAX_S:g} (a day); leave "
        "--live-hold out to serve the finished run until Ctrl-C"
    )


def meta_options() -> tuple:
    """The ``--meta``, ``--operator`` and ``--sample`` options (run and import share them)."""
    return (
        typer.Option([], "--meta", help=META_HELP, callback=checked_meta, metavar="KEY=VALUE"),
        typer.Option(None, "--operator", help=OPERATOR_HELP, metavar="NAME"),
        typer.Option(None, "--sample", help=SAMPLE_HELP, metavar="ID"),
    )


META_OPTION, OPERATOR_OPTION, SAMPLE_OPTION = meta_options()


def metadata_of(meta: list[str], operator: str | None, sample: str | None):
    """The options' metadata (:func:`labrig.core.metadata.from_options`); a bad value is a usage
    error naming the option."""
    from labrig.core.metadata import MetadataError, from_options

    try:
        return from_options(meta, operator, sample)
    except MetadataError as e:
        raise typer.BadParameter(str(e), param_hint="--meta/--operator/--sample") from None


@friendly
def run(
    protocol: Path = typer.Argument(
        ..., help="Protocol file (YAML), or a shipped example's name (paper, sweep...)."
    ),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_OPTION_HELP),
    out: Path | None = typer.Option(
        None, "--out", help="Run file to write (default: runs/NAME-DATE-TIME.h5).", metavar="FILE"
    ),
    seed: int | None = typer.Option(
        None, "--seed", min=0, max=MAX_SEED, help="Random seed of the simulated rig (0 to 2^63-1)."
    ),
    realtime: bool | None = flag(
        None,
        "--realtime/--no-realtime",
        help="Pace a simulated rig to the clock (default: with --live, yes; without, no).",
    ),
    overwrite: bool = flag(False, "--overwrite", help="Replace an existing --out file."),
    meta: list[str] = META_OPTION,
    operator: str | None = OPERATOR_OPTION,
    sample: str | None = SAMPLE_OPTION,
    resume: Path | None = typer.Option(
        None,
        "--resume",
        help="Continue this aborted or interrupted run file with the entries it lacks "
        "(same protocol; written beside it, then renamed over it).",
        metavar="FILE",
    ),
    live: bool = flag(
        False, "--live", help="Serve a live view of the run on 127.0.0.1 (prints its address)."
    ),
    live_port: int | None = typer.Option(
        None,
        "--live-port",
        min=0,
        max=65535,
        help="Port of the live view (implies --live; default: a free one).",
    ),
    params: Path | None = typer.Option(
        None, "--params", help="Live view: draw this model's prediction (labrig fit --out file)."
    ),
    live_hold: float | None = typer.Option(
        None,
        "--live-hold",
        callback=checked_live_hold,
        help="After a run that ended by itself, serve the finished run this long, 0 to "
        f"{LIVE_HOLD_MAX_S:g} s (implies --live; default: until Ctrl-C; 0: stop once an "
        "open page has it).",
        metavar="SECONDS",
    ),
) -> None:
    """Preflight a protocol, run it on the rig, and log every step to an HDF5 run file."""
    from labrig.cli.run_execute import RunExtras, run_with_progress

    live = live or live_port is not None or live_hold is not None
    if params is not None and not live:
        raise typer.BadParameter("draws on the live view: give --live too", param_hint="--params")
    if realtime is None:  # a live view is watched: the simulated rig runs at the clock's pace
        realtime = live
    extras = RunExtras(
        metadata=metadata_of(meta, operator, sample),
        resume=resume,
        live=live,
        live_port=live_port or 0,
        params=params,
        live_hold=live_hold,
    )
    code = run_with_progress(protocol, rig, out, seed, realtime, overwrite, extras)
    raise typer.Exit(code)
