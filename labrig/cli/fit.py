"""``labrig fit``: identify the model (or a baseline) from a run file; print parameters and NRMSE
(:func:`labrig.commands.fit.fit_run_file`; how entries are treated:
:mod:`labrig.commands.prepare`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from labrig.cli.common import (
    HELDOUT_OPTION,
    OFFSET_OPTION,
    OVERWRITE_OPTION,
    WARMUP_OPTION,
    FitEffect,
    Memory,
    Method,
    Model,
    check_out,
    choice,
    deliver_json,
    entries_option,
    friendly,
    json_option,
    one_of,
    out_file_option,
)

if TYPE_CHECKING:
    from labrig.analysis.baselines import BaselineResult
    from labrig.analysis.fit import FitResult
    from labrig.analysis.fit_effects import EffectsFit
    from labrig.commands.fit import FitOutcome

UNITS = {
    "alpha0_ue_per_V": "ue/V",
    "gamma_ue_per_V": "ue/V",
    "vc_V": "V",
    "tau_t_s": "s",
    "tau_d_s": "s",
}

METHOD_OPTION = typer.Option(
    Method.GLOBAL,
    "--method",
    parser=choice(Method, "a fit method"),
    metavar="METHOD",
    help="global or staged (the paper's section 3.1).",
)
MODEL_OPTION = typer.Option(
    Model.DYNAMIC,
    "--model",
    parser=choice(Model, "a model"),
    metavar="MODEL",
    help="dynamic (ours), prandtl_ishlinskii, bouc_wen or sindy (a sparse ODE fitted with "
    "pysindy, scored in free run; docs/sindy.md).",
)
EFFECT_OPTION = typer.Option(
    [],
    "--effect",
    parser=choice(FitEffect, "an effect fit can add"),
    metavar="EFFECT",
    help=f"Also fit this library effect with the model (repeatable): {one_of(FitEffect)}; "
    "e.g. viscoelastic_creep (which compensation control inverts); see docs/diagnose.md.",
)
MEMORY_OPTION = typer.Option(
    Memory.RETURN_POINT,
    "--memory",
    parser=choice(Memory, "a memory rule"),
    metavar="RULE",
    help="The hysteresis operator's memory: return_point (minor loops close and are "
    "forgotten), return_point_open (the same, but no loop closes onto the rest point at 0 V: "
    "bipolar loops stay open there) or last_reversal (the paper's single memory); "
    "docs/analysis.md.",
)


@friendly
def fit(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), recorded or imported."),
    entries: str | None = entries_option("Entries to fit"),
    out: Path | None = out_file_option("the result as JSON (what --json prints)"),
    as_json: bool = json_option(),
    method: Method = METHOD_OPTION,
    model: Model = MODEL_OPTION,
    warmup_s: float | None = WARMUP_OPTION,
    heldout: bool = HELDOUT_OPTION,
    offset: bool | None = OFFSET_OPTION,
    effect: list[FitEffect] = EFFECT_OPTION,
    memory: Memory = MEMORY_OPTION,
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Identify the model (or a baseline) from a run file; print parameters and NRMSE."""
    from labrig.analysis.fit_effects import EffectsFit
    from labrig.commands.fit import fit_run_file
    from labrig.commands.prepare import parse_entries
    from labrig.commands.progress import RichUI

    check_out(out, [run_file], overwrite)  # before the work
    ui = RichUI()
    outcome = fit_run_file(
        run_file,
        entries=parse_entries(entries),
        method=method.value,
        model=model.value,
        memory=memory.value,
        effects=[e.value for e in effect],
        warmup_s=warmup_s,
        heldout=heldout,
        offset=offset,
        ui=ui,
    )
    res = outcome.result
    for m in getattr(res, "messages", []):
        ui.err.print(f"[yellow]note:[/] {escape(m)}")
    if deliver_json(res.to_json(), as_json=as_json, out=out, overwrite=overwrite):
        con = Console()
        from labrig.analysis.records import strain_unit

        for t in summary_tables(res, model.value, strain_unit(outcome.setup.scored_records)):
            con.print(t)
        if isinstance(res, EffectsFit):
            con.print(effects_table(res))
        print_floor_and_time(con, outcome)


def print_floor_and_time(con: Console, outcome: FitOutcome) -> None:
    """The noise floor of the scored records (when known) and the fit's time."""
    from labrig.analysis.fit import FitResult
    from labrig.analysis.fit_effects import EffectsFit
    from labrig.analysis.noise_floor import noise_floor

    setup, res = outcome.setup, outcome.result
    # a fit with effects keeps no predictions: its floor is printed by `labrig diagnose`
    preds = {} if isinstance(res, EffectsFit) else res.predictions
    floor = noise_floor(setup.scored_records, preds, setup.warmup_s)
    if floor is not None:
        con.print(
            f"noise floor (NRMSE of a perfect model): {floor.nrmse_pct:.3g} % "
            f"({floor.noise_ue:.3g} rms from {escape(floor.source)})"
        )
    if isinstance(res, FitResult):
        held = f", leave-one-out {res.heldout_elapsed_s:.1f} s" if res.heldout_per_entry else ""
        con.print(f"fit {res.elapsed_s:.1f} s{held}")


def number(v: float | None, digits: int = 4) -> str:
    """A parameter for a table cell: ``digits`` significant digits, scientific when tiny or
    huge, ``—`` when undefined."""
    if v is None or not math.isfinite(v):
        return "—"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


def parameter_cells(v: float, u: float | None, why: str | None) -> tuple[str, str, str]:
    """A parameter's value, 1-sigma and relative 1-sigma cells: ``fixed`` when it was held
    fixed, and, when it is unidentifiable (``why``, :mod:`labrig.analysis.identifiability`),
    the value flagged with the reason and no 1-sigma when it has none or is not meaningful (a
    parameter that ended at a bound)."""
    from labrig.analysis.identifiability import AT_BOUND

    shown = number(v, 5)
    if why is not None:
        shown = f"unidentifiable (fitted {shown}; {why})"
        if u is None or AT_BOUND in why:
            return shown, "—", "—"
    elif u is None:
        return shown, "—", "fixed"
    return shown, number(u, 2), f"{100 * u / abs(v):.2g} %" if v else "—"


def summary_tables(
    res: FitResult | BaselineResult | EffectsFit, model: str, strain_unit: str = "ue"
) -> list[Table]:
    """Parameters (with uncertainties) and NRMSE per entry, as rich tables; the strain's unit
    ``strain_unit`` is the records' (a field named ``_ue`` holds a ``raw`` import's numbers as
    they are, and its unit says so)."""
    from labrig.analysis.fit import PARAM_NAMES

    j = res.to_json()
    t = Table(title=f"{'model' if model == 'dynamic' else model} parameters ({j['method']})")
    t.add_column("parameter")
    t.add_column("value", justify="right")
    if model == "dynamic":
        t.add_column("± 1σ", justify="right")
        t.add_column("rel.", justify="right")
        t.add_column("unit")
        ident = j.get("identifiability") or {}
        flagged = ident.get("unidentifiable") or {}
        for name in PARAM_NAMES:
            shown, sd, rel = parameter_cells(
                j["params"][name], j["uncertainty"].get(name), flagged.get(name)
            )
            unit = UNITS.get(name, "").replace("ue", strain_unit)
            t.add_row(name, escape(shown), sd, rel, Text(unit))
        t.add_row("shape", str(j["params"]["shape"]), "", "", "")
        t.add_row("memory", str(j["params"]["memory"]), "", "", "")
        loop = ident.get("loop")
        if loop:
            for key, unit in (("loop_width_ue", strain_unit), ("loop_curvature", "")):
                v, u = loop[key], loop[f"{key}_sd"]
                rel = "—" if u is None or not v else f"{100 * u / abs(v):.2g} %"
                t.add_row(key, number(v, 5), number(u, 2), rel, Text(unit))
            t.caption = (
                f"loop_width_ue: the operator's loop opening at mid-stroke of a "
                f"{number(loop['span_V'], 4)} V loop; loop_curvature: span / vc_V. "
                + str(ident.get("rule", ""))
            )
    else:
        for name, v in j["params"].items():
            if isinstance(v, list):
                v = ", ".join(number(x, 3) if isinstance(x, int | float) else str(x) for x in v)
            elif isinstance(v, float):
                v = number(v, 5)
            t.add_row(name, str(v))
    e = Table(title="NRMSE (%) per entry")
    e.add_column("entry")
    e.add_column("in-sample", justify="right")
    e.add_column("held-out", justify="right")
    held = res.heldout_per_entry or {}
    for name, v in j["per_entry"].items():
        e.add_row(name, f"{v:.3g}", f"{held[name]:.3g}" if name in held else "—")
    hm = j["heldout_nrmse_pct"]
    e.add_row(
        "[bold]mean[/]",
        f"[bold]{j['nrmse_pct']:.3g}[/]",
        f"[bold]{hm:.3g}[/]" if hm is not None else "—",
    )
    return [t, e]


def effects_table(res: EffectsFit) -> Table:
    """The fitted effects and the NRMSE with and without them (same held-out scoring)."""
    t = Table(title="effects fitted with the model")
    t.add_column("effect")
    t.add_column("parameters")
    flagged = res.to_json()["identifiability"]["unidentifiable"]
    for e in res.effects:
        own = [(k, f"{e['effect']}.{k}") for k in e["params"]]
        notes = [f"{k}: unidentifiable ({flagged[q]})" for k, q in own if q in flagged]
        t.add_row(e["effect"], escape("; ".join([e["description"], *notes])))
    held = (
        f"{number(res.base_heldout_nrmse_pct, 3)} % -> {number(res.heldout_nrmse_pct, 3)} %"
        if res.heldout_nrmse_pct is not None
        else "not computed"
    )
    t.caption = (
        f"NRMSE without -> with the effects: in-sample {number(res.base_nrmse_pct, 3)} % -> "
        f"{number(res.nrmse_pct, 3)} %; held-out (second half of each left-out entry) {held}"
    )
    return t
