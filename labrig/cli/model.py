"""``labrig model``: the dynamic hysteresis model on its own (``demo``: its response to the
paper's unipolar sine as a table; ``figures``: the paper's section-2 figures as PNG files)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    Preset,
    check_out,
    choice,
    deliver_json,
    friendly,
    json_option,
    json_text,
    one_of,
    out_file_option,
)
from labrig.cli.typer_app import LabrigTyper

#: ``labrig model demo``'s sine: the fewest samples a period (a loop needs its two halves) and
#: the most samples in all (about 80 MB of arrays)
DEMO_MIN_SAMPLES_PER_PERIOD = 8
DEMO_MAX_SAMPLES = 10_000_000
#: the largest demo amplitude (V): a hundred times the presets' stacks' drives, far from
#: where float64 overflows (the trial's 1e306 V printed a loop width of -6e306 ue)
DEMO_MAX_AMPLITUDE_V = 1e4

model_app = LabrigTyper(help="The dynamic hysteresis model: demo and the paper's figures.")


@model_app.command("demo")
@friendly
def demo(
    preset: Preset = typer.Option(
        Preset.PAPER_TABLE1,
        parser=choice(Preset, "a parameter preset"),
        metavar="PRESET",
        help=f"Parameter preset: {one_of(Preset)}.",
    ),
    amplitude_v: float = typer.Option(
        100.0, help="Peak of the unipolar sine (V, above 0, at most 10 000)."
    ),
    frequency_hz: float = typer.Option(1.0, help="Sine frequency (Hz, above 0)."),
    cycles: int = typer.Option(5, min=1, help="Number of cycles."),
    rate_hz: float = typer.Option(
        1000.0, help=f"Sample rate (Hz; at least {DEMO_MIN_SAMPLES_PER_PERIOD} samples a period)."
    ),
    as_json: bool = json_option("the table (one row per cycle)"),
    out: Path | None = out_file_option("the table as JSON (what --json prints)"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Print the model's strain for a unipolar sine (the paper's sweep) as a short table."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from labrig.model import PRESETS, DynamicHysteresisModel

    check_demo_sine(amplitude_v, frequency_hz, cycles, rate_hz)
    check_out(out, [], overwrite)
    model = DynamicHysteresisModel(PRESETS[preset.value])
    t = np.arange(round(cycles * rate_hz / frequency_hz) + 1) / rate_hz
    v = amplitude_v / 2 * (1 - np.cos(2 * np.pi * frequency_hz * t))
    s = model.predict(v, rate_hz)
    per = round(rate_hz / frequency_hz)
    rows = []
    for k in range(cycles):
        seg = slice(k * per, (k + 1) * per + 1)
        vs, ss = v[seg], s[seg]
        half = len(vs) // 2
        mid = amplitude_v / 2
        up = np.interp(mid, vs[:half], ss[:half])
        down = np.interp(mid, vs[half:][::-1], ss[half:][::-1])
        rows.append(
            {
                "cycle": k + 1,
                "max_strain_ue": float(ss.max()),
                "strain_at_0V_ue": float(ss[-1]),
                "loop_width_at_mid_ue": float(down - up),
            }
        )
    doc = {
        "preset": preset.value,
        "amplitude_V": amplitude_v,
        "frequency_hz": frequency_hz,
        "rate_hz": rate_hz,
        "cycles": rows,
    }
    if not deliver_json(doc, as_json=as_json, out=out, overwrite=overwrite):
        return
    table = Table(title=f"{preset}: {amplitude_v:g} V unipolar sine at {frequency_hz:g} Hz")
    for col in ("cycle", "max strain (ue)", "strain at 0 V (ue)", "loop width at mid (ue)"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(
            str(r["cycle"]),
            f"{r['max_strain_ue']:.1f}",
            f"{r['strain_at_0V_ue']:.1f}",
            f"{r['loop_width_at_mid_ue']:.1f}",
        )
    Console().print(table)


@model_app.command("figures")
@friendly
def figures(
    out: Path = typer.Option(
        Path("figures"), "--out", metavar="DIR", help="Folder for the PNG files."
    ),
    as_json: bool = json_option("the files written"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Regenerate the paper's section-2 figures as PNG files (its figures 1, 3, 4 and 5)."""
    from labrig.report.model_figures import write_model_figures

    paths = write_model_figures(out, overwrite=overwrite)
    if as_json:
        typer.echo(json_text({"files": [str(p) for p in paths]}))
        return
    for path in paths:
        typer.echo(str(path))


def check_demo_sine(amplitude_v: float, frequency_hz: float, cycles: int, rate_hz: float) -> None:
    """Refuse a demo sine that cannot be drawn as loops: a usage error (exit 64) naming the
    option and what would be valid."""
    import math

    for value, name, unit in (
        (amplitude_v, "--amplitude-v", "V"),
        (frequency_hz, "--frequency-hz", "Hz"),
    ):
        if not (math.isfinite(value) and value > 0):
            raise typer.BadParameter(f"{value:g}: must be a number above 0 {unit}", param_hint=name)
    if amplitude_v > DEMO_MAX_AMPLITUDE_V:
        raise typer.BadParameter(
            f"{amplitude_v:g}: must be at most {DEMO_MAX_AMPLITUDE_V:g} V (the presets describe "
            "stacks driven to 100-200 V; the strain of 1e306 V overflows)",
            param_hint="--amplitude-v",
        )
    low = DEMO_MIN_SAMPLES_PER_PERIOD * frequency_hz
    if not (math.isfinite(rate_hz) and rate_hz >= low):
        raise typer.BadParameter(
            f"{rate_hz:g}: must be at least {low:g} Hz ({DEMO_MIN_SAMPLES_PER_PERIOD} samples a "
            f"period of {frequency_hz:g} Hz)",
            param_hint="--rate-hz",
        )
    if cycles * rate_hz / frequency_hz > DEMO_MAX_SAMPLES:
        raise typer.BadParameter(
            f"{cycles} cycles of {rate_hz / frequency_hz:.6g} samples: at most "
            f"{DEMO_MAX_SAMPLES:,} samples in all; fewer cycles or a lower rate",
            param_hint="--cycles/--rate-hz",
        )
