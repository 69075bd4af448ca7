"""The report as one self-contained HTML file: inline CSS, figures as base64 PNG, no scripts and
no external resources, so it opens offline and can be mailed or archived as it is.

:func:`render` turns a :class:`~labrig.report.data.ReportData` (and the PNG figures) into the
page; every text from the run file is escaped.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Mapping
from html import escape
from typing import Any

from labrig.report.data import (
    METRICS,
    MODEL_LABELS,
    MODEL_SHORT,
    PARAM_ROWS,
    EntryView,
    Fitted,
    ReportData,
)

CSS = """
:root { --ink: #1d232a; --muted: #5b6470; --line: #d5dae0; --band: #f4f6f8; --ours: #b8302a; }
* { box-sizing: border-box; }
body { font-family: -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
  color: var(--ink); margin: 0; background: #fff; line-height: 1.45; font-size: 14px; }
main { max-width: 1180px; margin: 0 auto; padding: 24px 28px 60px; }
h1 { font-size: 24px; margin: 0 0 4px; }
h2 { font-size: 18px; margin: 34px 0 10px; padding-bottom: 4px;
  border-bottom: 2px solid var(--ink); }
h3 { font-size: 15px; margin: 0 0 2px; }
.sub { color: var(--muted); margin: 0 0 14px; }
nav { font-size: 13px; margin: 10px 0 0; color: var(--muted); }
nav a { color: var(--ink); margin-right: 14px; }
table { border-collapse: collapse; font-size: 13px; margin: 6px 0 10px; }
th, td { padding: 4px 9px; border-bottom: 1px solid var(--line); }
th { background: var(--band); font-weight: 600; text-align: center; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.name { text-align: left; white-space: nowrap; }
tr.mean td { border-top: 2px solid var(--ink); font-weight: 600; }
th.group { border-left: 2px solid #fff; }
td.first { border-left: 1px solid var(--line); }
td.best { font-weight: 700; }
td.ours, th.ours { color: var(--ours); }
.na { color: #9aa3ad; }
.notes { background: #fff8e6; border-left: 4px solid #e0a800; padding: 8px 14px; margin: 10px 0; }
.notes ul { margin: 4px 0; padding-left: 18px; }
.ok { background: #eef7ee; border-left: 4px solid #3c8d40; padding: 8px 14px; margin: 10px 0; }
.card { border: 1px solid var(--line); border-radius: 6px; padding: 12px 14px; margin: 14px 0; }
.card .meta { color: var(--muted); font-size: 13px; margin-bottom: 6px; }
img { max-width: 100%; height: auto; display: block; }
figure { margin: 8px 0 0; }
figcaption { color: var(--muted); font-size: 12.5px; margin-top: 4px; }
dl.prov { display: grid; grid-template-columns: max-content 1fr; gap: 3px 16px; font-size: 13px; }
dl.prov dt { color: var(--muted); }
dl.prov dd { margin: 0; overflow-wrap: anywhere; }
details { margin: 6px 0; }
summary { cursor: pointer; color: var(--ink); font-weight: 600; font-size: 13px; }
pre { background: var(--band); padding: 10px; overflow-x: auto; font-size: 12px;
  border: 1px solid var(--line); border-radius: 4px; max-height: 420px; }
.small { font-size: 12.5px; color: var(--muted); }
"""


def data_uri(png: bytes) -> str:
    """The PNG ``png`` as a ``data:`` URI."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def img(png: bytes | None, alt: str) -> str:
    """An ``<img>`` of the PNG ``png`` inlined as a data URI (empty without a figure)."""
    if png is None:
        return ""
    return f'<img src="{data_uri(png)}" alt="{escape(alt)}">'


def fmt(value: Any, metric: str = "", signed: bool = True) -> str:
    """A metric value for a table cell (``—`` when undefined); the signed errors with their
    sign unless ``signed=False`` (means of absolute values)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '<span class="na" title="not computed">—</span>'
    v = float(value)
    if metric in ("loop_area_error_pct", "strain_shift_error_ue"):
        sign = "+" if signed else ""
        return f"{v:{sign}.1f}" if abs(v) >= 0.95 else f"{v:{sign}.2f}"
    if metric == "max_error_ue":
        return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
    return f"{v:.3g}"


def _sig(v: float | None, digits: int = 4) -> str:
    if v is None or not math.isfinite(v):
        return "—"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


def _best(values: list[Any]) -> int | None:
    """Index of the smallest |value| (None when fewer than two are defined)."""
    ok = [(abs(float(v)), i) for i, v in enumerate(values) if v is not None and math.isfinite(v)]
    if len(ok) < 2:
        return None
    return min(ok)[1]


# -- sections ------------------------------------------------------------------------------------


def _summary(data: ReportData) -> str:
    keys = list(data.models)
    rows = []
    for k in keys:
        fm = data.models[k]
        cls = ' class="ours"' if k == "dynamic" else ""
        cells = []
        for metric, _, _ in METRICS:
            v = data.mean(k, metric)
            cells.append(f'<td class="num"{cls}>{fmt(v, metric, signed=False)}</td>')
        status = "" if fm.predictions is not None else ' <span class="na">(not fitted)</span>'
        rows.append(
            f'<tr><td class="name"{cls}>{escape(fm.label)}{status}</td>{"".join(cells)}</tr>'
        )
    head = "".join(
        f"<th>{escape(label)}<br><span class='small'>"
        f"{'mean |.|' if metric in ('loop_area_error_pct', 'strain_shift_error_ue') else 'mean'}"
        f" ({escape(unit)})</span></th>"
        for metric, label, unit in METRICS
    )
    out = [f"<table><tr><th>model</th>{head}</tr>{''.join(rows)}</table>"]
    nf = data.noise_floor
    if nf is not None:
        out.append(
            '<p class="small">Noise floor (NRMSE of a perfect model): '
            f"<b>{nf.nrmse_pct:.3g} %</b> (noise {nf.noise_ue:.3g} {escape(_strain_unit(data))} "
            f"rms, from {escape(nf.source)}).</p>"
        )
    else:
        out.append(
            '<p class="small">Noise floor: unknown (no noise level in the run file and '
            "no stretch of constant voltage to estimate it from).</p>"
        )
    return "\n".join(out)


def _notes(data: ReportData) -> str:
    if not data.notes:
        return '<div class="ok">Every metric and figure could be computed.</div>'
    items = "".join(f"<li>{escape(n)}</li>" for n in data.notes)
    return f'<div class="notes"><b>Notes</b><ul>{items}</ul></div>'


def _metrics_table(data: ReportData) -> str:
    keys = list(data.models)
    head1 = "<th rowspan='2'>entry</th><th rowspan='2'>f (Hz)</th><th rowspan='2'>A (V)</th>"
    head1 += "".join(
        f"<th class='group' colspan='{len(keys)}'>{escape(label)} ({escape(unit)})</th>"
        for _, label, unit in METRICS
    )
    head2 = "".join(
        f"<th class='{'ours' if k == 'dynamic' else ''}' title='{escape(MODEL_LABELS.get(k, k))}'>"
        f"{escape(MODEL_SHORT.get(k, k))}</th>"
        for _ in METRICS
        for k in keys
    )
    body = []
    for e in data.entries:
        cells = [
            f'<td class="name">{escape(e.name)}</td>',
            f'<td class="num">{_sig(e.frequency_hz, 3) if e.frequency_hz else "—"}</td>',
            f'<td class="num">{e.amplitude_V:g}</td>',
        ]
        for metric, _, _ in METRICS:
            vals = [e.metrics.get(k, {}).get(metric) for k in keys]
            best = _best(vals)
            for i, (k, v) in enumerate(zip(keys, vals, strict=True)):
                cls = ["num"]
                if i == 0:
                    cls.append("first")
                if i == best:
                    cls.append("best")
                if k == "dynamic":
                    cls.append("ours")
                cells.append(f'<td class="{" ".join(cls)}">{fmt(v, metric)}</td>')
        body.append(f"<tr>{''.join(cells)}</tr>")
    mean = ['<td class="name">mean</td><td></td><td></td>']
    for metric, _, _ in METRICS:
        vals = [data.mean(k, metric) for k in keys]
        best = _best(vals)
        for i, (k, v) in enumerate(zip(keys, vals, strict=True)):
            cls = ["num"] + (["first"] if i == 0 else []) + (["best"] if i == best else [])
            cls += ["ours"] if k == "dynamic" else []
            mean.append(f'<td class="{" ".join(cls)}">{fmt(v, metric, signed=False)}</td>')
    body.append(f'<tr class="mean">{"".join(mean)}</tr>')
    legend = ", ".join(f"{MODEL_SHORT.get(k, k)} = {MODEL_LABELS.get(k, k)}" for k in keys)
    return (
        f"<table><tr>{head1}</tr><tr>{head2}</tr>{''.join(body)}</table>"
        f'<p class="small">{escape(legend)}. Bold: the best of the models. NRMSE = 100 '
        "RMS(measured − predicted) / (max − min of measured), over the scored samples; held-out: "
        "predicted by a fit without that entry (leave-one-entry-out). Loop area and strain at "
        "zero voltage over the last full period; errors are predicted − measured (loop area "
        "relative to the measured one; the mean row averages |error|).</p>"
    )


def _params_section(data: ReportData) -> str:
    fm = data.models.get("dynamic")
    if fm is None or not fm.params:
        return "<p>No parameters (the model was not fitted).</p>"
    rows = []
    for name, sym, unit in PARAM_ROWS:
        v = fm.params.get(name)
        u = fm.uncertainty.get(name)
        rel = (
            f"{100 * u / abs(v):.2g} %" if (u is not None and v) else "fixed" if u is None else "—"
        )
        sd = _sig(u, 2) if u is not None else "—"
        rows.append(
            f'<tr><td class="name">{escape(sym)}</td>'
            f'<td class="name"><code>{escape(name)}</code></td>'
            f'<td class="num">{_sig(v, 5)}</td><td class="num">{sd}</td>'
            f'<td class="num">{rel}</td><td class="name">{escape(unit)}</td></tr>'
        )
    shape = escape(str(fm.params.get("shape", "")))
    memory = escape(str(fm.params.get("memory", "")))
    out = [
        "<table><tr><th>symbol</th><th>field</th><th>value</th><th>± 1σ</th><th>relative</th>"
        f"<th>unit</th></tr>{''.join(rows)}</table>",
        f'<p class="small">Hysteretic shape: {shape}; memory: {memory}. '
        f"Method: {escape(fm.method or '—')}. "
        "Uncertainties: one standard deviation from the Jacobian at the optimum (per-entry "
        "sandwich estimate); residuals of a free-run model are correlated in time, so treat them "
        "as lower bounds. “fixed”: not identified from these data.</p>",
    ]
    if fm.correlation:
        names = list(fm.correlation)
        sym = dict((n, s) for n, s, _ in PARAM_ROWS)
        head = "".join(f"<th>{escape(sym.get(n, n))}</th>" for n in names)
        body = []
        for a in names:
            cells = []
            for b in names:
                c = fm.correlation[a].get(b)
                strong = c is not None and a != b and abs(c) > 0.9
                style = ' style="font-weight:700"' if strong else ""
                cells.append(f'<td class="num"{style}>{"—" if c is None else f"{c:+.2f}"}</td>')
            body.append(f"<tr><th>{escape(sym.get(a, a))}</th>{''.join(cells)}</tr>")
        out.append(
            "<details><summary>Correlation of the parameter estimates</summary>"
            f"<table><tr><th></th>{head}</tr>{''.join(body)}</table>"
            '<p class="small">Bold: |correlation| above 0.9.</p></details>'
        )
    base = [data.models[k] for k in data.models if k != "dynamic"]
    if base:
        parts = []
        for b in base:
            if not b.params:
                continue
            items = ", ".join(f"{escape(k)} = {escape(_fmt_any(v))}" for k, v in b.params.items())
            parts.append(f"<li><b>{escape(b.label)}</b>: {items}</li>")
        if parts:
            out.append(
                "<details><summary>Baseline parameters</summary>"
                f"<ul class='small'>{''.join(parts)}</ul></details>"
            )
    return "\n".join(out)


def _fmt_any(v: Any) -> str:
    if isinstance(v, float):
        return _sig(v, 4)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_fmt_any(x) for x in v) + "]"
    return str(v)


def _settings(data: ReportData) -> str:
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
    return (
        "<dl class='prov'>"
        + "".join(f"<dt>{escape(k)}</dt><dd>{escape(str(v))}</dd>" for k, v in items if v)
        + "</dl>"
    )


def _entry_card(e: EntryView, data: ReportData, png: bytes | None) -> str:
    drive = []
    if e.kind:
        drive.append(e.kind)
    if e.frequency_hz:
        drive.append(f"{_sig(e.frequency_hz, 3)} Hz")
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
    anchor = "entry-" + "".join(c if c.isalnum() else "-" for c in e.name)
    return (
        f'<div class="card" id="{escape(anchor)}"><h3>{escape(e.name)}</h3>'
        f'<div class="meta">{escape(", ".join(drive))} · NRMSE {escape("; ".join(scores))}</div>'
        f"<figure>{img(png, 'loop and time series of ' + e.name)}</figure></div>"
    )


def _provenance(data: ReportData) -> str:
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
    out = ["<dl class='prov'>"]
    out += [f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in items if v]
    out.append("</dl>")
    if p.protocol_text:
        text = escape(p.protocol_text)
        out.append(f"<details><summary>Protocol file</summary><pre>{text}</pre></details>")
    if p.rig_text:
        out.append(f"<details><summary>Rig file</summary><pre>{escape(p.rig_text)}</pre></details>")
    if p.instrument:
        txt = json.dumps(p.instrument, indent=2, default=str)
        out.append(
            f"<details><summary>Instrument description</summary><pre>{escape(txt)}</pre></details>"
        )
    return "\n".join(out)


def _strain_unit(data: ReportData) -> str:
    for e in data.entries:
        u = e.record.meta.get("units", {}).get("strain")
        if u:
            return str(u)
    return "ue"


def render(
    data: ReportData,
    frequency_png: bytes | None,
    entry_pngs: Mapping[str, bytes | None],
    extra_html: str = "",
) -> str:
    """The whole page."""
    p = data.provenance
    fm: Fitted | None = data.models.get("dynamic")
    n = len(data.entries)
    sub = f"{escape(p.run_file)} · {n} {'entry' if n == 1 else 'entries'} scored"
    if fm is not None and fm.method:
        sub += f" · {escape(fm.method)} fit"
    nav = "".join(
        f'<a href="#{a}">{t}</a>'
        for a, t in (
            ("summary", "Summary"),
            ("metrics", "Metrics"),
            ("frequency", "Frequency dependence"),
            ("parameters", "Parameters"),
            ("entries", "Entries"),
            ("provenance", "Provenance"),
        )
    )
    if frequency_png is not None:
        freq = (
            f"<figure>{img(frequency_png, 'loop area and strain shift versus frequency')}"
            "<figcaption>Measured (circles) and predicted (lines) over the last full period of "
            "each periodic entry, one colour per drive amplitude (cf. the paper's Fig. 10). "
            "Prandtl-Ishlinskii and Bouc-Wen are rate-independent: their loops do not change with "
            "frequency; SINDy's sparse ODE does depend on the rate."
            "</figcaption></figure>"
        )
    else:
        freq = (
            "<p class='small'>Not drawn: it needs periodic entries at two frequencies or more "
            "(the metrics table gives loop area and strain-shift errors per entry).</p>"
        )
    cards = "\n".join(_entry_card(e, data, entry_pngs.get(e.name)) for e in data.entries)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="labrig {escape(data.labrig_version)}">
<title>{escape(data.title)}</title>
<style>{CSS}</style></head>
<body><main>
<h1>{escape(data.title)}</h1>
<p class="sub">{sub}</p>
<nav>{nav}</nav>
<h2 id="summary">Summary</h2>
{_summary(data)}
{_notes(data)}
<h2 id="metrics">Metrics per entry</h2>
{_metrics_table(data)}
<h2 id="frequency">Frequency dependence</h2>
{freq}
<h2 id="parameters">Identified parameters</h2>
{_params_section(data)}
{_settings(data)}
{extra_html}
<h2 id="entries">Entries: model versus measurement</h2>
<p class="small">Left: voltage-strain loop, measured (dark) and our model (red) over the scored
samples (cf. the paper's Fig. 9). Right: strain in time and the residual (measured − model)
underneath (cf. the paper's Fig. 12); dashed lines at ±1σ of the noise when known; a grey area is
the warm-up.</p>
{cards}
<h2 id="provenance">Provenance</h2>
{_provenance(data)}
</main></body></html>
"""
