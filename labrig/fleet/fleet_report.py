"""``fleet.html``: the fleet at a glance, built with the report's tools (matplotlib figures as
inline PNG, the template ``fleet.html.j2`` and the style sheet of :mod:`labrig.report.templating`,
every text escaped; no scripts, opens offline).

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
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from labrig.core.version import __version__
from labrig.fleet.cache import write_atomic
from labrig.fleet.outliers import QUANTITIES, Z_LIMIT, present_quantities
from labrig.fleet.schedule import ScheduleInfo
from labrig.report.plots import grid_margins, png, style_axes
from labrig.report.templating import render

RIG_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan")
PAGES = ("diagnosis.html", "report.html", "fit.json")
#: the page lists every run in a table up to this many runs (beyond: fleet.parquet has them)
MAX_TABLE_ROWS = 500
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


def spans_a_decade(x: np.ndarray) -> bool:
    """True when the positive values ``x`` span a factor of 10 or more: a log axis then; on a
    narrower range matplotlib labels every minor tick of the log axis and they overlap, so the
    axis stays linear (and so does one value, a fleet of one)."""
    return bool(x.size) and bool(np.all(x > 0)) and float(x.max()) >= 10.0 * float(x.min())


def distributions_figure(rows: list[dict[str, Any]], quantities: list[str]) -> bytes | None:
    """A histogram per quantity; flagged runs drawn as red ticks under it."""
    if not quantities:
        return None
    ncol = 4
    nrow = math.ceil(len(quantities) / ncol)
    height = 2.6 * nrow
    # fixed margins, not tight_layout: its extra draw of every panel was half the page's cost
    margins = grid_margins(12.0, height, nrow, ncol, left_in=0.55, wgap_in=0.6, hgap_in=0.7)
    fig = Figure(figsize=(12, height))
    grid = fig.add_gridspec(nrow, ncol, **margins)
    for k, q in enumerate(quantities):
        ax = fig.add_subplot(grid[k // ncol, k % ncol])
        x = _values(rows, q)
        ok = np.isfinite(x)
        ax.hist(x[ok], bins=min(30, max(5, int(ok.sum() ** 0.5) * 2)), color="0.6")
        out = [abs(r.get(f"z_{q}") or 0) > Z_LIMIT for r in rows]
        bad = x[np.array(out, dtype=bool) & ok]
        ax.plot(bad, np.zeros_like(bad), "|", color="tab:red", markersize=14, mew=2)
        ax.set_title(q, fontsize=9)
        if SCALE.get(q) == "log" and spans_a_decade(x[ok]):
            ax.set_xscale("log")
        style_axes(ax)
    return png(fig)


def control_chart(rows: list[dict[str, Any]], q: str) -> bytes:
    """``q`` against the test date, one colour per rig, median and the 3.5-z limits, the
    outliers labelled with their actuator (or run file)."""
    x = _values(rows, q)
    when = [_when(str(r.get("start_time") or "")) for r in rows]
    idx = [i for i in range(len(rows)) if np.isfinite(x[i]) and when[i] is not None]
    fig = Figure(figsize=(11, 2.8))
    margins = grid_margins(11.0, 2.8, 1, 1, left_in=0.9, bottom_in=0.8, top_in=0.15)
    ax = fig.add_subplot(fig.add_gridspec(1, 1, **margins)[0, 0])
    rigs = sorted({str(rows[i].get("rig") or "") for i in idx})
    for c, rig in enumerate(rigs):
        sel = [i for i in idx if str(rows[i].get("rig") or "") == rig]
        ax.plot(
            [when[i] for i in sel],  # type: ignore[arg-type]  # stub: no datetimes; mpl plots them
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
    if log and spans_a_decade(x[idx]):
        ax.set_yscale("log")
    ax.set_ylabel(q, fontsize=8)
    ax.legend(fontsize=7, loc="upper right", title="rig", title_fontsize=7)
    style_axes(ax)
    for label in ax.get_xticklabels():  # what Figure.autofmt_xdate does, without moving the axes
        label.set(rotation=30, horizontalalignment="right")
    return png(fig)


def page_of(row: dict[str, Any], out_dir: Path) -> str | None:
    """The run's own page beside the fleet page (diagnosis, report or fit), if written."""
    for page in PAGES:
        p = Path("runs") / str(row["key"]) / page
        if (out_dir / p).is_file():
            return p.as_posix()
    return None


def verdict_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Runs per verdict class (the failed ones last), with their fraction of the fleet."""
    ok = [r for r in rows if r["status"] == "ok"]
    counts = Counter(str(r.get("verdict_class") or "(not diagnosed)") for r in ok)
    out = [
        {"name": cls, "runs": n, "fraction": f"{100 * n / len(rows):.1f}"}
        for cls, n in counts.most_common()
    ]
    n_failed = len(rows) - len(ok)
    if n_failed:
        out.append(
            {"name": "failed", "runs": n_failed, "fraction": f"{100 * n_failed / len(rows):.1f}"}
        )
    return out


def flagged_rows(rows: list[dict[str, Any]], out_dir: Path) -> list[dict[str, Any]]:
    out = []
    for r in rows:
        if not r.get("flagged"):
            continue
        page = page_of(r, out_dir)
        out.append(
            {
                "file": Path(str(r["run_file"])).name,
                "actuator": str(r.get("actuator") or ""),
                "rig": str(r.get("rig") or ""),
                "flags": str(r["flags"]),
                "effect": str(r.get("named_effect") or ""),
                "verdict": str(r.get("verdict_class") or ""),
                "page": page,
                "page_name": Path(page).name if page else "",
            }
        )
    return out


def run_table(rows: list[dict[str, Any]], shown: list[str], out_dir: Path) -> list[dict[str, Any]]:
    """One line per run for the page's table: file, actuator, status, verdict, the shown
    quantities (4 significant digits), its own page."""
    out = []
    for r in rows:
        page = page_of(r, out_dir) if r["status"] == "ok" else None
        values = []
        for q in shown:
            v = r.get(q)
            values.append(f"{v:.4g}" if isinstance(v, int | float) and v == v else "—")
        out.append(
            {
                "file": Path(str(r["run_file"])).name,
                "actuator": str(r.get("actuator") or ""),
                "status": str(r["status"]),
                "verdict": str(r.get("verdict_class") or ""),
                "cells": values,
                "page": page,
                "page_name": Path(page).name if page else "",
            }
        )
    return out


def fleet_context(
    rows: list[dict[str, Any]], quantities: list[str], info: ScheduleInfo, out_dir: Path
) -> dict[str, Any]:
    """Everything ``fleet.html.j2`` shows (module docstring)."""
    ok_rows = [r for r in rows if r["status"] == "ok"]
    shown = present_quantities(rows)  # a small fleet too: its values, untested for outliers
    return {
        "version": __version__,
        "n": len(rows),
        "n_ok": len(ok_rows),
        "n_flagged": sum(bool(r.get("flagged")) for r in rows),
        "command": str(rows[0]["command"]) if rows else "",
        "scheduler": info.kind,
        "workers": f"{info.n_workers} worker" + ("" if info.n_workers == 1 else "s"),
        "verdicts": verdict_rows(rows) if rows else [],
        "z_limit": Z_LIMIT,
        "quantities": quantities,
        "flagged": flagged_rows(rows, out_dir),
        "distributions_png": distributions_figure(ok_rows, shown),
        "charts": [
            {"png": control_chart(ok_rows, q), "alt": f"{q} against the test date"} for q in shown
        ],
        "shown": shown,
        "runs": run_table(rows, shown, out_dir) if len(rows) <= MAX_TABLE_ROWS else [],
        "max_table_rows": MAX_TABLE_ROWS,
        "failed": [
            {"file": str(r["run_file"]), "error": str(r["error"])}
            for r in rows
            if r["status"] != "ok"
        ],
    }


def render_fleet(
    rows: list[dict[str, Any]], quantities: list[str], info: ScheduleInfo, out_dir: Path
) -> str:
    """The page (module docstring)."""
    return render("fleet.html.j2", **fleet_context(rows, quantities, info, out_dir))


def write_fleet_report(
    path: Path, rows: list[dict[str, Any]], quantities: list[str], info: ScheduleInfo
) -> Path:
    """Write ``fleet.html`` (through a temporary file and a rename); returns its path."""
    write_atomic(path, render_fleet(rows, quantities, info, path.parent))
    return path
