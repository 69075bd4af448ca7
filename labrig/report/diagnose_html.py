"""``DIR/diagnosis.html``: the diagnosis as one self-contained HTML page (inline CSS, base64
PNG figures from matplotlib's Agg canvas, no scripts), in the style of ``labrig report`` (its
CSS and helpers from :mod:`labrig.report.html` and :mod:`labrig.report.plots`);
:func:`write_diagnosis` writes it beside ``diagnosis.json``.

Figures: per-entry residual before and after (time series), and the held-out NRMSE of every
candidate tried against the base model's.
"""

from __future__ import annotations

import json
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from labrig.analysis.diagnose import Diagnosis
from labrig.analysis.records import Record
from labrig.report.html import CSS, img
from labrig.report.plots import png

__all__ = ["render_diagnosis", "residual_figure", "write_diagnosis"]


def residual_figure(d: Diagnosis, records: list[Record]) -> Figure:
    """One panel per entry: the residual (measured - model) in time before and after the added
    effects, with its axes labelled."""
    recs = [r for r in records if r.name in d.predictions_before]
    n = len(recs)
    cols = 2
    rows = -(-n // cols)
    fig = Figure(figsize=(11, 2.2 * rows + 0.5))
    for k, r in enumerate(recs):
        ax = fig.add_subplot(rows, cols, k + 1)
        rb = r.strain_ue - d.predictions_before[r.name]
        ax.plot(r.time_s, rb, lw=0.6, color="0.55", label="before")
        if r.name in d.predictions_after:
            ra = r.strain_ue - d.predictions_after[r.name]
            ax.plot(r.time_s, ra, lw=0.6, color="tab:red", label="after")
        ax.set_title(r.name, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
        unit = r.meta.get("strain_units", "ue") if isinstance(r.meta, dict) else "ue"
        ax.set_ylabel(f"residual ({unit})", fontsize=8)
        ax.set_xlabel("time (s)", fontsize=8)
    fig.tight_layout()
    return fig


def _candidates_figure(d: Diagnosis) -> bytes | None:
    rows = [(c["effect"], c["heldout_nrmse_pct"]) for c in d.candidates]
    rows = [(n, v) for n, v in rows if v is not None]
    if not rows:
        return None
    fig = Figure(figsize=(7, 0.45 * len(rows) + 1.2))
    ax = fig.add_subplot(1, 1, 1)
    names = ["base model", *[n for n, _ in rows]]
    vals = [d.before["heldout_nrmse_pct"], *[v for _, v in rows]]
    added = {e["effect"] for e in d.effects_added}
    colors = ["0.5"] + ["tab:red" if n in added else "tab:blue" for n, _ in rows]
    y = np.arange(len(names))
    ax.barh(y, vals, color=colors)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("held-out NRMSE (%)", fontsize=8)
    ax.tick_params(labelsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    return png(fig)


def _num(v: Any) -> str:
    if v is None:
        return '<span class="na">-</span>'
    if isinstance(v, float):
        return f"{v:.4g}"
    return escape(str(v))


def render_diagnosis(d: Diagnosis, records: list[Record], title: str = "labrig diagnose") -> str:
    """The page (a string)."""
    h = []
    h.append(f"<!doctype html><html><head><meta charset='utf-8'><title>{escape(title)}</title>")
    h.append(f"<style>{CSS}</style></head><body><main>")
    h.append(f"<h1>{escape(title)}</h1>")
    box = "ok" if d.classification in ("explained", "consistent_with_noise") else "notes"
    h.append(f"<h2>Verdict</h2><div class='{box}'><p>{escape(d.verdict)}</p></div>")
    h.append("<h2>Error before and after</h2><table><tr><th>entry</th>")
    h.append("<th>NRMSE before (%)</th><th>NRMSE after (%)</th></tr>")
    for k, v in d.before["per_entry"].items():
        a = d.after["per_entry"].get(k)
        h.append(f"<tr><td class='name'>{escape(k)}</td><td class='num'>{_num(v)}</td>")
        h.append(f"<td class='num'>{_num(a)}</td></tr>")
    h.append(
        f"<tr class='mean'><td class='name'>mean</td><td class='num'>{_num(d.before['nrmse_pct'])}"
        f"</td><td class='num'>{_num(d.after['nrmse_pct'])}</td></tr>"
    )
    h.append(
        f"<tr><td class='name'>held-out (leave one entry out)</td>"
        f"<td class='num'>{_num(d.before['heldout_nrmse_pct'])}</td>"
        f"<td class='num'>{_num(d.after['heldout_nrmse_pct'])}</td></tr></table>"
    )
    h.append("<h2>Effects added</h2>")
    if not d.effects_added:
        h.append("<p>None.</p>")
    for e in d.effects_added:
        ps = ", ".join(f"{k} = {_num(v)}" for k, v in e["params"].items())
        h.append(
            f"<div class='card'><h3>{escape(e['effect'])}</h3><div class='meta'>{escape(ps)}</div>"
            f"<p>{escape(e['evidence'])}</p></div>"
        )
    h.append("<h2>Candidates</h2><table><tr><th>effect</th><th>held-out NRMSE (%)</th>")
    h.append("<th>evidence</th></tr>")
    for c in d.candidates:
        h.append(
            f"<tr><td class='name'>{escape(c['effect'])}</td>"
            f"<td class='num'>{_num(c['heldout_nrmse_pct'])}</td>"
            f"<td>{escape(c['evidence'])}</td></tr>"
        )
    h.append("</table>")
    bars = _candidates_figure(d)
    if bars:
        h.append(f"<figure>{img(bars, 'held-out NRMSE of the candidates')}")
        h.append(
            "<figcaption>Held-out NRMSE of the base model and of each candidate tried "
            "(red: added).</figcaption></figure>"
        )
    h.append("<h2>Residual evidence (base model)</h2><ul>")
    for s in d.evidence_before.sentences:
        h.append(f"<li>{escape(s)}</li>")
    h.append("</ul><table><tr><th>entry</th><th>f (Hz)</th><th>Vpp (V)</th><th>NRMSE (%)</th>")
    h.append("<th>floor (%)</th><th>harmonics k=1..5 (% of fundamental)</th></tr>")
    for e in d.evidence_before.entries.values():
        harm = " / ".join(f"{x['amplitude_pct']:.2g}" for x in e.harmonics) or "-"
        h.append(
            f"<tr><td class='name'>{escape(e.name)}</td><td class='num'>{_num(e.frequency_hz)}</td>"
            f"<td class='num'>{_num(e.amplitude_V)}</td><td class='num'>{_num(e.nrmse_pct)}</td>"
            f"<td class='num'>{_num(e.floor_pct)}</td><td>{escape(harm)}</td></tr>"
        )
    h.append("</table>")
    h.append(f"<h2>Residuals</h2><figure>{img(png(residual_figure(d, records)), 'residuals')}")
    h.append(
        "<figcaption>Measured minus predicted strain, base model (grey) and with the added "
        "effects (red).</figcaption></figure>"
    )
    if d.messages:
        h.append("<h2>Messages</h2><ul>" + "".join(f"<li>{escape(m)}</li>" for m in d.messages))
        h.append("</ul>")
    h.append(f"<p class='small'>Diagnosis took {d.elapsed_s:.1f} s.</p></main></body></html>")
    return "".join(h)


def write_diagnosis(
    out_dir: Path, doc: dict[str, Any], d: Diagnosis, records: list[Record], title: str
) -> None:
    """``out_dir/diagnosis.json`` (the JSON contract ``doc``) and ``out_dir/diagnosis.html``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "diagnosis.json").write_text(json.dumps(doc, indent=2) + "\n")
    (out_dir / "diagnosis.html").write_text(render_diagnosis(d, records, title=title))
