"""``labrig validate TRAIN... --on TEST...``: every model identified on the training records,
scored on the test records by one rule (:func:`labrig.commands.validate.validate_runs`).

Prints the whole-record and second-half NRMSE (%) per model and the noise floor (a table, or
JSON with ``--json``); ``--out FILE`` writes the HTML page.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from labrig.cli.common import (
    OFFSET_OPTION,
    OVERWRITE_OPTION,
    WARMUP_OPTION,
    Method,
    choice,
    flag,
    friendly,
    json_option,
    json_text,
    one_of,
    out_file_option,
)


@friendly
def validate(
    train: list[Path] = typer.Argument(
        ...,
        help="Run files (HDF5) to identify every model on (the training records); with "
        "--leave-one-out, every record, each predicted in turn from the others.",
    ),
    on: list[Path] | None = typer.Option(
        None,
        "--on",
        metavar="TEST",
        help="Run file to predict and score (repeatable; never one of the training files).",
    ),
    leave_one_out: bool = flag(
        False,
        "--leave-one-out",
        help="Each of the files in turn predicted by every model identified on the others "
        "(at least 3 files; not with --on, --out, --overwrite, --effects-from).",
    ),
    out: Path | None = out_file_option("the HTML page (every prediction of every test record)"),
    as_json: bool = json_option("the scores"),
    effects_from: Path | None = typer.Option(
        None,
        "--effects-from",
        metavar="DIAGNOSIS",
        help="A diagnosis.json of the training data: its accepted effects are added to our model "
        "(refitted on the training records).",
    ),
    diagnose: bool = flag(
        False, "--diagnose", help="Diagnose the training records now and add what it accepts."
    ),
    method: Method = typer.Option(
        Method.GLOBAL,
        "--method",
        parser=choice(Method, "a fit method"),
        metavar="METHOD",
        help=f"Fit method of our model: {one_of(Method)}.",
    ),
    warmup_s: float | None = WARMUP_OPTION,
    offset: bool | None = OFFSET_OPTION,
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Identify every model on TRAIN, predict TEST: one scoring rule for all."""
    from labrig.commands.progress import RichUI
    from labrig.commands.validate import validate_runs

    ui = RichUI()
    if leave_one_out:
        _leave_one_out(
            train, on, out, effects_from, overwrite, diagnose, method, warmup_s, offset, as_json
        )
        return
    if not on:
        raise typer.BadParameter("give the test files (--on TEST) or --leave-one-out")
    v = validate_runs(
        train,
        on,
        effects_from=effects_from,
        run_diagnosis=diagnose,
        method=method.value,
        warmup_s=warmup_s,
        offset=offset,
        ui=ui,
        out=out,
        overwrite=overwrite,
    )
    for n in (n for n in v.notes if not n.startswith("training: ")):  # announced already
        ui.err.print(f"[yellow]note:[/] {escape(n)}")
    if out is not None:
        ui.err.print(f"wrote {escape(str(out))} ({len(v.page) / 1e6:.1f} MB)")
    if as_json:
        typer.echo(json_text(v.to_json()))
    else:
        print_scores(v.to_json())


def _leave_one_out(
    files: list[Path],
    on: list[Path] | None,
    out: Path | None,
    effects_from: Path | None,
    overwrite: bool,
    diagnose: bool,
    method: Method,
    warmup_s: float | None,
    offset: bool | None,
    as_json: bool,
) -> None:
    """``--leave-one-out``: one validation per held-out file, the mean per model."""
    from labrig.commands.progress import RichUI
    from labrig.commands.validate import validate_leave_one_out

    for given, name in (
        (on, "--on"),
        (out, "--out"),
        (effects_from, "--effects-from"),
        (overwrite, "--overwrite"),
    ):
        if given:
            why = (
                "nothing is written" if name in ("--out", "--overwrite") else "every file is tested"
            )
            raise typer.BadParameter(f"--leave-one-out takes no {name}: {why}")
    ui = RichUI()
    loo = validate_leave_one_out(
        files,
        run_diagnosis=diagnose,
        method=method.value,
        warmup_s=warmup_s,
        offset=offset,
        ui=ui,
    )
    for v in loo.folds:
        for n in (n for n in v.notes if not n.startswith("training: ")):
            ui.err.print(f"[yellow]note ({escape(v.test[0].name)}):[/] {escape(n)}")
    doc = loo.to_json()
    if as_json:
        typer.echo(json_text(doc))
    else:
        print_leave_one_out(doc)


def print_leave_one_out(doc: dict) -> None:
    """Whole-record NRMSE (%) per model and held-out file, their mean, and the noise floor."""
    from pathlib import PurePath

    from rich.console import Console
    from rich.table import Table

    from labrig.commands.validate import fmt_pct

    files = list(doc["leave_one_out"])
    stems = [PurePath(f).stem for f in files]
    heads = stems if len(set(stems)) == len(stems) else files  # two x.h5 in different folders
    t = Table(title="NRMSE (%) of each record predicted by models identified on the others")
    t.add_column("model")
    for h in heads:
        t.add_column(escape(h), justify="right")
    t.add_column("mean (second half)", justify="right")
    for m in doc["models"].values():
        t.add_row(
            escape(m["label"]),
            *(fmt_pct(m["per_file"].get(f)) for f in files),
            f"{fmt_pct(m['whole_nrmse_pct'])} ({fmt_pct(m['second_half_nrmse_pct'])})",
        )
    t.add_row("noise floor", *("" for _ in files), fmt_pct(doc["noise_floor_pct"]))
    Console().print(t)


def print_scores(doc: dict) -> None:
    """Whole-record and second-half NRMSE (%) per model, and the noise floor, as a table."""
    from rich.console import Console
    from rich.table import Table

    from labrig.commands.validate import fmt_pct

    t = Table(title="NRMSE (%) on the test records, every model identified on the training ones")
    t.add_column("model")
    t.add_column("whole record", justify="right")
    t.add_column("second half", justify="right")
    t.add_column("note")
    for m in doc["models"].values():
        t.add_row(
            escape(m["label"]),
            fmt_pct(m["whole_nrmse_pct"]),
            fmt_pct(m["second_half_nrmse_pct"]),
            escape(m["note"] or ""),
        )
    floor = fmt_pct(doc["noise_floor_pct"])
    t.add_row("noise floor", floor, floor, escape(doc["noise_floor_source"]))
    Console().print(t)
