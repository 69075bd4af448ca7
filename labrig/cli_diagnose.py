"""``labrig diagnose RUN.h5 [--params params.json] [--out DIR] [--json] [--also NAME]...
[--max-effects N]``.

The lead wires :func:`diagnose_command` into ``labrig.cli`` (see ``docs/diagnose.md``). Exit
codes: 0 done (whatever the verdict), 2 bad input (file, parameters), 1 unexpected failure.
``--json`` prints only the JSON contract on stdout (progress and messages go to stderr).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from labrig.errors import InputFileError, InputIssue

__all__ = ["check_also", "diagnose_command"]


def _clean(x: Any) -> Any:
    """JSON-safe: non-finite floats become ``null``."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def _load_params(path: Path, say: Callable[[str], None] = print):
    """Start parameters from a ModelParams JSON object or a ``labrig fit --json`` file.

    Only the dynamic model's parameters are used: a baseline's file is refused, and effects
    fitted with ``labrig fit --effect`` are announced as not used (diagnose starts from the base
    and tests every effect itself, so it can say whether each one pays)."""
    from pydantic import ValidationError

    from labrig.cli_analysis import refuse_baseline
    from labrig.model import ModelParams

    try:
        raw = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise InputFileError(
            [InputIssue(str(path), None, "--params", f"cannot read JSON: {e}")]
        ) from None
    if isinstance(raw, dict) and isinstance(raw.get("params"), dict):
        refuse_baseline(raw, path, "diagnose")
        effects = raw.get("effects") or []
        if effects:
            names = [e.get("effect", "?") if isinstance(e, dict) else str(e) for e in effects]
            say(
                f"{path}: using the base parameters only; its effects ({', '.join(names)}) "
                "are tested again, not assumed"
            )
        raw = raw["params"]  # the output of ``labrig fit --json``
    try:
        return ModelParams.model_validate(raw)
    except ValidationError as e:
        msg = "; ".join(f"{'.'.join(map(str, x['loc']))}: {x['msg']}" for x in e.errors())
        raise InputFileError([InputIssue(str(path), None, "--params", msg)]) from None


def check_also(names: list[str]) -> tuple[str, ...]:
    """The ``--also`` names, checked against the structural effects (``typer.BadParameter``,
    exit code 2, for any other name)."""
    import typer

    from labrig.model.effects import STRUCTURAL_EFFECT_NAMES

    bad = [n for n in names if n not in STRUCTURAL_EFFECT_NAMES]
    if bad:
        raise typer.BadParameter(
            f"{', '.join(bad)}: not a structural effect; choose from "
            f"{', '.join(STRUCTURAL_EFFECT_NAMES)} (the other effects are always tried)",
            param_hint="--also",
        )
    return tuple(dict.fromkeys(names))


def diagnose_command(
    run_file: Path,
    params: Path | None,
    out_dir: Path | None,
    as_json: bool,
    also: tuple[str, ...] = (),
    max_effects: int = 2,
) -> int:
    """Run the diagnosis of ``run_file`` and print / write it; returns the exit code.

    ``also``: structural effects to try beside the defaults; ``max_effects``: at most this
    many effects are added."""
    from labrig.analysis.diagnose import diagnose, split_entries
    from labrig.analysis.load import records_from_run
    from labrig.model.effects import EFFECT_NAMES, STRUCTURAL_EFFECT_NAMES

    err = Console(stderr=True)
    records = records_from_run(run_file)
    p0 = _load_params(params, err.print) if params is not None else None
    if len(records) == 1 and records[0].duration_s > 0:
        records = split_entries(records, 4)
        err.print(f"one entry: cut into {len(records)} consecutive parts for leave-one-entry-out")
    # imported data: the sensor's zero is arbitrary, fit one offset per entry
    offset = any(r.meta.get("kind") == "import" for r in records)
    if len(records) < 3:
        raise InputFileError(
            [
                InputIssue(
                    str(run_file),
                    None,
                    "entries",
                    f"diagnose needs at least 3 complete entries (leave-one-entry-out), "
                    f"found {len(records)}",
                )
            ]
        )

    def progress(msg: str) -> None:
        err.print(f"[dim]{msg}[/dim]")

    d = diagnose(
        records,
        p0,
        offset=offset,
        effects=EFFECT_NAMES + also,
        max_effects=max_effects,
        progress=progress,
    )
    doc = _clean(d.to_json())
    untried = [n for n in STRUCTURAL_EFFECT_NAMES if n not in also]
    if untried and d.classification in ("unexplained", "partially_explained"):
        err.print(
            f"hint: the structural effects {', '.join(untried)} were not tried; "
            f"`labrig diagnose {Path(run_file).name} "
            + " ".join(f"--also {n}" for n in untried)
            + " --max-effects 3` tries them (slower)"
        )
    if out_dir is not None:
        from labrig.report.diagnose_html import render_diagnosis

        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "diagnosis.json").write_text(json.dumps(doc, indent=2) + "\n")
        (out_dir / "diagnosis.html").write_text(
            render_diagnosis(d, records, title=f"labrig diagnose: {Path(run_file).name}")
        )
    if as_json:
        print(json.dumps(doc, indent=2))
        return 0
    con = Console()
    t = Table(title=f"diagnose {Path(run_file).name}")
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
    if out_dir is not None:
        con.print(f"wrote {out_dir / 'diagnosis.json'} and {out_dir / 'diagnosis.html'}")
    return 0
