"""The report as one self-contained HTML file: inline CSS, figures as base64 PNG, no scripts and
no external resources, so it opens offline and can be mailed or archived as it is.

:func:`render` fills the template ``templates/report.html.j2`` (:mod:`labrig.report.templating`)
with :func:`report_context`: the numbers of a :class:`~labrig.report.data.ReportData` formatted
for the page, and the PNG figures. The template escapes every text (autoescape).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from labrig.analysis.records import strain_unit
from labrig.report.data import (
    METRICS,
    MODEL_LABELS,
    MODEL_SHORT,
    PARAM_ROWS,
    PEER_NAMES,
    EntryView,
    Fitted,
    ReportData,
)
from labrig.report.templating import render as render_template
from labrig.report.templating import sig

__all__ = ["fmt", "nrmse_scope", "peers_and_rate", "render", "report_context"]

#: the signed metrics, whose mean is of their absolute values
SIGNED = ("loop_area_error_pct", "strain_shift_error_ue")


def fmt(value: Any, metric: str = "", signed: bool = True) -> str | None:
    """A metric value for a table cell (``None`` when undefined: the page shows ``—``); the
    signed errors with their sign unless ``signed=False`` (means of absolute values)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return None
    v = float(value)
    if metric in SIGNED:
        sign = "+" if signed else ""
        return f"{v:{sign}.1f}" if abs(v) >= 0.95 else f"{v:{sign}.2f}"
    if metric == "max_error_ue":
        return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
    return f"{v:.3g}"


def _best(values: list[Any]) -> int | None:
    """Index of the smallest |value| (None when fewer than two are defined)."""
    ok = [(abs(float(v)), i) for i, v in enumerate(values) if v is not None and math.isfinite(v)]
    if len(ok) < 2:
        return None
    return min(ok)[1]


def _cells(keys: list[str], values: list[Any], metric: str, signed: bool) -> list[dict]:
    """One metric's cells across the models: the first of the group, the best, ours."""
    best = _best(values)
    out = []
    for i, (k, v) in enumerate(zip(keys, values, strict=True)):
        cls = ["num"] + (["first"] if i == 0 else []) + (["best"] if i == best else [])
        cls += ["ours"] if k == "dynamic" else []
        out.append({"cls": " ".join(cls), "text": fmt(v, metric, signed)})
    return out


def nrmse_scope(data: ReportData) -> tuple[str, str, set[str]]:
    """What the NRMSE column is: in-sample, out-of-sample, or by entry.

    Parameters
    ----------
    data : ReportData
        The report; ``data.settings["in_sample"]`` names its entries every model was
        identified on (``None``: that differs between the models, or is not known; absent:
        nothing is said).

    Returns
    -------
    tuple
        The column's heading, a sentence for the table's legend, and the entries to mark as
        in-sample (only when the column mixes in- and out-of-sample entries).
    """
    names = [e.name for e in data.entries]
    if "in_sample" not in data.settings:  # a report made without saying
        return "NRMSE", "", set()
    seen = data.settings["in_sample"]
    if seen is None:
        why = (
            "The peers' NRMSE is in-sample (fitted on these records); ours is as “What this "
            "page compares” says."
            if data.settings.get("comparison")
            else "In-sample or not: the parameter file does not say which records our model was "
            "identified on."
        )
        return "NRMSE", why, set()
    seen_set = set(seen) & set(names)
    if seen_set == set(names):
        return "NRMSE in-sample", "In-sample: every model was identified on these entries.", set()
    if not seen_set:
        return (
            "NRMSE out-of-sample",
            "Out-of-sample: every model was identified on other records and predicts these.",
            set(),
        )
    return (
        "NRMSE",
        "In-sample on the entries marked “(training)”, which every model was identified on; "
        "out-of-sample on the others.",
        seen_set,
    )


def _label(data: ReportData, metric: str, label: str) -> str:
    """A metric's heading (the NRMSE's says whether it is in-sample: :func:`nrmse_scope`)."""
    return nrmse_scope(data)[0] if metric == "nrmse_pct" else label


def summary_context(data: ReportData) -> dict[str, Any]:
    """The summary table: every model's mean of every metric."""
    head = [
        {
            "label": _label(data, metric, label),
            "unit": unit,
            "stat": "mean |.|" if metric in SIGNED else "mean",
        }
        for metric, label, unit in METRICS
    ]
    rows = []
    for k, fm in data.models.items():
        ours = k == "dynamic"
        cells = [
            {"cls": "num ours" if ours else "num", "text": fmt(data.mean(k, m), m, signed=False)}
            for m, _, _ in METRICS
        ]
        rows.append(
            {"label": fm.label, "ours": ours, "not_fitted": fm.predictions is None, "cells": cells}
        )
    return {"head": head, "rows": rows}


def metrics_context(data: ReportData) -> dict[str, Any]:
    """The metrics table: per entry and model, then the means."""
    keys = list(data.models)
    _, scope, marked = nrmse_scope(data)
    rows = []
    for e in data.entries:
        cells = []
        for metric, _, _ in METRICS:
            values = [e.metrics.get(k, {}).get(metric) for k in keys]
            cells += _cells(keys, values, metric, True)
        rows.append(
            {
                "name": e.name,
                "training": e.name in marked,
                "frequency": sig(e.frequency_hz, 3) if e.frequency_hz else "—",
                "amplitude": f"{e.amplitude_V:g}",
                "cells": cells,
            }
        )
    mean = []
    for metric, _, _ in METRICS:
        mean += _cells(keys, [data.mean(k, metric) for k in keys], metric, False)
    models = [
        {
            "cls": "ours" if k == "dynamic" else "",
            "title": MODEL_LABELS.get(k, k),
            "short": MODEL_SHORT.get(k, k),
        }
        for _ in METRICS
        for k in keys
    ]
    return {
        "groups": [
            {"label": _label(data, metric, label), "unit": unit, "span": len(keys)}
            for metric, label, unit in METRICS
        ],
        "scope": scope,
        "models": models,
        "rows": rows,
        "mean": mean,
        "legend": ", ".join(f"{MODEL_SHORT.get(k, k)} = {MODEL_LABELS.get(k, k)}" for k in keys),
        "compared": len(keys) > 1,  # a best in bold
    }


def _any_value(v: Any) -> str:
    if isinstance(v, float):
        return sig(v, 4)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_any_value(x) for x in v) + "]"
    return str(v)


def params_context(data: ReportData) -> dict[str, Any] | None:
    """Our model's parameters with uncertainties, their correlation, the baselines' parameters
    (``None`` when our model was not fitted)."""
    from labrig.analysis.identifiability import RULE, loop_coordinates, unidentifiable

    fm = data.models.get("dynamic")
    if fm is None or not fm.params:
        return None
    flagged = fm.unidentifiable
    if flagged is None:
        flagged = unidentifiable(fm.params, fm.uncertainty, fm.correlation)
    rows = []
    for name, symbol, unit in PARAM_ROWS:
        v, u = fm.params.get(name), fm.uncertainty.get(name)
        held = u is None and name not in flagged  # no uncertainty: fixed, or not determined
        rel = f"{100 * u / abs(v):.2g} %" if (u is not None and v) else "fixed" if held else "—"
        value = sig(v, 5)
        if name in flagged:
            value = f"unidentifiable (fitted {value}; {flagged[name]})"
        rows.append(
            {
                "symbol": symbol,
                "field": name,
                "value": value,
                "sd": sig(u, 2) if u is not None else "—",
                "relative": rel,
                "unit": unit,
                "flagged": name in flagged,
            }
        )
    loop = loop_coordinates(fm.params, fm.uncertainty, fm.correlation, fm.loop_span_V)
    loop_rows = []
    if loop is not None:
        for key, symbol, unit in (
            ("loop_width_ue", "W", "ue"),
            ("loop_curvature", "q = span / Vc", ""),
        ):
            v, u = loop[key], loop[f"{key}_sd"]
            loop_rows.append(
                {
                    "symbol": symbol,
                    "field": key,
                    "value": sig(v, 5),
                    "sd": sig(u, 2) if u is not None else "—",
                    "relative": f"{100 * u / abs(v):.2g} %" if (u is not None and v) else "—",
                    "unit": unit,
                    "flagged": False,
                }
            )
    correlation = None
    if fm.correlation:
        names = list(fm.correlation)
        symbols = {n: s for n, s, _ in PARAM_ROWS}
        correlation = {
            "symbols": [symbols.get(n, n) for n in names],
            "rows": [
                {
                    "symbol": symbols.get(a, a),
                    "cells": [_correlation_cell(fm, a, b) for b in names],
                }
                for a in names
            ],
        }
    baselines = [
        {
            "label": b.label,
            "text": ", ".join(f"{k} = {_any_value(v)}" for k, v in b.params.items()),
        }
        for k, b in data.models.items()
        if k != "dynamic" and b.params
    ]
    return {
        "rows": rows,
        "loop_rows": loop_rows,
        "loop_span": sig(loop["span_V"], 4) if loop is not None else "",
        "rule": RULE,
        "flagged": bool(flagged),
        "shape": str(fm.params.get("shape", "")),
        "memory": str(fm.params.get("memory", "")),
        "method": fm.method or "—",
        "correlation": correlation,
        "baselines": baselines,
    }


def _correlation_cell(fm: Fitted, a: str, b: str) -> dict[str, Any]:
    c = fm.correlation[a].get(b)
    return {
        "text": "—" if c is None else f"{c:+.2f}",
        "strong": c is not None and a != b and abs(c) > 0.9,
    }


def settings_items(data: ReportData) -> list[tuple[str, str]]:
    """How the report fitted and scored (shown under the parameters)."""
    s = data.settings
    items = [
        ("entries scored", ", ".join(s.get("entries", []))),
        (
            "simulation",
            "chained as one run (each entry after its predecessors and their rests)"
            if s.get("chain")
            else "each entry on its own, from rest",
        ),
        ("warm-up", f"{data.warmup_s:g} s simulated but not scored" if data.warmup_s else "none"),
        ("offset", "one constant strain offset per entry fitted" if s.get("offset") else "none"),
        ("parameters", s.get("params_source", "")),
        ("fit time", s.get("fit_time", "")),
    ]
    return [(k, str(v)) for k, v in items if v]


def card(e: EntryView, data: ReportData, png: bytes | None) -> dict[str, Any]:
    """An entry's card: its drive, every model's NRMSE and its figure."""
    drive = [e.kind] if e.kind else []
    if e.frequency_hz:
        drive.append(f"{sig(e.frequency_hz, 3)} Hz")
    drive.append(f"{e.amplitude_V:g} V")
    drive.append(f"{e.record.duration_s:.3g} s at {e.record.rate_hz:g} Hz")
    scores = []
    for k in data.models:
        m = e.metrics.get(k)
        if not m:
            continue
        held = m.get("heldout_nrmse_pct")
        h = f", held-out {held:.3g} %" if held is not None else ""
        scores.append(f"{MODEL_SHORT.get(k, k)} {m['nrmse_pct']:.3g} %{h}")
    return {
        "anchor": "entry-" + "".join(c if c.isalnum() else "-" for c in e.name),
        "name": e.name,
        "drive": ", ".join(drive),
        "scores": "; ".join(scores),
        "png": png,
    }


def provenance_context(data: ReportData) -> dict[str, Any]:
    """Where the data came from, as the run file records it."""
    p = data.provenance
    items = [
        ("run file", p.run_file),
        ("run status", p.status + (f" ({p.reason})" if p.reason else "")),
        ("recorded", f"{p.start_time} to {p.end_time}" if p.start_time else ""),
        ("protocol", f"{p.protocol_name}" + (f" ({p.protocol_file})" if p.protocol_file else "")),
        ("rig", p.rig_file or ("built-in simulated rig" if p.instrument.get("simulated") else "")),
        ("software (recording)", f"labrig {p.software_version}" if p.software_version else ""),
        ("software (this report)", f"labrig {data.labrig_version}"),
        ("seed", "" if p.seed is None else str(p.seed)),
        ("entries in the file", str(p.n_entries)),
        ("report generated", data.generated),
    ]
    return {
        "fields": [(k, v) for k, v in items if v],
        "protocol_text": p.protocol_text,
        "rig_text": p.rig_text,
        "instrument": json.dumps(p.instrument, indent=2, default=str) if p.instrument else "",
    }


def peers_and_rate(models: Mapping[str, Any]) -> str:
    """The frequency figure's sentence on how the peers shown depend on the rate.

    Parameters
    ----------
    models : mapping
        The report's models by kind (``dynamic``, ``prandtl_ishlinskii``, ...).

    Returns
    -------
    str
        The sentence, or ``""`` when no peer is shown.
    """
    fixed = [PEER_NAMES[k] for k in ("prandtl_ishlinskii", "bouc_wen") if k in models]
    parts = []
    if fixed:
        one = len(fixed) == 1
        parts.append(
            f"{' and '.join(fixed)} {'is' if one else 'are'} rate-independent: "
            f"{'its' if one else 'their'} loops do not change with frequency"
        )
    if "sindy" in models:
        parts.append("SINDy's sparse ODE does depend on the rate")
    return "; ".join(parts) + "." if parts else ""


def report_context(
    data: ReportData,
    frequency_png: bytes | None,
    entry_pngs: Mapping[str, bytes | None],
    control: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Everything ``report.html.j2`` shows (``control``: the compensation-control section of
    :func:`labrig.report.control_section.control_context`, or ``None``)."""
    p = data.provenance
    fm = data.models.get("dynamic")
    n = len(data.entries)
    sub = f"{p.run_file} · {n} {'entry' if n == 1 else 'entries'} scored"
    if fm is not None and fm.method:
        sub += f" · {fm.method} fit"
    nf = data.noise_floor
    noise_floor = None
    if nf is not None:
        noise_floor = {
            "nrmse": f"{nf.nrmse_pct:.3g}",
            "noise": f"{nf.noise_ue:.3g}",
            "unit": strain_unit(e.record for e in data.entries),
            "source": nf.source,
        }
    return {
        "version": data.labrig_version,
        "title": data.title,
        "sub": sub,
        "nav": [
            ("summary", "Summary"),
            ("metrics", "Metrics"),
            ("frequency", "Frequency dependence"),
            ("parameters", "Parameters"),
            ("entries", "Entries"),
            ("provenance", "Provenance"),
        ],
        "summary": summary_context(data),
        "comparison": str(data.settings.get("comparison") or ""),
        "noise_floor": noise_floor,
        "notes": list(data.notes),
        "metrics": metrics_context(data),
        "frequency_png": frequency_png,
        "peers_and_rate": peers_and_rate(data.models),
        "params": params_context(data),
        "settings": settings_items(data),
        "control": control,
        "cards": [card(e, data, entry_pngs.get(e.name)) for e in data.entries],
        "provenance": provenance_context(data),
    }


def render(
    data: ReportData,
    frequency_png: bytes | None,
    entry_pngs: Mapping[str, bytes | None],
    control: Mapping[str, Any] | None = None,
) -> str:
    """The whole page."""
    return render_template(
        "report.html.j2", **report_context(data, frequency_png, entry_pngs, control)
    )
