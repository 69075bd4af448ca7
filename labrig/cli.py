"""The ``labrig`` command line (typer): thin; parses, calls, prints."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig import __version__

app = typer.Typer(
    name="labrig",
    help="Run piezo-actuator experiments on real or simulated rigs, log them to HDF5, and "
    "compare them with a fractional-order dynamic hysteresis model.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
model_app = typer.Typer(help="The dynamic hysteresis model: demo and the seed's figures.")
app.add_typer(model_app, name="model")


def _version(value: bool) -> None:
    if value:
        typer.echo(f"labrig {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """labrig: piezo rigs, HDF5 run files, and the fractional-order hysteresis model."""


@model_app.command("demo")
def model_demo(
    preset: str = typer.Option("PAPER_TABLE1", help="Parameter preset."),
    amplitude_v: float = typer.Option(100.0, help="Peak of the unipolar sine (V)."),
    frequency_hz: float = typer.Option(1.0, help="Sine frequency (Hz)."),
    cycles: int = typer.Option(5, help="Number of cycles."),
    rate_hz: float = typer.Option(1000.0, help="Sample rate (Hz)."),
) -> None:
    """Print the model's strain for a unipolar sine (the seed's sweep) as a short table."""
    from labrig.cli_model import run_demo

    run_demo(preset, amplitude_v, frequency_hz, cycles, rate_hz)


@model_app.command("figures")
def model_figures(
    out: Path = typer.Option(Path("figures"), "--out", help="Output directory for PNG files."),
) -> None:
    """Regenerate the seed's section-2 figures (Figs. 1, 3, 4, 5) as PNG files."""
    from labrig.report.model_figures import write_model_figures

    for path in write_model_figures(out):
        typer.echo(str(path))


if __name__ == "__main__":  # pragma: no cover
    app()
