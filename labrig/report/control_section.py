"""The compensation-control part of ``labrig report`` (the paper's Figs. 15-17).

For every strain-command entry (a ``command_strain`` channel and a ``control`` key in its step
definition): the metrics of :func:`labrig.control.entry_metrics` (tracking NRMSE and hysteresis
width in % of the command span, strain at zero command; :func:`labrig.control.control_metrics`
gives them for ``labrig report --json``), and one figure per command pairing the direct and
compensated entries: measured strain versus command (Figs. 15-16) and the computed drive voltage
in time (Fig. 17). :func:`control_context` gives them to the template ``control.html.j2``,
which ``report.html.j2`` includes.
"""

from __future__ import annotations

from typing import Any

from matplotlib.figure import Figure

from labrig.analysis.records import Record
from labrig.control.metrics import control_metrics, is_control_entry
from labrig.report.plots import png, style_axes

__all__ = ["COLORS", "control_context", "control_metrics", "is_control_entry"]

COLORS = {"direct": "tab:blue", "compensated": "tab:red"}


def _pair_key(r: Record) -> tuple:
    m = r.meta
    return (m.get("kind"), m.get("amplitude_ue"), m.get("frequency_hz"))


def _figure(group: list[Record]) -> bytes:
    fig = Figure(figsize=(11, 3.6))
    ax_l, ax_t, ax_v = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 1.3, 1.3]})
    for r in sorted(group, key=lambda r: r.meta["control"]):
        i0 = int(r.meta.get("command_start_index", 0))
        i1 = int(r.meta.get("command_stop_index", r.strain_ue.size))
        c, s = r.aux["command_strain"][i0:i1], r.strain_ue[i0:i1]
        t = r.time_s[i0:i1] - r.time_s[i0]
        col = COLORS.get(r.meta["control"], "k")
        ax_l.plot(c, s, color=col, lw=0.8, label=r.meta["control"])
        ax_t.plot(t, s, color=col, lw=0.8, label=f"measured, {r.meta['control']}")
        ax_v.plot(t, r.voltage_V[i0:i1], color=col, lw=0.8, label=r.meta["control"])
    r0 = group[0]
    i0 = int(r0.meta.get("command_start_index", 0))
    i1 = int(r0.meta.get("command_stop_index", r0.strain_ue.size))
    c0 = r0.aux["command_strain"][i0:i1]
    ax_l.plot([c0.min(), c0.max()], [c0.min(), c0.max()], "k:", lw=0.8, label="ideal")
    ax_t.plot(r0.time_s[i0:i1] - r0.time_s[i0], c0, "k:", lw=0.8, label="command")
    ax_l.set(xlabel="command strain (ue)", ylabel="measured strain (ue)", title="Figs. 15-16")
    ax_t.set(xlabel="time (s)", ylabel="strain (ue)", title="tracking")
    ax_v.set(xlabel="time (s)", ylabel="drive voltage (V)", title="computed voltage (Fig. 17)")
    for ax in (ax_l, ax_t, ax_v):
        style_axes(ax)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return png(fig)


def _number(x: float | None, spec: str = ".2f") -> str:
    return "—" if x is None else format(x, spec)


def control_context(records: list[Record]) -> dict[str, Any] | None:
    """The section's rows and figures (``None`` when the run has no strain-command entry)."""
    entries = [r for r in records if is_control_entry(r)]
    if not entries:
        return None
    metrics = control_metrics(entries)
    rows = [
        {
            "name": r.name,
            "control": str(metrics[r.name]["control"]),
            "frequency": _number(metrics[r.name]["frequency_hz"], "g"),
            "tracking": _number(metrics[r.name]["tracking_nrmse_pct"]),
            "width": _number(metrics[r.name]["hysteresis_width_pct"]),
            "zero": _number(metrics[r.name]["zero_command_strain_ue"], ".1f"),
        }
        for r in entries
    ]
    groups: dict[tuple, list[Record]] = {}
    for r in entries:
        groups.setdefault(_pair_key(r), []).append(r)
    figures = []
    for (kind, amp, freq), grp in groups.items():
        caption = f"{kind} {amp:g} ue" if amp is not None else str(kind)
        caption += f" at {freq:g} Hz" if freq else ""
        figures.append({"png": _figure(grp), "caption": caption})
    return {"rows": rows, "figures": figures}
