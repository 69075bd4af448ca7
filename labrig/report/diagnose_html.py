"""``DIR/diagnosis.html``: the diagnosis as one self-contained HTML page (inline CSS, base64
PNG figures from matplotlib's Agg canvas, no scripts), in the style of ``labrig report``: the
template ``templates/diagnosis.html.j2`` (:mod:`labrig.report.templating`) filled by
:func:`diagnosis_context`. The files of a diagnosis are written by
:mod:`labrig.commands.diagnose`.

Figures: per-entry residual before and after (time series), and the held-out NRMSE of every
candidate tried against the base model's.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from labrig.analysis.diagnose import Diagnosis
from labrig.analysis.records import Record, strain_unit
from labrig.report.plots import grid_margins, png, set_title
from labrig.report.templating import render

__all__ = [
    "ResidualFigures",
    "diagnosis_context",
    "render_diagnosis",
    "residual_figure",
    "residual_png",
]


def _panels(d: Diagnosis, records: list[Record]) -> list[Record]:
    """The records the residual figure draws (those the diagnosis predicted), in order."""
    return [r for r in records if r.name in d.predictions_before]


def _new_figure(n: int) -> tuple[Figure, list[Axes]]:
    """An empty residual figure of ``n`` panels (two columns) and its axes."""
    cols = 2
    rows = max(-(-n // cols), 1)
    height = 2.2 * rows + 0.5
    fig = Figure(figsize=(11, height))
    # fixed margins (inches: tick labels and axis labels, the titles): a tight layout would
    # lay every panel out, then draw the figure twice (most of the page's time)
    gs = fig.add_gridspec(rows, cols, **grid_margins(11.0, height, rows, cols))
    return fig, [fig.add_subplot(gs[k // cols, k % cols]) for k in range(n)]


def _draw_panels(axes: list[Axes], d: Diagnosis, recs: list[Record]) -> bool:
    """Each record's residual (measured - model) in time before and after the added effects,
    on empty ``axes``; ``False`` when a title is left to matplotlib's automatic placement
    (:func:`~labrig.report.plots.set_title`)."""
    fixed = True
    for k, (ax, r) in enumerate(zip(axes, recs, strict=True)):
        rb = r.strain_ue - d.predictions_before[r.name]
        ax.plot(r.time_s, rb, lw=0.6, color="0.55", label="before")
        if r.name in d.predictions_after:
            ra = r.strain_ue - d.predictions_after[r.name]
            ax.plot(r.time_s, ra, lw=0.6, color="tab:red", label="after")
        fixed &= set_title(ax, r.name, fontsize=9)  # after the data: fixed at the top if it can
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
        unit = strain_unit([r])
        ax.set_ylabel(f"residual ({unit})", fontsize=8)
        ax.set_xlabel("time (s)", fontsize=8)
    return fixed


def residual_figure(d: Diagnosis, records: list[Record]) -> Figure:
    """One panel per entry: the residual (measured - model) in time before and after the added
    effects, with its axes labelled."""
    recs = _panels(d, records)
    fig, axes = _new_figure(len(recs))
    _draw_panels(axes, d, recs)
    return fig


def _empty(axes: list[Axes]) -> None:
    """The axes as a new figure has them (their settings kept): no lines, patches, texts or
    legend, no data limits, autoscaling on."""
    for ax in axes:
        for artist in [*ax.lines, *ax.patches, *ax.texts]:
            artist.remove()
        legend = ax.get_legend()
        if legend is not None:
            legend.remove()
        ax.relim()
        ax.set_autoscale_on(True)


class ResidualFigures:
    """:func:`residual_figure`'s PNG for one diagnosis after another (a ``batch diagnose``
    worker's tasks): the figure of the last panel count, with its axes and the tick objects
    matplotlib makes for them, is kept and emptied between diagnoses (a quarter to a third less
    CPU per page: benchmarks/RESULTS.md, fourth round), so each is drawn as on a new figure,
    pixel for pixel (the tests compare the two). A diagnosis whose titles need matplotlib's
    automatic placement (:func:`~labrig.report.plots.set_title`) is drawn on a new figure, not
    kept. The figure holds the last diagnosis' residuals (about 1.4 MB for the paper's
    campaign) until the next one."""

    def __init__(self) -> None:
        self._held: tuple[int, Figure, list[Axes]] | None = None

    def __call__(self, d: Diagnosis, records: list[Record]) -> bytes:
        """The PNG of :func:`residual_figure` for ``d`` and ``records``."""
        recs = _panels(d, records)
        if self._held is not None and self._held[0] == len(recs):
            _, fig, axes = self._held
            _empty(axes)
            if _draw_panels(axes, d, recs):
                return png(fig)
        self._held = None
        fig, axes = _new_figure(len(recs))
        if _draw_panels(axes, d, recs):
            self._held = (len(recs), fig, axes)
        return png(fig)


_figures = threading.local()


def residual_png(d: Diagnosis, records: list[Record]) -> bytes:
    """``png(residual_figure(d, records))``, drawn on this thread's :class:`ResidualFigures`."""
    held = getattr(_figures, "residual", None)
    if held is None:
        held = _figures.residual = ResidualFigures()
    return held(d, records)


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


def number(v: Any) -> str:
    """A value of the diagnosis for a table cell: 4 significant digits, ``-`` when undefined."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def diagnosis_context(d: Diagnosis, records: list[Record], title: str) -> dict[str, Any]:
    """Everything ``diagnosis.html.j2`` shows."""
    after = d.after["per_entry"]
    return {
        "title": title,
        "num": number,
        "settled": d.classification in ("explained", "consistent_with_noise"),
        "verdict": d.verdict,
        "headline": d.headline,
        "per_entry": [(k, v, after.get(k)) for k, v in d.before["per_entry"].items()],
        "before": d.before,
        "after": d.after,
        "effects_added": [
            {
                "effect": e["effect"],
                "params": ", ".join(f"{k} = {number(v)}" for k, v in e["params"].items()),
                "evidence": e["evidence"],
            }
            for e in d.effects_added
        ],
        "candidates": d.candidates,
        "candidates_png": _candidates_figure(d),
        "evidence": {
            "sentences": d.evidence_before.sentences,
            "entries": [
                {
                    "name": e.name,
                    "frequency_hz": e.frequency_hz,
                    "amplitude_V": e.amplitude_V,
                    "nrmse_pct": e.nrmse_pct,
                    "floor_pct": e.floor_pct,
                    "harmonics": " / ".join(f"{x['amplitude_pct']:.2g}" for x in e.harmonics)
                    or "-",
                }
                for e in d.evidence_before.entries.values()
            ],
        },
        "residuals_png": residual_png(d, records),
        "messages": d.messages,
        "elapsed_s": d.elapsed_s,
    }


def render_diagnosis(d: Diagnosis, records: list[Record], title: str = "labrig diagnose") -> str:
    """The page (a string)."""
    return render("diagnosis.html.j2", **diagnosis_context(d, records, title))
