"""``labrig report`` as a library call: :func:`build_run_report` reads the run file, fits our model
(or takes its parameters from a ``labrig fit`` file) and the baselines on the same records, and
returns the HTML page with its metrics table.

Steps: :func:`~labrig.commands.prepare.prepare` (which records, chained or not, warm-up,
offset); :func:`fit_report_models` (our model and the baselines, as
:class:`~labrig.report.data.Fitted`); :func:`~labrig.report.data.build_report` (the metrics);
the figures (:mod:`labrig.report.plots`, :mod:`labrig.report.control_section`) and the page
(:func:`labrig.report.html.render`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from labrig.analysis.baselines import KINDS
from labrig.analysis.fit import FitResult, predict_record
from labrig.analysis.noise_floor import noise_floor
from labrig.analysis.params_file import fitted_effects, read_fit_output
from labrig.analysis.records import strain_unit, warmup_samples
from labrig.commands.fit import (
    CommandUI,
    FitOutcome,
    Progress,
    QuietUI,
    fit_base,
    fit_dynamic,
)
from labrig.commands.prepare import (
    AnalysisError,
    Setup,
    prepare,
    training_setup,
    unit_issues,
)
from labrig.core.blas import single_thread_blas
from labrig.core.errors import InputFileError, InputIssue
from labrig.core.jsonsafe import MAX_JSON_BYTES, json_safe, loads_bounded
from labrig.core.outputs import same_file
from labrig.core.textfile import read_text_bounded
from labrig.core.version import __version__
from labrig.model import DynamicHysteresisModel, ModelParams
from labrig.model.effects import Effect
from labrig.report.data import (
    PEER_NAMES,
    Fitted,
    Provenance,
    ReportData,
    build_report,
    metrics_json,
)


def peers_caveat(
    params_file: Path | str, fitted_on: Any, run_file: Path | str, peers: Sequence[str] = KINDS
) -> str | None:
    """What ``labrig report RUN --params P`` compares, said plainly: our model was identified
    wherever ``P`` was fitted (``fitted_on``: its entries), the ``peers`` are fitted now on the
    report's own records, so they are scored in-sample; ``labrig validate`` compares like with
    like. ``None`` without peers (nothing is compared)."""
    if not peers:
        return None
    on = ", ".join(map(str, fitted_on)) if isinstance(fitted_on, list) and fitted_on else "?"
    names = ", ".join(PEER_NAMES[k] for k in peers)
    return (
        f"Not a like-for-like comparison: our model's parameters come from {params_file} "
        f"(identified on {on}), while the peers ({names}) are "
        f"fitted now on the records of this report, so they are scored in-sample. To identify "
        f"every model on the same training records and score them all on records none of them "
        f"saw: labrig validate TRAIN.h5 --on {Path(run_file).name}"
    )


@dataclass
class FittedModels:
    """The report's models fitted to a :class:`~labrig.commands.prepare.Setup`."""

    models: dict[str, Fitted]
    source: str  # where our model's parameters come from
    notes: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    #: set when our model and the peers were not identified on the same records
    caveat: str | None = None
    #: the run files the peers are identified on (our model's training files), else ``None``
    #: (the report's own records)
    peers_on: list[Path] | None = None
    #: the records the peers are identified on when not the report's own: our model's
    #: training records (its training files, the entries it was fitted on)
    peers_setup: Setup | None = None
    #: the report's entries every model was identified on (its NRMSE there is in-sample; on
    #: the others out-of-sample); ``None`` when that differs between the models (our model's
    #: training records are not known: the peers are fitted on the report's own)
    in_sample: list[str] | None = None


@dataclass
class BuiltReport:
    """The report: the HTML page and the metrics table ``labrig report --json`` prints;
    ``caveat``: what the comparison is not (:func:`peers_caveat`), when it applies."""

    setup: Setup
    page: str
    metrics: dict[str, Any]
    caveat: str | None = None


def predict_entries(
    params: ModelParams,
    setup: Setup,
    effects: tuple[list[Effect], dict[str, dict[str, float]]] | None = None,
    *,
    raw: bool = False,
) -> dict[str, np.ndarray]:
    """The model's strain for each scored entry (chained as the run when ``setup.chain``),
    with one offset per entry fitted over the scored samples when ``setup.offset``; with the
    fitted ``effects`` (:func:`labrig.analysis.params_file.fitted_effects`) when given, simulated as
    ``labrig fit --effect`` fitted them (their nuisance terms fitted over the scored samples).
    ``raw``: the model's strain alone, no offset and no nuisance terms (``labrig validate``
    fits those by its own rule)."""
    if effects and effects[0]:
        from labrig.analysis.extended import ExtendedProblem

        prob = ExtendedProblem(
            setup.records,
            effects[0],
            chain=setup.chain,
            shape=params.shape,
            memory=params.memory,
            scored=setup.scored,
            warmup_s=setup.warmup_s,
            offset=setup.offset and not raw,
        )
        return prob.predictions(params.model_dump(), effects[1], nuisance=not raw)
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
    return out if raw else with_offsets(out, setup)


def with_offsets(predictions: dict[str, np.ndarray], setup: Setup) -> dict[str, np.ndarray]:
    """``predictions`` (entry -> strain) plus, when ``setup.offset``, each entry's constant
    offset fitted over its scored samples (the mean of measured minus predicted)."""
    if not setup.offset:
        return predictions
    out = dict(predictions)
    for r in setup.records:
        if r.name in out:
            i0 = warmup_samples(r, setup.warmup_s)
            out[r.name] = out[r.name] + float(np.mean(r.strain_ue[i0:] - out[r.name][i0:]))
    return out


def _fitted_now(
    setup: Setup,
    method: str,
    heldout: bool,
    progress: Progress,
    fitted: FitResult | None = None,
) -> FittedModels:
    """Our model fitted to the setup's records (``fitted``: that fit, already made on this
    setup, is used instead of fitting again)."""
    res = fitted if fitted is not None else fit_dynamic(setup, method, heldout, progress)
    j = res.to_json()
    model = Fitted(
        "dynamic",
        res.predictions,
        res.heldout_per_entry,
        j["heldout_nrmse_pct"],
        j["params"],
        j["uncertainty"],
        j["correlation"],
        res.method,
        loop_span_V=res.loop_span_V,
        unidentifiable=j["identifiability"]["unidentifiable"],
    )
    return FittedModels(
        {"dynamic": model},
        f"fitted now ({res.method}, {res.elapsed_s:.1f} s)",
        [f"fit: {m}" for m in res.messages],
        in_sample=list(setup.scored),
    )


def training_files(doc: dict[str, Any], params_file: Path) -> list[Path] | None:
    """The run files a ``labrig fit`` output was fitted on (its ``train_files``; relative paths
    from the parameter file's folder), or ``None`` when it does not say."""
    listed = doc.get("train_files") if isinstance(doc, dict) else None
    if not isinstance(listed, list) or not listed or not all(isinstance(p, str) for p in listed):
        return None
    return [p if p.is_absolute() else params_file.parent / p for p in map(Path, listed)]


def named_training_files(params_file: Path | None) -> list[Path]:
    """The training files a parameter file names (:func:`training_files`), read leniently: an
    unreadable or malformed file names none (it is refused, naming its field, when it is read
    for the report)."""
    if params_file is None:
        return []
    try:
        doc = loads_bounded(read_text_bounded(params_file, MAX_JSON_BYTES))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return []
    return training_files(doc, Path(params_file)) or []


def _peers_elsewhere(setup: Setup, tr: Setup, kind: str, progress: Progress) -> Fitted:
    """The peer ``kind`` identified on the training records ``tr`` (as ``labrig validate``
    does) and predicting the report's records (each entry's offset fitted as for our model)."""
    b = fit_base(tr, kind, False, progress)
    sim = b.simulate(setup.records, setup.chain)
    preds = with_offsets({n: sim[n] for n in setup.scored}, setup)
    return Fitted(
        kind, preds, None, None, b.params, method=f"{kind} (identified on the training records)"
    )


def _loop_span(doc: dict[str, Any], setup: Setup) -> float | None:
    """The stroke (V) of the loop coordinates: the parameter file's, else the records' largest
    peak-to-peak voltage."""
    loop = (doc.get("identifiability") or {}).get("loop") if isinstance(doc, dict) else None
    span = loop.get("span_V") if isinstance(loop, dict) else None
    if isinstance(span, int | float) and span > 0:
        return float(span)
    spans = [float(np.ptp(r.voltage_V)) for r in setup.scored_records if r.n]
    return max(spans) if spans else None


def _described(name: str, doc: dict[str, Any]) -> str:
    """An effect of a ``labrig fit`` file with its fitted values as the fit described them
    (``"thermal_drift (k = 0.499 +- 0.00046 %/K)"``), or its name alone."""
    for e in doc.get("effects") or []:
        if isinstance(e, dict) and e.get("effect") == name and e.get("description"):
            return f"{name} ({e['description']})"
    return name


def _from_file(
    setup: Setup,
    doc: dict[str, Any],
    params_file: Path,
    heldout: bool = False,
    progress: Progress | None = None,
    peers: Sequence[str] = KINDS,
) -> FittedModels:
    """Our model with the parameters (and effects) of a ``labrig fit`` file, and where the
    peers are to be identified (:func:`_where_identified`). The file gives its held-out NRMSE
    as a mean only; with ``heldout`` (and two scored entries or more, no effects) the held-out
    NRMSE of each entry is measured now, leave-one-entry-out as ``labrig fit`` does (each fold
    fits the other entries), so the report keeps its column."""
    params = ModelParams(**doc["params"])
    effects = fitted_effects(doc, params_file, setup.records)
    source = f"from {params_file}"
    if effects[0]:
        source += " with the effects fitted with it: " + "; ".join(
            _described(e.name, doc) for e in effects[0]
        )
    out = FittedModels({}, source)
    _where_identified(out, setup, doc, params_file, peers)  # before any fit
    held_per, held_mean = None, doc.get("heldout_nrmse_pct")
    if heldout and len(setup.scored) >= 2 and not effects[0]:
        method = str(doc.get("method", "global"))
        method = method if method in ("global", "staged") else "global"
        res = fit_dynamic(setup, method, True, progress, params.memory)
        held_per, held_mean = res.heldout_per_entry, res.heldout_nrmse_pct
        out.notes.append(
            "held-out NRMSE per entry: leave-one-entry-out fits made now "
            f"({method}; the parameters file gives its mean only)"
        )
    else:
        out.notes.append(
            "held-out NRMSE per entry not available with --params here (the file gives its "
            "mean only; it is measured now with --heldout, two scored entries or more and no "
            "effects)"
        )
    out.models["dynamic"] = Fitted(
        "dynamic",
        predict_entries(params, setup, effects),
        held_per,
        held_mean,
        doc["params"],
        doc.get("uncertainty") or {},
        doc.get("correlation") or {},
        str(doc.get("method", "")),
        loop_span_V=_loop_span(doc, setup),
        unidentifiable=(doc.get("identifiability") or {}).get("unidentifiable"),
    )
    return out


def _where_identified(
    out: FittedModels,
    setup: Setup,
    doc: dict[str, Any],
    params_file: Path,
    peers: Sequence[str],
) -> None:
    """Where our model of ``params_file`` was identified, and so the peers: its training
    records when the file names them (:func:`_identified_elsewhere`; the report's own records
    need nothing), else the report's records for the peers, in-sample, with a caveat."""
    fitted_on = doc.get("entries")  # checked when read: a list of names, or absent
    train = training_files(doc, params_file)
    if train is None or any(not p.is_file() for p in train):
        if fitted_on is not None and fitted_on != setup.scored:
            out.notes.append(
                f"the parameters were fitted on {', '.join(fitted_on)}; this "
                f"report scores {', '.join(setup.scored)}"
            )
        if train is not None:
            missing = [str(p) for p in train if not p.is_file()]
            out.notes.append(
                f"the training files of {params_file} are not found: {', '.join(missing)}"
            )
        out.caveat = peers_caveat(params_file, fitted_on, setup.path, peers)
    elif _own_records(train, fitted_on, setup):
        out.in_sample = list(setup.scored)  # the peers are fitted on them too
    else:
        _identified_elsewhere(out, setup, train, fitted_on, params_file, peers)


def _own_records(train: list[Path], fitted_on: list[str] | None, setup: Setup) -> bool:
    """Whether our model was identified on the report's own records: its one training file is
    the report's, and it was fitted on the entries the report scores (or does not say which)."""
    return _the_reports_file(train, setup) and (
        fitted_on is None or set(fitted_on) == set(setup.scored)
    )


def _the_reports_file(train: list[Path], setup: Setup) -> bool:
    """Whether the training files ``train`` are the report's own file alone."""
    return len(train) == 1 and same_file(train[0], setup.path)


def _identified_elsewhere(
    out: FittedModels,
    setup: Setup,
    train: list[Path],
    fitted_on: list[str] | None,
    params_file: Path,
    peers: Sequence[str],
) -> None:
    """Our model was identified on other records than the report's (other files, or other
    entries of the same file): the peers are identified on those same records
    (:func:`training_records`) and ``out`` says so, with which of the report's entries are then
    in-sample (those of the training records, when the file is the report's own)."""
    tr = training_records(train, fitted_on, params_file, setup)
    out.peers_on, out.peers_setup = train, tr
    seen = set(tr.scored) if _the_reports_file(train, setup) else set()
    out.in_sample = [n for n in setup.scored if n in seen]
    names = ", ".join(p.name for p in train)
    where = f"{', '.join(tr.scored)} of {names}" if fitted_on is not None else names
    who = "our model and the peers are" if peers else "our model is"
    does = "predict" if peers else "predicts"
    if not out.in_sample:
        scope = ", out-of-sample"
    elif out.in_sample == setup.scored:
        scope = ", in-sample"
    else:
        scope = f": in-sample on {', '.join(out.in_sample)}, out-of-sample on the others"
    out.notes.append(
        f"{who} identified on {where} (the training files of {params_file.name}) and "
        f"{does} the records of this report{scope}"
    )


def training_records(
    train: list[Path], fitted_on: list[str] | None, params_file: Path, setup: Setup
) -> Setup:
    """The records our model of ``params_file`` was identified on: its training files
    ``train``, of one file the entries it was fitted on (``fitted_on``; every complete entry
    when it does not say), as ``labrig fit`` prepares them. An
    :class:`~labrig.core.errors.InputFileError` naming the parameter file's field when they
    cannot be read, or when their strain is in another unit than the report's records
    (:func:`~labrig.commands.prepare.unit_issues`: a model predicts in the unit it was
    identified in)."""
    try:
        if len(train) > 1:
            tr = training_setup(train)
        else:  # the report's own file: the snapshot it has read
            run = setup.run if _the_reports_file(train, setup) else None
            tr = prepare(train[0], fitted_on, run=run)
    except InputFileError as e:
        field = "entries" if any(i.field == "--entries" for i in e.issues) else "train_files"
        raise InputFileError(
            [
                InputIssue(
                    str(params_file),
                    None,
                    field,
                    "its training records cannot be read as they are named:",
                ),
                *e.issues,
            ]
        ) from None
    mixed = unit_issues(
        [(Path(tr.path), r) for r in tr.scored_records]
        + [(Path(setup.path), r) for r in setup.scored_records]
    )
    if mixed:
        unit, theirs = strain_unit(tr.scored_records), strain_unit(setup.scored_records)
        raise InputFileError(
            [
                InputIssue(
                    str(params_file),
                    None,
                    "train_files",
                    f"its model was identified on strain in {unit!r} "
                    f"({', '.join(p.name for p in train)}) and predicts in {unit!r}; the "
                    f"report's records are in {theirs!r}: fit the model on records in "
                    f"{theirs!r} (labrig fit {Path(setup.path).name}), or bring them in "
                    f"{unit!r} (labrig import --strain-units, --strain-scale)",
                ),
                *mixed,
            ]
        )
    return tr


def checked_peers(peers: Sequence[str] | None) -> tuple[str, ...]:
    """``peers`` in the report's order (:data:`~labrig.analysis.baselines.KINDS`), each once
    (``None``: all of them); ``ValueError`` naming an unknown one and the valid names."""
    if peers is None:
        return KINDS
    # one name, not its letters; an iterator read once
    peers = [peers] if isinstance(peers, str) else list(peers)
    unknown = [p for p in peers if p not in KINDS]
    if unknown:
        raise ValueError(
            f"unknown peer {', '.join(map(repr, unknown))}: choose from {', '.join(KINDS)} "
            "(none: an empty list)"
        )
    return tuple(k for k in KINDS if k in peers)


def fit_report_models(
    setup: Setup,
    doc: dict[str, Any] | None,
    params_file: Path | None,
    method: str,
    heldout: bool,
    progress: Progress,
    fit: FitResult | None = None,
    peers: Sequence[str] | None = None,
) -> FittedModels:
    """Our model (fitted now, or from the ``labrig fit`` output ``doc`` read from
    ``params_file``, or ``fit`` made on this setup already) and the baselines ``peers``, fitted
    on the same records; a baseline that cannot be fitted is reported as such (its ``note``)."""
    t0 = time.perf_counter()
    peers = checked_peers(peers)
    if doc is None or params_file is None:
        fitted = _fitted_now(setup, method, heldout, progress, fit)
    else:
        fitted = _from_file(setup, doc, params_file, heldout, progress, peers)
    if not peers:
        fitted.notes.append("no peers fitted (peers: none)")
    for kind in peers:
        try:
            if fitted.peers_setup is not None:
                fitted.models[kind] = _peers_elsewhere(setup, fitted.peers_setup, kind, progress)
                continue
            b = fit_base(setup, kind, heldout, progress)
        except AnalysisError as e:
            fitted.models[kind] = Fitted(kind, None, note=str(e))
            continue
        bj = b.to_json()
        fitted.models[kind] = Fitted(
            kind,
            b.predictions,
            b.heldout_per_entry,
            bj["heldout_nrmse_pct"],
            bj["params"],
            method=kind,
        )
    fitted.elapsed_s = time.perf_counter() - t0
    return fitted


def provenance(setup: Setup) -> Provenance:
    """Where the data came from, as the run file records it."""
    run = setup.run
    return Provenance(
        run_file=str(setup.path),
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


def report_data(setup: Setup, fitted: FittedModels, heldout: bool, from_file: bool) -> ReportData:
    """The report's content (:func:`labrig.report.data.build_report`) for the fitted models."""
    notes = list(setup.notes) + fitted.notes
    if not heldout:
        notes.append("held-out NRMSE not computed (--no-heldout)")
    elif len(setup.scored) < 2:
        notes.append("held-out NRMSE needs two scored entries or more")
    run = setup.run
    scored = setup.scored_records
    peers = any(k != "dynamic" for k in fitted.models)
    if from_file and not peers:
        fit_time = "leave-one-out fits of our model" if heldout else "nothing fitted"
    else:
        what = "baselines" if from_file else ("model and baselines" if peers else "model")
        fit_time = what + (", with leave-one-out" if heldout else "")
    if setup.imported or not run.protocol_name:
        title = f"Model versus measurement: {setup.path.name} (imported data)"
    else:
        title = f"Model versus measurement: {run.protocol_name}"
    settings = {
        "entries": setup.scored,
        "chain": setup.chain,
        "offset": setup.offset,
        "params_source": fitted.source,
        "comparison": fitted.caveat or "",
        "in_sample": fitted.in_sample,
        "fit_time": f"{fitted.elapsed_s:.1f} s ({fit_time})",
    }
    return build_report(
        title,
        scored,
        fitted.models,
        setup.warmup_s,
        provenance(setup),
        settings,
        notes,
        noise_floor(scored, fitted.models["dynamic"].predictions or {}, setup.warmup_s),
        datetime.now().astimezone().isoformat(timespec="seconds"),
        __version__,
    )


def render_page(setup: Setup, data: ReportData) -> str:
    """The figures and the HTML page of ``data``."""
    from labrig.report.control_section import control_context
    from labrig.report.html import render
    from labrig.report.plots import EntryFigures, frequency_figure

    models = data.models
    unit = strain_unit(setup.scored_records)
    noise = data.noise_floor.noise_ue if data.noise_floor else None
    dyn = models["dynamic"].predictions or {}
    pngs = {}
    entry_figure = EntryFigures()  # one figure, emptied from entry to entry
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
    return render(data, freq, pngs, control_context(list(setup.records)))


def metrics_table(setup: Setup, data: ReportData) -> dict[str, Any]:
    """``labrig report --json``: the metrics of every scored entry and model
    (:func:`labrig.report.data.metrics_json`), with the control metrics of the strain-command
    entries, as strict JSON (undefined values ``null``; no figure module imported: matplotlib
    costs about 0.6 s of CPU to import, and ``--json`` alone draws nothing)."""
    from labrig.control.metrics import control_metrics

    table = metrics_json(data)
    for name, m in control_metrics(list(setup.records)).items():
        table.setdefault(name, {}).update(m)
    return json_safe(table)


def build_run_report(
    path: Path,
    params_file: Path | None = None,
    *,
    entries: list[str] | None = None,
    warmup_s: float | None = None,
    offset: bool | None = None,
    method: str = "global",
    heldout: bool = True,
    ui: CommandUI | None = None,
    page: bool = True,
    fit: FitOutcome | None = None,
    peers: Sequence[str] | None = None,
) -> BuiltReport:
    """``labrig report``: the report of the run file ``path`` (module docstring); our model's
    parameters from ``params_file`` (``labrig fit`` output) when given, else fitted now.
    ``page=False``: the metrics only (no figures drawn; ``BuiltReport.page`` is ``""``).
    ``peers``: the baselines fitted beside our model (default ``None``: all of
    :data:`~labrig.analysis.baselines.KINDS`; ``()``: none).
    ``fit``: ``labrig fit`` of the same file with the same settings, already made (``batch
    report``): its records and fit are used, so the file is read and our model fitted once."""
    ui = ui or QuietUI()
    peers = checked_peers(peers)  # before any work
    doc = read_fit_output(params_file) if params_file is not None else None
    if fit is not None and not isinstance(fit.result, FitResult):
        raise ValueError("report takes a fit of our model (not a baseline or effects fit)")
    setup = fit.setup if fit is not None else prepare(path, entries, warmup_s, offset)
    ui.announce(setup)
    # one BLAS thread throughout (the fits already set it inside): the metrics, the noise floor
    # and the figures' arrays are small, and OpenBLAS's idle threads cost CPU on a busy machine
    with single_thread_blas():
        with ui.fitting() as progress:
            ours = fit.result if fit is not None else None
            fitted = fit_report_models(
                setup, doc, params_file, method, heldout, progress, ours, peers
            )
        data = report_data(setup, fitted, heldout, doc is not None)
        html = ""
        if page:
            with ui.busy("drawing the figures"):
                html = render_page(setup, data)
        metrics = metrics_table(setup, data)
    return BuiltReport(setup, html, metrics, fitted.caveat)
