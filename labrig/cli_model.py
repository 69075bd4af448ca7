"""``labrig model demo``: the model's response to the seed's unipolar sine, as a table."""

from __future__ import annotations

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from labrig.model import PRESETS, DynamicHysteresisModel


def run_demo(preset: str, amplitude_v: float, frequency_hz: float, cycles: int, rate_hz: float):
    if preset not in PRESETS:
        choices = ", ".join(PRESETS)
        typer.echo(f"error: unknown preset {preset!r}; choose one of {choices}", err=True)
        raise typer.Exit(2)
    model = DynamicHysteresisModel(PRESETS[preset])
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
