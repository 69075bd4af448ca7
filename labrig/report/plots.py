"""Figures of the model-versus-measurement report, as PNG bytes (matplotlib Agg, object API).

- :func:`entry_figure` (the paper's Figs. 9 and 12): one entry's voltage-strain loop, measured and
  predicted overlaid, beside its strain time series with the residual underneath.
- :func:`frequency_figure` (the paper's Fig. 10): (a) loop area and (b) strain at zero voltage
  versus the drive frequency, one colour per amplitude: measured as markers, our model as solid
  lines, the baselines dashed and dotted.

Only the object API (``Figure`` + ``FigureCanvasAgg``): no pyplot, no global state.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from labrig.report.data import MODEL_LABELS, EntryView

DPI = 100
MEASURED = "0.25"
OURS = "tab:red"
#: line style of each model in the summary figure
STYLES = {"dynamic": "-", "prandtl_ishlinskii": "--", "bouc_wen": ":"}
AMPLITUDE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan")


def png(fig: Figure) -> bytes:
    """The figure as PNG bytes: drawn once at :data:`DPI` on an Agg canvas, its pixels encoded
    by Pillow (the pixels ``fig.savefig(format="png", dpi=DPI)`` writes; RGB when every pixel
    is opaque, as on the report's white figures: a quarter less to compress and to embed)."""
    from PIL import Image

    fig.set_dpi(DPI)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    pixels = rgba[..., :3] if bool(np.all(rgba[..., 3] == 255)) else rgba
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(buf, format="png")
    return buf.getvalue()


def set_title(ax: Axes, text: str, **kwargs: Any) -> bool:
    """``ax.set_title(text, **kwargs)`` fixed at the top of the axes (``y = 1``), where
    matplotlib's automatic placement puts it when nothing stands above the axes, so drawing
    does not lay the axis' tick labels out once more to place it; automatic (``y=None``) when
    the y axis shows an offset or a power of ten above it (``1e4``, ``+1.2e3``), which the
    automatic placement lifts the title over. Call it once the axes' data are plotted (the
    offset depends on the y limits). ``True`` when the title is fixed."""
    fmt = ax.yaxis.get_major_formatter()
    fmt.set_locs([float(x) for x in ax.yaxis.get_majorticklocs()])
    fixed = not fmt.get_offset()
    ax.set_title(text, y=1.0 if fixed else None, **kwargs)
    return fixed


def style_axes(ax: Axes) -> None:
    """The report's look of an axes: a light grid, small tick labels."""
    ax.grid(True, alpha=0.3)
    ax.tick_params(labelsize=8)


#: former name of :func:`style_axes` (labrig/report/control_section.py still imports it)
_style = style_axes


def grid_margins(
    width_in: float,
    height_in: float,
    rows: int,
    cols: int,
    *,
    left_in: float = 0.75,
    right_in: float = 0.15,
    bottom_in: float = 0.45,
    top_in: float = 0.3,
    wgap_in: float = 0.85,
    hgap_in: float = 0.75,
) -> dict[str, float]:
    """``Figure.add_gridspec`` keywords for a grid of ``rows x cols`` panels with fixed
    margins and gaps given in inches (``left`` ... ``top`` as fractions of the figure,
    ``wspace`` and ``hspace`` as fractions of a panel's width and height)."""
    w = (width_in - left_in - right_in - (cols - 1) * wgap_in) / cols
    h = (height_in - bottom_in - top_in - (rows - 1) * hgap_in) / rows
    return {
        "left": left_in / width_in,
        "right": 1.0 - right_in / width_in,
        "bottom": bottom_in / height_in,
        "top": 1.0 - top_in / height_in,
        "wspace": wgap_in / w,
        "hspace": hgap_in / h,
    }


def entry_figure(
    entry: EntryView,
    predicted: NDArray[np.float64],
    warmup_s: float = 0.0,
    noise_ue: float | None = None,
    strain_unit: str = "ue",
    others: dict[str, NDArray[np.float64]] | None = None,
) -> bytes:
    """Loop (left) and time series with the residual underneath (right) of one entry.

    When the record ends with the voltage held constant for a second or more (the envelope's
    0 V hold), an inset zooms on the strain there (the creep), with the ``others`` (baseline
    label -> prediction) dashed for comparison. (:class:`EntryFigures` draws many entries.)"""
    return EntryFigures()(entry, predicted, warmup_s, noise_ue, strain_unit, others)


EntryAxes = tuple[Axes, Axes, Axes]


class EntryFigures:
    """:func:`entry_figure` for one entry after another on one figure: its axes, and the tick
    objects matplotlib makes for them (most of a small figure's cost), are made once and
    emptied between entries (every line, patch, text and inset removed, the data limits reset,
    autoscaling on again), so each entry is drawn as on a new figure, pixel for pixel (the
    tests compare the two). An entry whose titles need matplotlib's automatic placement
    (:func:`set_title`) is drawn again on a new figure, which the next entries then reuse."""

    def __init__(self) -> None:
        self._fig: Figure | None = None
        self._axes: EntryAxes | None = None

    def _new(self) -> tuple[Figure, EntryAxes]:
        # fixed margins: a constrained layout would draw every figure twice
        fig = Figure(figsize=(11.0, 3.5))
        gs = fig.add_gridspec(
            2, 2, width_ratios=(1.0, 2.3), height_ratios=(1.6, 1.0),
            left=0.065, right=0.985, bottom=0.13, top=0.93, wspace=0.17, hspace=0.1,
        )  # fmt: skip
        ax_l = fig.add_subplot(gs[:, 0])
        ax_s = fig.add_subplot(gs[0, 1])
        axes = (ax_l, ax_s, fig.add_subplot(gs[1, 1], sharex=ax_s))
        self._fig, self._axes = fig, axes
        return fig, axes

    def __call__(
        self,
        entry: EntryView,
        predicted: NDArray[np.float64],
        warmup_s: float = 0.0,
        noise_ue: float | None = None,
        strain_unit: str = "ue",
        others: dict[str, NDArray[np.float64]] | None = None,
    ) -> bytes:
        """The PNG of :func:`entry_figure` for these arguments."""
        args = (entry, predicted, warmup_s, noise_ue, strain_unit, others)
        if self._fig is None or self._axes is None:
            fig, axes = self._new()
            _draw_entry(axes, *args)
        else:
            fig, axes = self._fig, self._axes
            _empty(axes)
            if not _draw_entry(axes, *args):  # a title placed by matplotlib: a new figure
                fig, axes = self._new()
                _draw_entry(axes, *args)
        return png(fig)


def _empty(axes: EntryAxes) -> None:
    """The axes as a new figure has them (their settings kept): no lines, patches, texts or
    insets, no data limits, autoscaling on."""
    for ax in axes:
        for artist in [*ax.child_axes, *ax.lines, *ax.patches, *ax.texts]:
            artist.remove()
        ax.relim()
        ax.set_autoscale_on(True)


def _draw_entry(
    axes: EntryAxes,
    entry: EntryView,
    predicted: NDArray[np.float64],
    warmup_s: float,
    noise_ue: float | None,
    strain_unit: str,
    others: dict[str, NDArray[np.float64]] | None,
) -> bool:
    """:func:`entry_figure` drawn on empty ``axes`` (loop, strain, residual); ``False`` when
    a title is left to matplotlib's automatic placement (:func:`set_title`)."""
    r = entry.record
    t, v, s = r.time_s - r.time_s[0], r.voltage_V, r.strain_ue
    p = np.asarray(predicted, dtype=float)
    i0 = min(round(warmup_s * r.rate_hz), r.n - 1)
    ax_l, ax_s, ax_r = axes
    # measured wide and light, the model thin on top: where they agree the grey shows as a halo
    ax_l.plot(v[i0:], s[i0:], color=MEASURED, lw=2.4, alpha=0.45, label="measured")
    ax_l.plot(v[i0:], p[i0:], color=OURS, lw=0.8, label="model")
    ax_l.set_xlabel("voltage (V)", fontsize=9)
    ax_l.set_ylabel(f"strain ({strain_unit})", fontsize=9)
    ax_l.legend(fontsize=8, loc="upper left", frameon=False)
    fixed = set_title(ax_l, "voltage-strain loop", fontsize=9)

    ax_s.plot(t, s, color=MEASURED, lw=2.4, alpha=0.45, label="measured")
    ax_s.plot(t, p, color=OURS, lw=0.8, label="model")
    ax_s.set_ylabel(f"strain ({strain_unit})", fontsize=9)
    fixed &= set_title(ax_s, "strain and residual in time", fontsize=9)
    ax_s.tick_params(labelbottom=False)
    res = s - p
    ax_r.plot(t[i0:], res[i0:], color=OURS, lw=0.5, alpha=0.6)
    ax_r.axhline(0.0, color="0.4", lw=0.6)
    if noise_ue:
        for y in (-noise_ue, noise_ue):
            ax_r.axhline(y, color="k", lw=1.0, ls="--", zorder=3)
        ax_r.text(
            0.995,
            noise_ue,
            "±1σ noise",
            transform=ax_r.get_yaxis_transform(),
            va="bottom",
            ha="right",
            fontsize=7,
            color="0.1",
            zorder=4,
            bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8},
        )
    ax_r.set_ylabel(f"residual ({strain_unit})", fontsize=9)
    ax_r.set_xlabel("time (s)", fontsize=9)
    if i0 > 0:
        for ax in (ax_s, ax_r):
            ax.axvspan(t[0], t[i0], color="0.85", lw=0, zorder=0)
        ax_s.text(
            0.5 * t[i0],
            0.97,
            "warm-up",
            transform=ax_s.get_xaxis_transform(),
            ha="center",
            va="top",
            fontsize=7,
            color="0.35",
        )
    for ax in (ax_l, ax_s, ax_r):
        style_axes(ax)
    k = _final_hold(v, r.rate_hz)
    if k is not None and k > i0:
        fixed &= _hold_inset(ax_s, t[k:], s[k:], p[k:], others, k, strain_unit)
    ax_s.set_xlim(t[0], t[-1])
    return fixed


def frequency_figure(
    entries: list[EntryView], models: list[str], strain_unit: str = "ue"
) -> bytes | None:
    """Seed Fig. 10: loop area (a) and strain at zero voltage (b) versus frequency, per
    amplitude; ``None`` unless periodic entries cover two frequencies or more."""
    rows = [e for e in entries if e.periodic and e.frequency_hz and e.metrics]
    fs = sorted(e.frequency_hz for e in rows if e.frequency_hz)
    if not rows or fs[-1] <= 1.05 * fs[0]:  # one frequency (within 5 %): nothing to plot against
        return None
    amps = sorted({e.amplitude_V for e in rows})
    colors = {a: AMPLITUDE_COLORS[i % len(AMPLITUDE_COLORS)] for i, a in enumerate(amps)}
    # fixed margins, the legend in the right one: a constrained layout draws the figure twice
    fig = Figure(figsize=(11.0, 4.0))
    gs = fig.add_gridspec(
        1, 2, **grid_margins(11.0, 4.0, 1, 2, left_in=0.8, right_in=2.0, top_in=0.35, bottom_in=0.5)
    )
    ax_a, ax_b = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
    panels = (
        (ax_a, "loop_area_Vue", "loop_area_pred_Vue", f"loop area (V·{strain_unit})"),
        (
            ax_b,
            "strain_shift_ue",
            "strain_shift_pred_ue",
            f"strain at zero voltage ({strain_unit})",
        ),
    )
    for ax, meas_key, pred_key, ylabel in panels:
        for a in amps:
            group = sorted(
                (e for e in rows if e.amplitude_V == a), key=lambda e: e.frequency_hz or 0.0
            )
            f = np.array([e.frequency_hz for e in group])
            first = next(iter(group[0].metrics.values()))
            if first.get(meas_key) is None:
                continue
            meas = np.array([next(iter(e.metrics.values()))[meas_key] for e in group])
            ax.plot(f, meas, "o", color=colors[a], ms=6, mfc="none", mew=1.5, zorder=3)
            for key in models:
                vals = [e.metrics.get(key, {}).get(pred_key) for e in group]
                if any(x is None for x in vals):
                    continue
                lw = 1.6 if key == "dynamic" else 1.0
                ax.plot(
                    f,
                    np.array(vals, dtype=float),
                    STYLES.get(key, "-."),
                    color=colors[a],
                    lw=lw,
                    marker="." if key == "dynamic" else None,
                    alpha=1.0 if key == "dynamic" else 0.7,
                )
        ax.set_xlabel("drive frequency (Hz)", fontsize=9)
        ax.set_ylabel(ylabel, fontsize=9)
        ax.set_xlim(left=0)
        style_axes(ax)
    set_title(ax_a, "(a) loop area versus frequency", fontsize=10)
    set_title(ax_b, "(b) strain at zero voltage versus frequency", fontsize=10)
    handles = [
        Line2D([], [], color=colors[a], lw=6, alpha=0.8, label=f"amplitude {a:g} V") for a in amps
    ]
    handles.append(
        Line2D([], [], ls="none", marker="o", mfc="none", mew=1.5, color="0.2", label="measured")
    )
    for key in models:
        handles.append(
            Line2D(
                [],
                [],
                ls=STYLES.get(key, "-."),
                color="0.2",
                lw=1.6 if key == "dynamic" else 1.0,
                label=MODEL_LABELS.get(key, key),
            )
        )
    fig.legend(
        handles=handles,
        loc="center left",
        bbox_to_anchor=(1.0 - 1.9 / 11.0, 0.5),
        fontsize=8,
        frameon=False,
    )
    return png(fig)


def _final_hold(v: NDArray, rate_hz: float, min_s: float = 1.0) -> int | None:
    """First sample of a constant-voltage stretch of ``min_s`` or more ending the record."""
    tol = 1e-6 * max(float(np.ptp(v)), 1e-12)
    changed = np.flatnonzero(np.abs(v - v[-1]) > tol)
    k = int(changed[-1]) + 1 if changed.size else 0
    if v.size - k < min_s * rate_hz or k == 0:
        return None
    return k


def _hold_inset(ax, t, s, p, others, k, unit) -> bool:
    """Zoom on the strain during the final hold: measured (with a 0.2 s moving average), the
    model, and the baselines (labelled off scale when outside the measured range); ``False``
    when its title is left to matplotlib's placement (:func:`set_title`)."""
    ins = ax.inset_axes((0.5, 0.36, 0.48, 0.56))
    ins.plot(t, s, color=MEASURED, lw=1.2, alpha=0.3)
    w = max(round(0.2 / float(t[1] - t[0])), 1) if t.size > 1 else 1
    if t.size > 2 * w:
        avg = np.convolve(s, np.ones(w) / w, mode="valid")
        ins.plot(
            t[w // 2 : w // 2 + avg.size], avg, color="k", lw=0.9, label="measured (0.2 s avg.)"
        )
    ins.plot(t, p, color=OURS, lw=1.2, label="model")
    lo = min(float(np.min(s)), float(np.min(p)))
    hi = max(float(np.max(s)), float(np.max(p)))
    pad = 0.15 * (hi - lo) + 1e-9
    for (label, q), ls in zip((others or {}).items(), ("--", ":"), strict=False):
        q = np.asarray(q)[k:]
        if np.min(q) > hi + 1.2 * (hi - lo) + pad or np.max(q) < lo - pad:
            label = f"{label}: off scale ({np.mean(q):.0f} {unit})"
        ins.plot(t, q, color="0.35", lw=1.0, ls=ls, label=label)
    ins.set_ylim(lo - pad, hi + 1.2 * (hi - lo) + pad)  # the upper part for the legend
    fixed = set_title(ins, f"constant-voltage hold: strain ({unit})", fontsize=7, pad=2)
    ins.tick_params(labelsize=6.5)
    ins.grid(True, alpha=0.3)
    ins.legend(fontsize=6, loc="upper right", ncol=2, frameon=False)
    return fixed


def validation_figure(
    entry: EntryView,
    predictions: dict[str, NDArray[np.float64]],
    warmup_s: float = 0.0,
    strain_unit: str = "ue",
) -> bytes:
    """``labrig validate``: one test entry predicted by each model (label -> strain over the
    record), one row per model: its voltage-strain loop over the measured one (left) and its
    residual, measured minus predicted, in time (right); the warm-up is not drawn."""
    r = entry.record
    i0 = min(round(warmup_s * r.rate_hz), r.n - 1)
    t, v, s = r.time_s[i0:] - r.time_s[0], r.voltage_V[i0:], r.strain_ue[i0:]
    rows = max(len(predictions), 1)
    fig = Figure(figsize=(11.0, 1.9 * rows + 0.5))
    gs = fig.add_gridspec(
        rows, 2, width_ratios=(1.0, 2.3), left=0.065, right=0.985,
        bottom=0.5 / (1.9 * rows + 0.5) + 0.03, top=0.97, wspace=0.17, hspace=0.35,
    )  # fmt: skip
    first = None
    for k, (label, pred) in enumerate(predictions.items()):
        p = np.asarray(pred, dtype=float)[i0:]
        ax_l = fig.add_subplot(gs[k, 0])
        ax_r = fig.add_subplot(gs[k, 1], sharex=first)
        first = first or ax_r
        ax_l.plot(v, s, color=MEASURED, lw=2.4, alpha=0.45, label="measured")
        ax_l.plot(v, p, color=OURS, lw=0.8, label=label)
        ax_l.legend(fontsize=7, loc="upper left", frameon=False)
        ax_l.set_ylabel(f"strain ({strain_unit})", fontsize=8)
        ax_r.plot(t, s - p, color=OURS, lw=0.5)
        ax_r.axhline(0.0, color="0.4", lw=0.6)
        ax_r.set_ylabel(f"residual ({strain_unit})", fontsize=8)
        set_title(ax_r, label, fontsize=8, loc="left")
        for ax in (ax_l, ax_r):
            style_axes(ax)
        if k == rows - 1:
            ax_l.set_xlabel("voltage (V)", fontsize=9)
            ax_r.set_xlabel("time (s)", fontsize=9)
    return png(fig)
