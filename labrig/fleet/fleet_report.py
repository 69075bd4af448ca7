"""``fleet.html``: the fleet at a glance, built with the report's tools (matplotlib figures as
inline PNG, the report's style sheet, every text escaped; no scripts, opens offline).

Sections: the verdicts (fraction of runs per verdict class), the flagged runs (each with its
run file, the outlying quantities with their robust z, and the effects diagnose found, linked to
its per-run page), parameter distributions, control charts of each quantity against the test
date (one colour per rig, the median and the limits ``median +- 3.5 * 1.4826 * MAD`` where the
robust z crosses the rule's 3.5), and the runs that failed with their errors.
"""

from __future__ import annotations

import math
from collections import Counter
from datetime import datetime
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from labrig import __version__
from labrig.fleet.cache import write_atomic
from labrig.fleet.outliers import QUANTITIES, Z_LIMIT
from labrig.fleet.schedule import ScheduleInfo
from labrig.report.html import CSS, img
from labrig.report.plots import png, style_axes

RIG_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan")
PAGES = ("diagnosis.html", "report.html", "fit.json")
SCALE = dict(QUANTITIES)


def _num(v: Any, digits: int = 4) -> str:
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        return "—"
    return f"{v:.{digits}g}"


def _when(text: str) -> datetime | None:
    try:
        return datetime.fromisoformat(text)
    except (TypeError, ValueError):
        return None


def _values(rows: list[dict[str, Any]], q: str) -> np.ndarray:
    return np.array([float(r[q]) if isinstance(r.get(q), int | float) else np.nan for r in rows])


def distributions_figure(rows: list[dict[str, Any]], quantities: list[str]) -> bytes | None:
    """A histogram per quantity; flagged runs drawn as red ticks under it."""
    if not quantities:
        return None
    ncol = 4
    nrow = math.ceil(len(quantities) / ncol)
    fig = Figure(figsize=(12, 2.6 * nrow))
    for k, q in enumerate(quantities):
        ax = fig.add_subplot(nrow, ncol, k + 1)
        x = _values(rows, q)
        ok = np.isfinite(x)
        ax.hist(x[ok], bins=min(30, max(5, int(ok.sum() ** 0.5) * 2)), color="0.6")
        out = [abs(r.get(f"z_{q}") or 0) > Z_LIMIT for r in rows]
        bad = x[np.array(out, dtype=bool) & ok]
        ax.plot(bad, np.zeros_like(bad), "|", color="tab:red", markersize=14, mew=2)
        ax.set_title(q, fontsize=9)
        if SCALE.get(q) == "log" and ok.any() and np.all(x[ok] > 0):
            ax.set_xscale("log")
        style_axes(ax)
    fig.tight_layout()
    return png(fig)


def control_chart(rows: list[dict[str, Any]], q: str) -> bytes:
    """``q`` against the test date, one colour per rig, median and the 3.5-z limits, the
    outliers labelled with their actuator (or run file)."""
    x = _values(rows, q)
    when = [_when(str(r.get("start_time") or "")) for r in rows]
    idx = [i for i in range(len(rows)) if np.isfinite(x[i]) and when[i] is not None]
    fig = Figure(figsize=(11, 2.8))
    ax = fig.add_subplot(1, 1, 1)
    rigs = sorted({str(rows[i].get("rig") or "") for i in idx})
    for c, rig in enumerate(rigs):
        sel = [i for i in idx if str(rows[i].get("rig") or "") == rig]
        ax.plot(
            [when[i] for i in sel],
            x[sel],
            "o",
            ms=3.5,
            color=RIG_COLORS[c % len(RIG_COLORS)],
            label=rig or "(no rig)",
        )
    log = SCALE.get(q) == "log"
    y = np.log(x[idx]) if log else x[idx]
    if len(y):
        med = float(np.median(y))
        mad = float(np.median(np.abs(y - med)))
        lo, hi = med - Z_LIMIT * mad / 0.6745, med + Z_LIMIT * mad / 0.6745
        back = np.exp if log else (lambda v: v)
        ax.axhline(back(med), color="k", lw=1)
        for lim in (lo, hi):
            ax.axhline(back(lim), color="tab:red", lw=0.8, ls="--")
    for i in idx:
        z = rows[i].get(f"z_{q}")
        if z is not None and abs(z) > Z_LIMIT:
            name = rows[i].get("actuator") or Path(str(rows[i]["run_file"])).stem
            ax.annotate(str(name), (when[i], x[i]), fontsize=7, color="tab:red",
                        xytext=(3, 3), textcoords="offset points")  # fmt: skip
    if log:
        ax.set_yscale("log")
    ax.set_ylabel(q, fontsize=8)
    ax.legend(fontsize=7, loc="upper right", title="rig", title_fontsize=7)
    style_axes(ax)
    fig.autofmt_xdate()
    fig.tight_layout()
    return png(fig)


def _link(row: dict[str, Any], out_dir: Path) -> str:
    for page in PAGES:
        p = Path("runs") / str(row["key"]) / page
        if (out_dir / p).is_file():
            return f'<a href="{escape(p.as_posix())}">{escape(page)}</a>'
    return ""


def verdict_table(rows: list[dict[str, Any]]) -> str:
    ok = [r for r in rows if r["status"] == "ok"]
    counts = Counter(str(r.get("verdict_class") or "(not diagnosed)") for r in ok)
    n_failed = len(rows) - len(ok)
    h = ["<table><tr><th>verdict</th><th>runs</th><th>fraction</th></tr>"]
    for cls, n in counts.most_common():
        h.append(f"<tr><td>{escape(cls)}</td><td>{n}</td><td>{100 * n / len(rows):.1f} %</td></tr>")
    if n_failed:
        frac = 100 * n_failed / len(rows)
        h.append(f"<tr><td>failed</td><td>{n_failed}</td><td>{frac:.1f} %</td></tr>")
    h.append("</table>")
    return "".join(h)


def flagged_table(rows: list[dict[str, Any]], out_dir: Path) -> str:
    flagged = [r for r in rows if r.get("flagged")]
    if not flagged:
        return "<p>No run is flagged.</p>"
    h = [
        "<table><tr><th>run file</th><th>actuator</th><th>rig</th><th>why flagged</th>"
        "<th>points to</th><th>verdict</th><th>page</th></tr>"
    ]
    for r in flagged:
        h.append(
            f"<tr><td>{escape(Path(str(r['run_file'])).name)}</td>"
            f"<td>{escape(str(r.get('actuator') or ''))}</td>"
            f"<td>{escape(str(r.get('rig') or ''))}</td><td>{escape(str(r['flags']))}</td>"
            f"<td>{escape(str(r.get('named_effect') or ''))}</td>"
            f"<td>{escape(str(r.get('verdict_class') or ''))}</td><td>{_link(r, out_dir)}</td></tr>"
        )
    h.append("</table>")
    return "".join(h)


def failed_table(rows: list[dict[str, Any]]) -> str:
    failed = [r for r in rows if r["status"] != "ok"]
    if not failed:
        return "<p>Every run succeeded.</p>"
    h = ["<table><tr><th>run file</th><th>error</th></tr>"]
    for r in failed:
        h.append(
            f"<tr><td>{escape(str(r['run_file']))}</td><td>{escape(str(r['error']))}</td></tr>"
        )
    h.append("</table>")
    return "".join(h)


def render_fleet(
    rows: list[dict[str, Any]], quantities: list[str], info: ScheduleInfo, out_dir: Path
) -> str:
    """The page (module docstring)."""
    n = len(rows)
    n_ok = sum(r["status"] == "ok" for r in rows)
    n_flag = sum(bool(r.get("flagged")) for r in rows)
    ok_rows = [r for r in rows if r["status"] == "ok"]
    charts = "".join(
        f"<figure>{img(control_chart(ok_rows, q), f'{q} against the test date')}</figure>"
        for q in quantities
    )
    dist = distributions_figure(ok_rows, quantities)
    rule = (
        f"A run is flagged when a quantity's robust z-score <code>0.6745 (x - median) / MAD</code> "
        f"over the fleet has |z| &gt; {Z_LIMIT} (time constants on a log scale), when diagnose "
        "added an effect, or when its verdict is <code>unexplained</code> (docs/fleet.md)."
    )
    if not quantities:
        rule += " Too few runs succeeded for the outlier test (at least 5 are needed)."
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="generator" content="labrig {escape(__version__)}">
<title>Fleet: {n} runs</title><style>{CSS}</style></head>
<body><main>
<h1>Fleet: {n} runs</h1>
<p class="sub">{n_ok} succeeded, {n - n_ok} failed, {n_flag} flagged · command
{escape(str(rows[0]["command"]) if rows else "")} · {escape(info.kind)} on {info.n_workers}
worker(s) · labrig {escape(__version__)}</p>
<h2 id="verdicts">Verdicts</h2>{verdict_table(rows) if rows else ""}
<h2 id="flagged">Flagged runs</h2><p class="small">{rule}</p>{flagged_table(rows, out_dir)}
<h2 id="distributions">Parameter distributions</h2>
{img(dist, "distributions") if dist else "<p>No parameters to show.</p>"}
<p class="small">Red ticks: runs outside |z| &gt; {Z_LIMIT} for that quantity.</p>
<h2 id="control">Control charts</h2>
<p class="small">Each quantity against the run's start time, one colour per rig; black: the
median, dashed red: where |z| = {Z_LIMIT}.</p>{charts}
<h2 id="failed">Failed runs</h2>{failed_table(rows)}
</main></body></html>
"""


def write_fleet_report(
    path: Path, rows: list[dict[str, Any]], quantities: list[str], info: ScheduleInfo
) -> Path:
    """Write ``fleet.html`` (through a temporary file and a rename); returns its path."""
    write_atomic(path, render_fleet(rows, quantities, info, path.parent))
    return path
