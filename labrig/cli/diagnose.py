"""``labrig diagnose RUN.h5 [--params params.json] [--out DIR] [--json] [--also NAME]...
[--max-effects N]``: find what the model misses (:func:`labrig.analysis.diagnose.diagnose`;
the method: docs/diagnose.md).

Exit codes: 0 done (whatever the verdict), 2 bad input (file, parameters), 1 unexpected
failure. ``--json`` prints only the JSON contract on stdout (progress and messages go to
stderr).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from labrig.cli.common import StructuralEffect, choice, flag, friendly, one_of
from labrig.errors import InputFileError, InputIssue

__all__ = ["diagnose", "diagnose_command"]


@friendly
def diagnose(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    params: Path | None = typer.Option(
        None, "--params", help="Start parameters (ModelParams JSON or `labrig fit` output)."
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Directory for diagnosis.json and diagnosis.html."
    ),
    overwrite: bool = flag(
        False, "--overwrite", help="Replace diagnosis.json and diagnosis.html in --out."
    ),
    as_json: bool = flag(False, "--json", help="Print only the JSON on stdout."),
    also: list[StructuralEffect] = typer.Option(
        [],
        "--also",
        parser=choice(
            StructuralEffect, "a structural effect", "(the other effects are always tried)"
        ),
        metavar="<effect>",
        help=f"Also try this structural effect (repeatable): {one_of(StructuralEffect)} "
        "(not default candidates; docs/diagnose.md).",
    ),
    max_effects: int = typer.Option(
        2, "--max-effects", min=1, max=4, help="Add at most this many effects (1-4)."
    ),
) -> None:
    """Find what the model misses: residual evidence, candidate effects, held-out before/after."""
    names = tuple(dict.fromkeys(a.value for a in also))
    code = diagnose_command(run_file, params, out, as_json, names, max_effects, overwrite)
    raise typer.Exit(code)


#: what ``diagnose --out DIR`` writes in ``DIR``
OUTPUT_NAMES = ("diagnosis.json", "diagnosis.html")


def diagnose_command(
    run_file: Path,
    params: Path | None,
    out_dir: Path | None,
    as_json: bool,
    also: tuple[str, ...] = (),
    max_effects: int = 2,
    overwrite: bool = False,
) -> int:
    """Run the diagnosis of ``run_file`` and print / write it; returns the exit code.

    ``also``: structural effects to try beside the defaults; ``max_effects``: at most this
    many effects are added. The files in ``out_dir`` are checked before the work (an input,
    an existing file without ``overwrite``, an unwritable place) and written beside their
    targets, then renamed into place (:mod:`labrig.outputs`)."""
    from labrig.outputs import staged_outputs

    if out_dir is None:
        return _diagnose(run_file, params, None, as_json, also, max_effects)
    targets = [out_dir / n for n in OUTPUT_NAMES]
    with staged_outputs(targets, inputs=[run_file, params], overwrite=overwrite) as staged:
        code = _diagnose(run_file, params, staged.folder(out_dir), as_json, also, max_effects)
    if not as_json:
        Console().print(f"wrote {targets[0]} and {targets[1]}")
    return code


def _diagnose(
    run_file: Path,
    params: Path | None,
    write_dir: Path | None,
    as_json: bool,
    also: tuple[str, ...],
    max_effects: int,
) -> int:
    """The diagnosis, printed, and written to ``write_dir`` (the staging folder) if given."""
    from labrig.analysis.diagnose import diagnose as run_diagnosis
    from labrig.analysis.prepare import prepare_diagnosis
    from labrig.jsonsafe import json_safe
    from labrig.model.effects import EFFECT_NAMES, STRUCTURAL_EFFECT_NAMES

    err = Console(stderr=True)
    setup = prepare_diagnosis(run_file, params, err.print)

    def progress(msg: str) -> None:
        err.print(f"[dim]{msg}[/dim]")

    d = run_diagnosis(
        setup.records,
        setup.start,
        offset=setup.offset,
        effects=EFFECT_NAMES + also,
        max_effects=max_effects,
        progress=progress,
    )
    doc = json_safe(d.to_json())
    untried = [n for n in STRUCTURAL_EFFECT_NAMES if n not in also and n not in EFFECT_NAMES]
    if untried and d.classification in ("unexplained", "partially_explained"):
        err.print(
            f"hint: the structural effects {', '.join(untried)} were not tried; "
            f"`labrig diagnose {Path(run_file).name} "
            + " ".join(f"--also {n}" for n in untried)
            + " --max-effects 3` tries them (slower)"
        )
    if write_dir is not None:
        from labrig.report.diagnose_html import write_diagnosis

        title = f"labrig diagnose: {Path(run_file).name}"
        try:
            write_diagnosis(write_dir, doc, d, setup.records, title)
        except OSError as e:
            raise InputFileError(
                [InputIssue(str(write_dir.parent), None, "--out", f"cannot write: {e}")]
            ) from None
    if as_json:
        print(json.dumps(doc, indent=2))
        return 0
    print_diagnosis(doc, Path(run_file).name)
    return 0


def print_diagnosis(doc: dict[str, Any], name: str) -> None:
    """The diagnosis as tables: NRMSE before and after, the effects added, the candidates, the
    verdict."""
    con = Console()
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
    c.add_column("effect")
    c.add_column("held-out (%)", justify="right")
    c.add_column("evidence")
    for x in doc["candidates"]:
        h = x["heldout_nrmse_pct"]
        c.add_row(x["effect"], "-" if h is None else f"{h:.3g}", x["evidence"])
    con.print(c)
    con.print(f"[bold]verdict[/bold]: {doc['verdict']}")
