"""``labrig diagnose RUN.h5 [--params params.json] [--out DIR] [--json] [--also NAME]...
[--max-effects N] [--mains-hz HZ]``: find what the model misses
(:func:`labrig.commands.diagnose.diagnose_run_file`; the method: docs/diagnose.md).

Exit codes: 0 done (whatever the verdict), 2 bad input (file, parameters), 64 a usage error,
1 unexpected failure. ``--json`` prints only the JSON contract on stdout (progress and messages
go to stderr).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from labrig.cli.common import (
    OVERWRITE_OPTION,
    StructuralEffect,
    choice,
    friendly,
    json_option,
    one_of,
    out_dir_option,
)

__all__ = [
    "ALSO_OPTION",
    "MAINS_HZ_OPTION",
    "MAX_EFFECTS_OPTION",
    "WORKERS_OPTION",
    "diagnose",
    "diagnose_command",
]

ALSO_OPTION = typer.Option(
    [],
    "--also",
    parser=choice(StructuralEffect, "a structural effect", "(the other effects are always tried)"),
    metavar="EFFECT",
    help=f"Also try this structural effect (repeatable): {one_of(StructuralEffect)}; "
    "remanence is not a default candidate, viscoelastic_creep is one only where an entry is "
    "long and slow enough to identify it (docs/diagnose.md).",
)
MAX_EFFECTS_OPTION = typer.Option(
    2, "--max-effects", min=1, max=4, help="Add at most this many effects (1-4)."
)
WORKERS_OPTION = typer.Option(
    None,
    "--workers",
    min=1,
    max=256,
    metavar="COUNT",
    help="Processes for the held-out folds and the candidates of a round (default: the "
    "processors this process may use); the result does not depend on it.",
)
MAINS_HZ_OPTION = typer.Option(
    None,
    "--mains-hz",
    min=1.0,
    max=1000.0,
    metavar="HZ",
    help="Mains frequency for mains_pickup (default: the line the strain shows at 50 or 60 Hz).",
)


@friendly
def diagnose(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    params: Path | None = typer.Option(
        None,
        "--params",
        metavar="FILE",
        help="Start parameters (ModelParams JSON or `labrig fit` output).",
    ),
    out: Path | None = out_dir_option("diagnosis.json and diagnosis.html"),
    overwrite: bool = OVERWRITE_OPTION,
    as_json: bool = json_option("the diagnosis (the JSON contract of docs/diagnose.md)"),
    also: list[StructuralEffect] = ALSO_OPTION,
    max_effects: int = MAX_EFFECTS_OPTION,
    mains_hz: float | None = MAINS_HZ_OPTION,
    workers: int | None = WORKERS_OPTION,
) -> None:
    """Find what the model misses: residual evidence, candidate effects, held-out before/after."""
    names = tuple(dict.fromkeys(a.value for a in also))
    code = diagnose_command(
        run_file, params, out, as_json, names, max_effects, overwrite, mains_hz, workers
    )
    raise typer.Exit(code)


def diagnose_command(
    run_file: Path,
    params: Path | None,
    out_dir: Path | None,
    as_json: bool,
    also: tuple[str, ...] = (),
    max_effects: int = 2,
    overwrite: bool = False,
    mains_hz: float | None = None,
    workers: int | None = None,
) -> int:
    """Run the diagnosis of ``run_file`` and print / write it; returns the exit code.

    ``also``: structural effects to try beside the defaults; ``max_effects``: at most this
    many effects are added; ``mains_hz``: the mains frequency (Hz, default: detected). The
    files in ``out_dir`` are checked before the work and written beside their targets, then
    renamed into place (:func:`~labrig.commands.diagnose.diagnose_run_file`)."""
    from labrig.analysis.parallel import available_workers
    from labrig.commands.diagnose import diagnose_run_file

    err = Console(stderr=True)
    result = diagnose_run_file(
        run_file,
        params,
        also=also,
        max_effects=max_effects,
        mains_hz=mains_hz,
        out=out_dir,
        overwrite=overwrite,
        say=err.print,
        progress=StepClock(err),
        workers=available_workers() if workers is None else workers,
    )
    hint = result.hint()
    if hint:
        err.print(hint)
    if as_json:
        print(json.dumps(result.document, indent=2))
    else:
        print_diagnosis(result.document, Path(run_file).name)
    if result.written:
        err.print(f"wrote {' and '.join(str(p) for p in result.written)}")
    return 0


class StepClock:
    """The diagnosis' progress on stderr, each step with the time since the command began:
    ``[  12.3 s] round 1: ranking 9 candidates``."""

    def __init__(self, console: Console):
        self.console = console
        self.start = time.monotonic()

    def __call__(self, msg: str) -> None:
        elapsed = time.monotonic() - self.start
        self.console.print(f"[dim]\\[{elapsed:6.1f} s] {escape(msg)}[/dim]")


def print_diagnosis(doc: dict[str, Any], name: str) -> None:
    """The diagnosis as tables: NRMSE before and after, the effects added, the candidates, the
    verdict."""
    con = Console()
    if doc.get("headline"):
        con.print(f"[bold]{escape(doc['headline'])}[/bold]")
    t = Table(title=f"diagnose {name}")
    t.add_column("")
    t.add_column("NRMSE (%)", justify="right")
    t.add_column("held-out NRMSE (%)", justify="right")
    for k in ("before", "after"):
        t.add_row(k, f"{doc[k]['nrmse_pct']:.3g}", f"{doc[k]['heldout_nrmse_pct']:.3g}")
    con.print(t)
    if doc["effects_added"]:
        for e in doc["effects_added"]:
            con.print(f"[bold]added {e['effect']}[/bold]: {e['evidence']}")
    else:
        con.print("no effect added")
    c = Table(title="candidates")
    c.add_column("round", justify="right")
    c.add_column("effect")
    c.add_column("held-out (%)", justify="right")
    c.add_column("evidence")
    last = None
    for x in doc["candidates"]:
        h = x["heldout_nrmse_pct"]
        rnd = x.get("round")
        if last is not None and rnd != last:
            c.add_section()  # a rule between rounds
        last = rnd
        c.add_row(str(rnd or ""), x["effect"], "-" if h is None else f"{h:.3g}", x["evidence"])
    con.print(c)
    con.print(f"[bold]verdict[/bold]: {doc['verdict']}")
