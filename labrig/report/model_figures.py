"""The paper's section-2 figures regenerated from :mod:`labrig.model` (PNG, matplotlib Agg).

``write_model_figures(out)`` writes four files into ``out`` and returns their paths:

- ``fig1_hysteresis_loop.png`` (cf. the paper's Fig. 1): the dynamic model with the paper's
  Table 1 parameters driven by a 0-100 V unipolar sine at 1 Hz from rest: voltage and the
  equivalent static voltage ``V*`` in time, the strain in time with its value at each 0 V
  minimum (the strain shift), the strain-voltage loops cycle by cycle next to the quasi-static
  operator alone, and the slope ``alpha = dS/dV*`` of the quasi-static operator (the paper's
  Eqs. 2 and 10).
- ``fig3_frequency_response.png`` (cf. the paper's Fig. 3): magnitude and phase of unit relaxors
  ``1 / (1 + (tau s)^lam)``, ``tau = 1 s``, for ``lam = 0.25 ... 1.75``.
- ``fig4_input_output.png`` (cf. the paper's Fig. 4): output versus input of unit relaxors for a
  bipolar (a) and a unipolar (b) sine at three frequencies, from rest (the transient is shown).
- ``fig5_step_response.png`` (cf. the paper's Fig. 5): unit-step responses
  ``1 - E_lam(-(t/tau)^lam)`` on a linear and a logarithmic time axis (overshoot for
  ``lam > 1``, long tail for ``lam < 1``).

The paper calls the order ``n``; the code calls it ``lam`` (docs/model.md, section 3). Only the
object API of matplotlib is used (``Figure`` + ``FigureCanvasAgg``): no pyplot, no global
backend switch, no display.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, Relaxor
from labrig.report.plots import grid_margins

#: fractional orders of the unit-relaxor figures (the paper's Figs. 3 and 5)
ORDERS: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75)
#: orders of the input-output figure (the paper's Fig. 4), fewer for legibility
ORDERS_IO: tuple[float, ...] = (0.25, 0.5, 1.0, 1.5)
#: normalised angular frequencies ``omega tau`` of the paper's Fig. 4
OMEGA_TAU_IO: tuple[float, ...] = (0.1, 1.0, 10.0)

_DPI = 120


def _colors(n: int) -> list:
    cmap = colormaps["viridis"]
    return [cmap(x) for x in np.linspace(0.0, 0.9, n)]


def _grid(
    width_in: float, height_in: float, rows: int, cols: int, **margins_in: float
) -> tuple[Figure, Any]:
    """A figure of ``rows x cols`` panels with fixed margins in inches (a title line above
    the panels; :func:`~labrig.report.plots.grid_margins`): a constrained layout would lay the
    figure out by drawing it, about a third of its cost, once more."""
    fig = Figure(figsize=(width_in, height_in))
    margins = {"left_in": 0.8, "right_in": 0.2, "bottom_in": 0.55, "top_in": 0.65, **margins_in}
    kw = grid_margins(width_in, height_in, rows, cols, **margins)
    return fig, fig.subplots(rows, cols, gridspec_kw=kw)


def _suptitle(fig: Figure, text: str) -> None:
    """The figure's title, centred in its top margin's first 0.3 inches."""
    fig.suptitle(text, y=1.0 - 0.08 / fig.get_figheight(), va="top")


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=_DPI)
    return path


def _lam_label(lam: float) -> str:
    return f"λ = {lam:g}"


# -- the paper's Fig. 3 ---------------------------------------------------------------------------


def figure_frequency_response(path: Path) -> Path:
    """Bode plot of the unit relaxors (the paper's Fig. 3)."""
    w = np.logspace(-3, 3, 601)  # rad/s; tau = 1 s so w is also w*tau
    f = w / (2 * np.pi)
    fig, (ax_m, ax_p) = _grid(7.0, 6.5, 2, 1, top_in=0.45, hgap_in=0.2)
    ax_p.sharex(ax_m)
    ax_m.tick_params(labelbottom=False)
    for lam, col in zip(ORDERS, _colors(len(ORDERS)), strict=True):
        g = Relaxor(1.0, lam).frequency_response(f)
        ax_m.semilogx(w, 20 * np.log10(np.abs(g)), color=col, label=_lam_label(lam))
        ax_p.semilogx(w, np.degrees(np.angle(g)), color=col, label=_lam_label(lam))
    ax_m.set_ylabel("magnitude |H(jω)| (dB)")
    ax_m.set_ylim(-80, 15)
    ax_p.set_ylabel("phase arg H(jω) (deg)")
    ax_p.set_xlabel("angular frequency ω (rad/s), τ = 1 s")
    ax_p.set_ylim(-180, 5)
    ax_p.set_yticks(np.arange(-180, 1, 30))
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.legend(ncol=2, fontsize=8, loc="lower left")
    _suptitle(
        fig, "Frequency response of unit relaxors H(s) = 1/(1 + (τs)^λ)  (cf. the paper's Fig. 3)"
    )
    return _save(fig, path)


# -- the paper's Fig. 4 ---------------------------------------------------------------------------


def _sine_io(
    lam: float, omega: float, unipolar: bool, cycles: int = 6, per_cycle: int = 240
) -> tuple[NDArray, NDArray]:
    """Input and output of the unit relaxor for a sine from rest (linear hold: smooth input)."""
    rate_hz = per_cycle * omega / (2 * np.pi)
    t = np.arange(cycles * per_cycle + 1) / rate_hz
    x = 0.5 * (1 - np.cos(omega * t)) if unipolar else np.sin(omega * t)
    y = Relaxor(1.0, lam).filter(x, rate_hz, method="exact", hold="linear")
    return x, y


def figure_input_output(path: Path, cycles: int = 6, per_cycle: int = 240) -> Path:
    """Input-output characteristics of unit relaxors for sines (the paper's Fig. 4).

    Each sine starts from rest; the first ``cycles - 1`` cycles (the transient) are drawn thin,
    the last one bold (close to the steady-state ellipse, except for the slow drift of the
    small orders, which is the long memory the model is after).
    """
    fig, axes = _grid(11.0, 7.4, 2, len(OMEGA_TAU_IO), top_in=0.65, wgap_in=0.7, hgap_in=0.85)
    cols = _colors(len(ORDERS_IO))
    for row, unipolar in enumerate((False, True)):
        for j, omega in enumerate(OMEGA_TAU_IO):
            ax = axes[row, j]
            lo_y, hi_y = (0.0, 1.0) if unipolar else (-1.0, 1.0)
            for lam, col in zip(ORDERS_IO, cols, strict=True):
                x, y = _sine_io(lam, omega, unipolar, cycles, per_cycle)
                last = slice((cycles - 1) * per_cycle, None)
                ax.plot(x, y, color=col, lw=0.6, alpha=0.55)
                ax.plot(x[last], y[last], color=col, lw=1.8, label=_lam_label(lam))
                lo_y, hi_y = min(lo_y, float(y.min())), max(hi_y, float(y.max()))
            lo = 0.0 if unipolar else -1.0
            ax.plot([lo, 1.0], [lo, 1.0], color="0.5", lw=0.8, ls=":", label="out = in")
            pad = 0.05 * (hi_y - lo_y)
            ax.set_xlim(lo - 0.05, 1.05)
            ax.set_ylim(lo_y - pad, hi_y + pad)
            ax.grid(True, alpha=0.3)
            kind = "unipolar (1 - cos ωt)/2" if unipolar else "bipolar sin ωt"
            ax.set_title(f"({'ab'[row]}) {kind}, ωτ = {omega:g}", fontsize=10)
            ax.set_xlabel("input in(t) (a.u.)")
            if j == 0:
                ax.set_ylabel("output out(t) (a.u.)")
    axes[0, 0].legend(fontsize=8, loc="upper left")
    _suptitle(
        fig,
        f"Input-output characteristics of unit relaxors (τ = 1 s), {cycles} cycles from rest: "
        "thin = transient, bold = last cycle  (cf. the paper's Fig. 4)",
    )
    return _save(fig, path)


# -- the paper's Fig. 5 ---------------------------------------------------------------------------


def figure_step_response(path: Path) -> Path:
    """Unit-step responses on linear and logarithmic time axes (the paper's Fig. 5)."""
    t_lin = np.linspace(0.0, 10.0, 801)
    t_log = np.logspace(-3, 3, 1201)
    fig, (ax_l, ax_g) = _grid(11.0, 4.8, 1, 2, top_in=0.6)
    ax_l.plot(
        np.r_[-0.5, 0.0, 0.0, t_lin[-1]], [0, 0, 1, 1], color="k", ls="--", lw=1, label="input"
    )
    ax_g.semilogx(t_log, np.ones_like(t_log), color="k", ls="--", lw=1, label="input")
    for lam, col in zip(ORDERS, _colors(len(ORDERS)), strict=True):
        r = Relaxor(1.0, lam)
        ax_l.plot(t_lin, r.step_response(t_lin), color=col, label=_lam_label(lam))
        ax_g.semilogx(t_log, r.step_response(t_log), color=col, label=_lam_label(lam))
    ax_l.set_xlim(-0.5, t_lin[-1])
    ax_l.set_title("linear time scale", fontsize=10)
    ax_g.set_title("logarithmic time scale", fontsize=10)
    for ax in (ax_l, ax_g):
        ax.set_xlabel("time t (s), τ = 1 s")
        ax.set_ylabel("input / output (a.u.)")
        ax.set_ylim(-0.05, 1.7)
        ax.grid(True, which="both", alpha=0.3)
    ax_l.legend(fontsize=8, ncol=2, loc="lower right")
    _suptitle(fig, "Step responses of unit relaxors 1 - E_λ(-(t/τ)^λ)  (cf. the paper's Fig. 5)")
    return _save(fig, path)


# -- the paper's Fig. 1 ---------------------------------------------------------------------------


def figure_hysteresis_loop(path: Path, cycles: int = 8, rate_hz: float = 1000.0) -> Path:
    """The dynamic model (Table 1) under a 0-100 V unipolar 1 Hz sine (the paper's Fig. 1,
    Eqs. 1-10)."""
    p = PAPER_TABLE1
    model = DynamicHysteresisModel(p)
    n = round(cycles * rate_hz) + 1
    t = np.arange(n) / rate_hz
    v = 50.0 * (1.0 - np.cos(2 * np.pi * 1.0 * t))
    vstar = model.equivalent_static_voltage(v, rate_hz, method="exact")
    s = model.operator.apply(vstar)
    s_static = model.operator.apply(v)
    per = round(rate_hz)
    mins = np.arange(per, n, per)  # the 0 V minima, t = 1, 2, ... s

    fig, ((ax_v, ax_s), (ax_loop, ax_a)) = _grid(11.0, 8.0, 2, 2, top_in=0.65, hgap_in=0.85)

    ax_v.plot(t, v, color="k", lw=1.0, label="driving voltage V")
    ax_v.plot(t, vstar, color="tab:red", lw=1.0, label="equivalent static voltage V* = G_t G_d V")
    ax_v.set_xlabel("time t (s)")
    ax_v.set_ylabel("voltage (V)")
    ax_v.set_title("(a) input and equivalent static voltage", fontsize=10)
    ax_v.set_ylim(-5, 130)
    ax_v.legend(fontsize=8, loc="upper center", ncol=2)

    ax_s.plot(t, s, color="tab:blue", lw=1.0, label="dynamic model")
    ax_s.plot(t, s_static, color="0.5", lw=0.8, ls="--", label="quasi-static operator only")
    ax_s.plot(t[mins], s[mins], "o", color="tab:red", ms=4, label="strain at V = 0 (shift)")
    for k in (mins[0], mins[-1]):
        ax_s.annotate(
            f"{s[k]:.0f} µε",
            (t[k], s[k]),
            textcoords="offset points",
            xytext=(-10, -14),
            fontsize=8,
            color="tab:red",
        )
    ax_s.set_xlabel("time t (s)")
    ax_s.set_ylabel("strain S (µε)")
    ax_s.set_title("(b) strain and strain shift at 0 V", fontsize=10)
    ax_s.set_ylim(-60, 1.2 * float(max(s.max(), s_static.max())))
    ax_s.set_xlim(-0.2, t[-1] + 0.6)
    ax_s.legend(fontsize=8, loc="upper center", ncol=3)

    cols = colormaps["plasma"](np.linspace(0.0, 0.85, cycles))
    for c in range(cycles):
        sl = slice(c * per, (c + 1) * per + 1)
        ax_loop.plot(v[sl], s[sl], color=cols[c], lw=1.0, label=f"cycle {c + 1}")
    ax_loop.plot(v[: per + 1], s_static[: per + 1], color="0.4", ls="--", lw=1.0,
                 label="quasi-static operator only")  # fmt: skip
    ax_loop.set_xlabel("driving voltage V (V)")
    ax_loop.set_ylabel("strain S (µε)")
    ax_loop.set_title("(c) strain-voltage loops, 1 Hz, from rest", fontsize=10)
    ax_loop.legend(fontsize=7, ncol=2, loc="upper left")

    # slope of the quasi-static operator along its input (the paper's Fig. 1, alpha vs voltage)
    one = slice(0, per + 1)
    dv = np.diff(v[one])
    alpha = np.diff(s_static[one]) / np.where(dv == 0, np.nan, dv)
    vm = 0.5 * (v[one][1:] + v[one][:-1])
    rising = dv > 0
    ax_a.plot(vm[rising], alpha[rising], color="tab:green", label="rising (V_shift = 0 V)")
    ax_a.plot(vm[~rising], alpha[~rising], color="tab:purple",
              label="falling (V_shift = 100 V)")  # fmt: skip
    ax_a.axhline(p.alpha0_ue_per_V, color="0.5", ls=":", lw=1, label="α0")
    ax_a.set_xlabel("voltage V (V)")
    ax_a.set_ylabel("α = dS/dV (µε/V)")
    ax_a.set_title("(d) α = α0 + γ(1 - exp(-|V - V_shift|/Vc)), one cycle", fontsize=10)
    ax_a.legend(fontsize=8, loc="upper center")

    for ax in (ax_v, ax_s, ax_loop, ax_a):
        ax.grid(True, alpha=0.3)
    _suptitle(
        fig,
        "Dynamic hysteresis model, the paper's Table 1 parameters, 0-100 V unipolar sine at 1 Hz "
        "(cf. the paper's Fig. 1)",
    )
    return _save(fig, path)


# -- entry point ---------------------------------------------------------------------------------

FIGURES = (
    ("fig1_hysteresis_loop.png", figure_hysteresis_loop),
    ("fig3_frequency_response.png", figure_frequency_response),
    ("fig4_input_output.png", figure_input_output),
    ("fig5_step_response.png", figure_step_response),
)


def write_model_figures(out: Path, overwrite: bool = False) -> list[Path]:
    """Write the section-2 figures (the paper's Figs. 1, 3, 4, 5) as PNG files into ``out``
    (created if needed); existing files are refused before any drawing unless ``overwrite``
    (:class:`~labrig.core.errors.InputFileError`), and the files are written beside their targets,
    then renamed into place (:mod:`labrig.core.outputs`)."""
    from labrig.core.outputs import staged_outputs

    out = Path(out)
    targets = [out / name for name, _ in FIGURES]
    with staged_outputs(targets, overwrite=overwrite) as staged:
        for target, (_, fn) in zip(targets, FIGURES, strict=True):
            fn(staged.path(target))
    return targets
