"""``labrig model``: the dynamic hysteresis model on its own (``demo``: its response to the
paper's unipolar sine as a table; ``figures``: the paper's section-2 figures as PNG files)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import Preset, choice, one_of

model_app = typer.Typer(help="The dynamic hysteresis model: demo and the paper's figures.")


@model_app.command("demo")
def demo(
    preset: Preset = typer.Option(
        Preset.PAPER_TABLE1,
        parser=choice(Preset, "a parameter preset"),
        metavar="<preset>",
        help=f"Parameter preset: {one_of(Preset)}.",
    ),
    amplitude_v: float = typer.Option(100.0, help="Peak of the unipolar sine (V)."),
    frequency_hz: float = typer.Option(1.0, help="Sine frequency (Hz)."),
    cycles: int = typer.Option(5, help="Number of cycles."),
    rate_hz: float = typer.Option(1000.0, help="Sample rate (Hz)."),
) -> None:
    """Print the model's strain for a unipolar sine (the paper's sweep) as a short table."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from labrig.model import PRESETS, DynamicHysteresisModel

    model = DynamicHysteresisModel(PRESETS[preset.value])
    t = np.arange(round(cycles * rate_hz / frequency_hz) + 1) / rate_hz
    v = amplitude_v / 2 * (1 - np.cos(2 * np.pi * frequency_hz * t))
    s = model.predict(v, rate_hz)
    per = round(rate_hz / frequency_hz)
    table = Table(title=f"{preset}: {amplitude_v:g} V unipolar sine at {frequency_hz:g} Hz")
    for col in ("cycle", "max strain (ue)", "strain at 0 V (ue)", "loop width at mid (ue)"):
        table.add_column(col, justify="right")
    for k in range(cycles):
        seg = slice(k * per, (k + 1) * per + 1)
        vs, ss = v[seg], s[seg]
        half = len(vs) // 2
        mid = amplitude_v / 2
        up = np.interp(mid, vs[:half], ss[:half])
        down = np.interp(mid, vs[half:][::-1], ss[half:][::-1])
        table.add_row(str(k + 1), f"{ss.max():.1f}", f"{ss[-1]:.1f}", f"{down - up:.1f}")
    Console().print(table)


@model_app.command("figures")
def figures(
    out: Path = typer.Option(Path("figures"), "--out", help="Output directory for PNG files."),
) -> None:
    """Regenerate the paper's section-2 figures (Figs. 1, 3, 4, 5) as PNG files."""
    from labrig.report.model_figures import write_model_figures

    for path in write_model_figures(out):
        typer.echo(str(path))
