"""``labrig fit`` and ``labrig report``: read a run file, fit, print or write the results.

How a run file's entries are treated (:func:`prepare`):

- **Rig runs** (entries recorded by ``labrig run``: a DAQ-driven, zero-order-hold voltage, one
  sample rate): the actuator's memory spans the entries and the 0 V rests between them, so the
  entries are simulated back to back as the run (``chain``), each followed by the rest recorded
  in its step definition; entries that are not scored (not chosen with ``--entries``, or not
  complete) still drive the simulation as history. The run starts at rest: no warm-up, no
  offset (the conditioner is zeroed at rest).
- **Imported data** (``labrig import``: a measured voltage, linear hold, unrelated files): every
  entry on its own, from rest at 0 V; one constant strain offset per entry is fitted (the
  sensor's zero is arbitrary); when a record does not start at rest (its first voltage is not
  near 0 V) the first two drive periods are a warm-up, simulated but not scored.

``--warmup-s`` and ``--offset/--no-offset`` override the automatic choices; every choice is
stated on stderr and in the report.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from labrig import __version__
from labrig.analysis.baselines import KINDS, BaselineResult, fit_baseline
from labrig.analysis.fit import PARAM_NAMES, FitResult, fit_model, predict_record
from labrig.analysis.load import records_from_run
from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record
from labrig.errors import InputFileError, InputIssue, LabrigError
from labrig.model import DynamicHysteresisModel, ModelParams
from labrig.model.effects import Effect
from labrig.model.hysteresis import MEMORY_RULES
from labrig.store import RunFile, read_run

MODELS = ("dynamic", *KINDS)
JSON_KEYS = (
    "params",
    "uncertainty",
    "correlation",
    "nrmse_pct",
    "per_entry",
    "heldout_nrmse_pct",
    "method",
    "entries",
)


class AnalysisError(LabrigError):
    """The data cannot be fitted as asked (exit code 2)."""

    exit_code = 2


@dataclass
class Setup:
    """The records of a run file and how to fit them (module docstring)."""

    path: Path
    run: RunFile
    records: list[Record]  # simulated, in run order (with chain: history included)
    scored: list[str]  # fitted and scored
    chain: bool
    warmup_s: float
    offset: bool
    imported: bool
    notes: list[str] = field(default_factory=list)

    @property
    def scored_records(self) -> list[Record]:
        keep = set(self.scored)
        return [r for r in self.records if r.name in keep]


def _issue(path: Path, message: str, fld: str = "") -> InputFileError:
    return InputFileError([InputIssue(str(path), None, fld, message)])


def parse_entries(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    return names or None


def _auto_warmup(records: Sequence[Record]) -> tuple[float, str | None]:
    """Two drive periods when a record does not start at rest, else 0 (and why)."""
    late = []
    for r in records:
        span = float(np.ptp(r.voltage_V)) or 1.0
        if abs(float(r.voltage_V[0])) > 0.01 * span:
            late.append(r)
    if not late:
        return 0.0, None
    fs = [f for f in (drive_frequency_hz(r) for r in records) if f]
    w = 2.0 / min(fs) if fs else 1.0
    shortest = min(r.duration_s for r in records)
    w = min(w, 0.25 * shortest)
    w = float(f"{w:.3g}")
    first = late[0]
    why = (
        f"{len(late)} of {len(records)} records do not start at rest (e.g. {first.name} starts "
        f"at {first.voltage_V[0]:.3g} V): the first {w:g} s of every record are simulated but "
        "not scored (warm-up; --warmup-s to change)"
    )
    return w, why


def prepare(
    path: Path,
    entries: list[str] | None = None,
    warmup_s: float | None = None,
    offset: bool | None = None,
) -> Setup:
    """Read the run file and decide chain, warm-up and offset (module docstring)."""
    run = read_run(path, load_data=False)
    names = list(run.entries)
    if not names:
        raise _issue(path, "the run file has no entries")
    if entries:
        missing = [n for n in entries if n not in names]
        if missing:
            raise _issue(
                path,
                f"no entry {', '.join(map(repr, missing))} (entries: {', '.join(names)})",
                "--entries",
            )
        if len(set(entries)) != len(entries):
            raise _issue(path, "an entry is named twice", "--entries")
    complete = [n for n in names if run[n].complete]
    all_recs = records_from_run(path, names)  # incomplete ones too (history of a chain)
    by_name = {r.name: r for r in all_recs}
    if entries:
        unusable = [n for n in entries if n not in by_name]
        if unusable:
            raise _issue(
                path, f"entry {unusable[0]!r} has no voltage and strain to fit", "--entries"
            )
        scored = [n for n in names if n in set(entries)]
    else:
        scored = [n for n in names if n in by_name and n in set(complete)]
    if not scored:
        raise _issue(path, "no complete entry with voltage and strain to fit")
    notes: list[str] = []
    skipped = [n for n in names if n not in complete and n not in scored]
    if skipped:
        notes.append(
            f"not complete, not scored (name them with --entries to score them anyway): "
            f"{', '.join(skipped)}"
        )
    imported = all(
        r.hold == "linear" or r.meta.get("kind") == "import" for r in all_recs if r.name in scored
    )
    chain = (
        not imported
        and all(r.hold == "zoh" for r in all_recs)
        and len({r.rate_hz for r in all_recs}) == 1
    )
    if not imported and not chain:
        notes.append("entries differ in sample rate or hold: each is simulated on its own")
    if chain:
        records = all_recs
        history = [r.name for r in records if r.name not in set(scored)]
        if history:
            notes.append(f"not scored, simulated as history of the run: {', '.join(history)}")
    else:
        records = [by_name[n] for n in scored]
    if warmup_s is None:
        if chain:
            warmup_s = 0.0
        else:
            warmup_s, why = _auto_warmup(records)
            if why:
                notes.append(why)
    elif warmup_s < 0 or not math.isfinite(warmup_s):
        raise _issue(path, f"--warmup-s must be >= 0, got {warmup_s}", "--warmup-s")
    elif warmup_s > 0:
        notes.append(f"warm-up: the first {warmup_s:g} s of each record are not scored")
    if offset is None:
        offset = imported
        if offset:
            notes.append(
                "imported data: one constant strain offset per entry is fitted (the sensor's "
                "zero is unknown; --no-offset to change)"
            )
    elif offset:
        notes.append("one constant strain offset per entry is fitted (--offset)")
    short = [r.name for r in records if r.name in scored and r.duration_s <= warmup_s * 1.01]
    if short:
        raise _issue(path, f"the warm-up of {warmup_s:g} s leaves nothing of {short[0]!r} to score")
    return Setup(path, run, records, scored, chain, float(warmup_s), bool(offset), imported, notes)


# -- progress ------------------------------------------------------------------------------------


class FitProgress:
    """Rich progress on stderr for the fits (tasks added as the fits report them)."""

    def __init__(self, console: Console):
        self.console = console
        self.bar = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(bar_width=30),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=False,
        )
        self._tasks: dict[str, Any] = {}

    def __enter__(self) -> FitProgress:
        self.bar.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.bar.__exit__(*exc)

    def task(self, key: str, description: str, total: int) -> Callable[[int], None]:
        if key not in self._tasks:
            self._tasks[key] = self.bar.add_task(description, total=total)
        tid = self._tasks[key]

        def update(done: int) -> None:
            self.bar.update(tid, completed=done)

        return update

    def model_callback(self, label: str, n_scored: int) -> Callable[[str, int, int], None]:
        """A ``progress(stage, done, total)`` callback for :func:`fit_model`."""

        def cb(stage: str, done: int, total: int) -> None:
            if stage == "fit":
                self.task(f"{label}:fit", f"{label}: fit on {n_scored} entries", 1)(done)
            else:
                self.task(f"{label}:held", f"{label}: leave-one-entry-out", total)(done)

        return cb


# -- fitting -------------------------------------------------------------------------------------


def fit_dynamic(
    setup: Setup,
    method: str,
    heldout: bool,
    progress: FitProgress | None,
    memory: str = "return_point",
) -> FitResult:
    cb = progress.model_callback("model", len(setup.scored)) if progress else None
    try:
        return fit_model(
            setup.records,
            method=method,
            memory=memory,
            heldout=heldout,
            warmup_s=setup.warmup_s,
            progress=cb,
            chain=setup.chain,
            scored=setup.scored,
            offset=setup.offset,
        )
    except (ValueError, RuntimeError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the model: {e}") from None


def fit_base(
    setup: Setup, kind: str, heldout: bool, progress: FitProgress | None
) -> BaselineResult:
    label = {"prandtl_ishlinskii": "Prandtl-Ishlinskii", "bouc_wen": "Bouc-Wen"}[kind]
    upd = progress.task(kind, f"{label}: fit (and leave-one-out)", 1) if progress else None
    try:
        res = fit_baseline(
            setup.records,
            kind,
            heldout=heldout,
            warmup_s=setup.warmup_s,
            chain=setup.chain,
            scored=setup.scored,
            offset=setup.offset,
        )
    except (ValueError, RuntimeError, FloatingPointError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the {label} baseline: {e}") from None
    if upd:
        upd(1)
    return res


def _num(v: float | None, digits: int = 4) -> str:
    if v is None or not math.isfinite(v):
        return "—"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


UNITS = {
    "alpha0_ue_per_V": "ue/V",
    "gamma_ue_per_V": "ue/V",
    "vc_V": "V",
    "tau_t_s": "s",
    "tau_d_s": "s",
}


def summary_tables(res: FitResult | BaselineResult, model: str) -> list[Table]:
    """Parameters (with uncertainties) and NRMSE per entry, as rich tables."""
    j = res.to_json()
    out = []
    t = Table(title=f"{'model' if model == 'dynamic' else model} parameters ({j['method']})")
    t.add_column("parameter")
    t.add_column("value", justify="right")
    if model == "dynamic":
        t.add_column("± 1σ", justify="right")
        t.add_column("rel.", justify="right")
        t.add_column("unit")
        for name in PARAM_NAMES:
            v = j["params"][name]
            u = j["uncertainty"].get(name)
            rel = "fixed" if u is None else (f"{100 * u / abs(v):.2g} %" if v else "—")
            t.add_row(name, _num(v, 5), _num(u, 2), rel, UNITS.get(name, ""))
        t.add_row("shape", str(j["params"]["shape"]), "", "", "")
        t.add_row("memory", str(j["params"]["memory"]), "", "", "")
    else:
        for name, v in j["params"].items():
            if isinstance(v, list):
                v = ", ".join(_num(x, 3) for x in v)
            elif isinstance(v, float):
                v = _num(v, 5)
            t.add_row(name, str(v))
    out.append(t)
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
    out.append(e)
    return out


def run_fit(
    run_file: Path,
    entries: str | None,
    out: Path | None,
    as_json: bool,
    method: str,
    model: str,
    warmup_s: float | None,
    heldout: bool,
    offset: bool | None,
    effects: Sequence[str] = (),
    memory: str = "return_point",
) -> None:
    """``labrig fit``."""
    from labrig.analysis.fit_effects import EffectsFit, resolve_effects

    err = Console(stderr=True)
    if method not in ("global", "staged"):
        raise AnalysisError(f"--method must be global or staged, got {method!r}")
    if model not in MODELS:
        raise AnalysisError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    if memory not in MEMORY_RULES:
        raise AnalysisError(f"--memory must be one of {', '.join(MEMORY_RULES)}, got {memory!r}")
    if effects and model != "dynamic":
        raise AnalysisError(f"--effect applies to the dynamic model, not to --model {model}")
    try:
        resolve_effects(effects)  # before any fitting
    except ValueError as e:
        raise AnalysisError(f"--effect {e}") from None
    if out is not None and out.is_dir():
        raise AnalysisError(f"--out {out} is a directory; give a file name such as params.json")
    setup = prepare(run_file, parse_entries(entries), warmup_s, offset)
    _print_setup(err, setup)
    with FitProgress(err) as progress:
        if model == "dynamic":
            res: FitResult | BaselineResult | EffectsFit = fit_dynamic(
                setup, method, heldout and not effects, progress, memory
            )
            if effects:
                res = fit_with_effects(setup, res, effects, heldout, progress)
        else:
            res = fit_base(setup, model, heldout, progress)
    j = finite(res.to_json())
    text = json.dumps(j, indent=2, allow_nan=False)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text + "\n", encoding="utf-8")
    for m in getattr(res, "messages", []):
        err.print(f"[yellow]note:[/] {escape(m)}")
    if as_json:
        typer.echo(text)
    else:
        con = Console()
        for t in summary_tables(res, model):
            con.print(t)
        if isinstance(res, EffectsFit):
            con.print(effects_table(res))
        from labrig.report.data import noise_floor

        floor = noise_floor(setup.scored_records, setup.run.instrument, setup.warmup_s)
        if floor is not None:
            con.print(
                f"noise floor (NRMSE of a perfect model): {floor.nrmse_pct:.3g} % "
                f"({floor.noise_ue:.3g} rms from {escape(floor.source)})"
            )
        if isinstance(res, FitResult):
            held = f", leave-one-out {res.heldout_elapsed_s:.1f} s" if res.heldout_per_entry else ""
            con.print(f"fit {res.elapsed_s:.1f} s{held}")
    if out is not None:
        err.print(f"wrote {escape(str(out))}")


def fit_with_effects(
    setup: Setup,
    base: FitResult,
    effects: Sequence[str],
    heldout: bool,
    progress: FitProgress | None,
):
    """``--effect``: the base fit refitted with the named effects (labrig.analysis.fit_effects)."""
    from labrig.analysis.fit_effects import fit_effects

    def cb(stage: str, done: int, total: int) -> None:
        if progress is None:
            return
        label = {"effects": "model + effects: fit from each start", "heldout": "leave-one-out"}
        progress.task(f"eff:{stage}", label.get(stage, stage), total)(done)

    try:
        return fit_effects(
            setup.records,
            base,
            effects,
            chain=setup.chain,
            scored=setup.scored,
            warmup_s=setup.warmup_s,
            offset=setup.offset,
            heldout=heldout,
            progress=cb,
        )
    except (ValueError, RuntimeError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the model with effects: {e}") from None


def effects_table(res) -> Table:
    """The fitted effects and the NRMSE with and without them (same held-out scoring)."""
    t = Table(title="effects fitted with the model")
    t.add_column("effect")
    t.add_column("parameters")
    for e in res.effects:
        t.add_row(e["effect"], escape(e["description"]))
    held = (
        f"{_num(res.base_heldout_nrmse_pct, 3)} % -> {_num(res.heldout_nrmse_pct, 3)} %"
        if res.heldout_nrmse_pct is not None
        else "not computed"
    )
    t.caption = (
        f"NRMSE without -> with the effects: in-sample {_num(res.base_nrmse_pct, 3)} % -> "
        f"{_num(res.nrmse_pct, 3)} %; held-out (second half of each left-out entry) {held}"
    )
    return t


def _print_setup(err: Console, setup: Setup) -> None:
    how = "chained as one run" if setup.chain else "each on its own, from rest"
    err.print(
        f"[bold]{escape(str(setup.path))}[/]: {len(setup.scored)} entries to fit "
        f"({how}; warm-up {setup.warmup_s:g} s; offset {'on' if setup.offset else 'off'})"
    )
    for n in setup.notes:
        err.print(f"[yellow]note:[/] {escape(n)}")


# -- report --------------------------------------------------------------------------------------


def refuse_baseline(doc: dict[str, Any], path: Path, who: str) -> None:
    """An :class:`InputFileError` when the ``labrig fit`` output ``doc`` is a baseline's."""
    if doc.get("method") in KINDS:
        raise _issue(
            path,
            f"holds a {doc['method']} baseline; {who} needs the model's parameters "
            "(labrig fit without --model)",
            "method",
        )


def read_params(path: Path) -> dict[str, Any]:
    """A ``labrig fit --json`` file for the dynamic model."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise _issue(path, "parameter file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _issue(path, f"not a JSON parameter file ({e})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("params"), dict):
        raise _issue(path, "no 'params' object (expected the output of labrig fit --json)")
    refuse_baseline(doc, path, "the report")
    try:
        ModelParams(**doc["params"])
    except (TypeError, ValueError) as e:
        msg = str(e).splitlines()
        raise _issue(path, f"invalid model parameters: {' '.join(msg[:3])}", "params") from None
    _fitted_effects(doc, path, check_params=False)  # names now; parameters with the records
    return doc


def _fitted_effects(
    doc: dict[str, Any], path: Path, records: Sequence[Record] = (), check_params: bool = True
) -> tuple[list[Effect], dict]:
    """The library effects of a ``labrig fit --effect`` file and their parameters (checked),
    configured as when they were fitted (the file's ``effects_context``; else from ``records``;
    a file without either can only have its names checked: ``check_params=False``)."""
    from labrig.analysis.diagnose_fit import effect_context
    from labrig.analysis.fit_effects import resolve_effects

    listed = doc.get("effects") or []
    if not isinstance(listed, list) or not all(
        isinstance(e, dict) and isinstance(e.get("params"), dict) for e in listed
    ):
        raise _issue(path, "'effects' must be a list of {effect, params} objects", "effects")
    context = doc.get("effects_context")
    if context is None and records:
        context = effect_context(records)
    kinds = {"temperature": bool, "amplifier_voltage": bool, "mains_hz": float, "v_ref": float}
    if context is not None and not (
        isinstance(context, dict)
        and set(context) == set(kinds)
        and all(
            isinstance(context[k], t) or (t is float and isinstance(context[k], int))
            for k, t in kinds.items()
        )
    ):
        raise _issue(
            path, f"'effects_context' must have {', '.join(kinds)} (as labrig fit writes it)",
            "effects_context",
        )  # fmt: skip
    try:
        effects = resolve_effects([str(e.get("effect")) for e in listed], context)
    except ValueError as e:
        raise _issue(path, str(e), "effects") from None
    values: dict[str, dict[str, float]] = {}
    if not check_params:
        return effects, values
    for eff, e in zip(effects, listed, strict=True):
        want = [q.name for q in eff.params]
        p = e["params"]
        if sorted(p) != sorted(want) or not all(
            isinstance(p[k], int | float) and math.isfinite(p[k]) for k in want
        ):
            raise _issue(path, f"{eff.name} needs numeric params {', '.join(want)}", "effects")
        values[eff.name] = {k: float(p[k]) for k in want}
    return effects, values


def predict_entries(
    params: ModelParams, setup: Setup, effects: tuple[list[Effect], dict] | None = None
) -> dict[str, np.ndarray]:
    """The model's strain for each scored entry (chained as the run when ``setup.chain``),
    with one offset per entry fitted over the scored samples when ``setup.offset``; with the
    fitted ``effects`` (:func:`_fitted_effects`) when given, simulated as ``labrig fit
    --effect`` fitted them."""
    if effects and effects[0]:
        from labrig.analysis.diagnose_fit import ExtendedProblem

        prob = ExtendedProblem(
            setup.records,
            effects[0],
            chain=setup.chain,
            shape=params.shape,
            memory=params.memory,
            scored=setup.scored,
            warmup_s=setup.warmup_s,
            offset=setup.offset,
        )
        return prob.predictions(params.model_dump(), effects[1])
    keep = set(setup.scored)
    out: dict[str, np.ndarray] = {}
    if setup.chain:
        rate = setup.records[0].rate_hz
        stream = DynamicHysteresisModel(params).stream(rate, setup.records[0].hold)
        for r in setup.records:
            p = stream.process(r.voltage_V)
            if r.name in keep:
                out[r.name] = np.array(p, dtype=float)
            n_rest = round(max(float(r.meta.get("rest_after_s", 0.0) or 0.0), 0.0) * rate)
            if n_rest:
                stream.process(np.zeros(n_rest))
    else:
        for r in setup.records:
            if r.name in keep:
                out[r.name] = predict_record(params, r)
    if setup.offset:
        for r in setup.records:
            if r.name in out:
                i0 = round(setup.warmup_s * r.rate_hz)
                out[r.name] = out[r.name] + float(np.mean(r.strain_ue[i0:] - out[r.name][i0:]))
    return out


def run_report(
    run_file: Path,
    params_file: Path | None,
    out: Path,
    as_json: bool,
    entries: str | None,
    warmup_s: float | None,
    heldout: bool,
    offset: bool | None,
    method: str,
) -> None:
    """``labrig report``."""
    from labrig.report.control_section import control_html, control_metrics
    from labrig.report.data import Fitted, Provenance, build_report, metrics_json, noise_floor
    from labrig.report.html import _img, render
    from labrig.report.plots import entry_figure, frequency_figure

    err = Console(stderr=True)
    if out.is_dir():
        raise AnalysisError(f"--out {out} is a directory; give a file name such as report.html")
    doc = read_params(params_file) if params_file is not None else None
    setup = prepare(run_file, parse_entries(entries), warmup_s, offset)
    _print_setup(err, setup)
    notes = list(setup.notes)
    models: dict[str, Fitted] = {}
    t0 = time.perf_counter()
    with FitProgress(err) as progress:
        if doc is None:
            res = fit_dynamic(setup, method, heldout, progress)
            notes += [f"fit: {m}" for m in res.messages]
            j = res.to_json()
            models["dynamic"] = Fitted(
                "dynamic",
                res.predictions,
                res.heldout_per_entry,
                j["heldout_nrmse_pct"],
                j["params"],
                j["uncertainty"],
                j["correlation"],
                res.method,
            )
            source = f"fitted now ({res.method}, {res.elapsed_s:.1f} s)"
        else:
            params = ModelParams(**doc["params"])
            effects = _fitted_effects(doc, params_file, setup.records)
            models["dynamic"] = Fitted(
                "dynamic",
                predict_entries(params, setup, effects),
                None,
                doc.get("heldout_nrmse_pct"),
                doc["params"],
                doc.get("uncertainty") or {},
                doc.get("correlation") or {},
                str(doc.get("method", "")),
            )
            source = f"from {params_file}"
            if effects[0]:
                source += " with the effects fitted with it: " + ", ".join(
                    e.name for e in effects[0]
                )
            fitted_on = doc.get("entries")
            if isinstance(fitted_on, list) and fitted_on != setup.scored:
                notes.append(
                    f"the parameters were fitted on {', '.join(map(str, fitted_on))}; this "
                    f"report scores {', '.join(setup.scored)}"
                )
            notes.append(
                "held-out NRMSE per entry not available with --params (the file gives its mean "
                "only)"
            )
        for kind in KINDS:
            try:
                b = fit_base(setup, kind, heldout, progress)
            except AnalysisError as e:
                models[kind] = Fitted(kind, None, note=str(e))
                continue
            bj = b.to_json()
            models[kind] = Fitted(
                kind,
                b.predictions,
                b.heldout_per_entry,
                bj["heldout_nrmse_pct"],
                bj["params"],
                method=kind,
            )
    if not heldout:
        notes.append("held-out NRMSE not computed (--no-heldout)")
    elif len(setup.scored) < 2:
        notes.append("held-out NRMSE needs two scored entries or more")
    run = setup.run
    prov = Provenance(
        run_file=str(run_file),
        status=run.status,
        reason=run.reason,
        start_time=run.start_time,
        end_time=run.end_time,
        protocol_name=run.protocol_name,
        protocol_file=run.protocol_file,
        protocol_text=run.protocol_text,
        rig_file=run.rig_file,
        rig_text=run.rig_text,
        software_version=run.software_version,
        seed=run.seed,
        instrument=run.instrument,
        n_entries=len(run),
    )
    scored = setup.scored_records
    floor = noise_floor(scored, run.instrument, setup.warmup_s)
    if setup.imported or not run.protocol_name:
        title = f"Model versus measurement: {run_file.name} (imported data)"
    else:
        title = f"Model versus measurement: {run.protocol_name}"
    settings = {
        "entries": setup.scored,
        "chain": setup.chain,
        "offset": setup.offset,
        "params_source": source,
        "fit_time": (
            f"{time.perf_counter() - t0:.1f} s ("
            + ("model and baselines" if doc is None else "baselines")
            + (", with leave-one-out)" if heldout else ")")
        ),
    }
    data = build_report(
        title,
        scored,
        models,
        setup.warmup_s,
        prov,
        settings,
        notes,
        floor,
        datetime.now().astimezone().isoformat(timespec="seconds"),
        __version__,
    )
    unit = _strain_unit(scored)
    with err.status("drawing the figures"):
        noise = floor.noise_ue if floor else None
        dyn = models["dynamic"].predictions or {}
        pngs = {}
        for e in data.entries:
            if e.name not in dyn:
                continue
            others = {
                fm.label: fm.predictions[e.name]
                for k, fm in models.items()
                if k != "dynamic" and fm.predictions and e.name in fm.predictions
            }
            pngs[e.name] = entry_figure(e, dyn[e.name], setup.warmup_s, noise, unit, others)
        freq = frequency_figure(data.entries, list(models), unit)
        all_records = setup.records
        ctrl_html = control_html(list(all_records), _img)
    page = render(data, freq, pngs, ctrl_html)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(page, encoding="utf-8")
    err.print(f"wrote {escape(str(out))} ({len(page) / 1e6:.1f} MB)")
    if as_json:
        table = metrics_json(data)
        for name, m in control_metrics(list(all_records)).items():
            table.setdefault(name, {}).update(m)
        typer.echo(json.dumps(finite(table), indent=2, allow_nan=False))
    else:
        typer.echo(str(out))


def _strain_unit(records: Sequence[Record]) -> str:
    for r in records:
        u = r.meta.get("units", {}).get("strain") if isinstance(r.meta.get("units"), dict) else None
        if u:
            return str(u)
    return "ue"


def finite(x: Any) -> Any:
    """``x`` with every non-finite float replaced by ``None`` (strict JSON)."""
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
