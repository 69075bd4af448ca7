"""The ``labrig`` command line (typer): thin; parses, calls, prints."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import typer

from labrig import __version__
from labrig.errors import LabrigError

app = typer.Typer(
    name="labrig",
    help="Run piezo-actuator experiments on real or simulated rigs, log them to HDF5, and "
    "compare them with a fractional-order dynamic hysteresis model.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
model_app = typer.Typer(help="The dynamic hysteresis model: demo and the seed's figures.")
app.add_typer(model_app, name="model")
sim_app = typer.Typer(help="The simulated bench: run its instrument simulators standalone.")
app.add_typer(sim_app, name="sim")


# options shared by `fit` and `report`
WARMUP_OPTION = typer.Option(
    None, "--warmup-s", help="Seconds of each record simulated but not scored (default: auto)."
)
HELDOUT_OPTION = typer.Option(
    True, "--heldout/--no-heldout", help="Leave-one-entry-out NRMSE (the slow part)."
)
OFFSET_OPTION = typer.Option(
    None,
    "--offset/--no-offset",
    help="Fit one strain offset per entry (default: on for imported data).",
)


def friendly(fn: Callable) -> Callable:
    """Expected failures print one clear message (no traceback) and exit with their code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except LabrigError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(e.exit_code) from None
        except FileExistsError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            typer.echo("interrupted", err=True)
            raise typer.Exit(130) from None

    return wrapper


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


@app.command("check")
@friendly
def check(
    protocol: Path = typer.Argument(..., help="Protocol file (YAML)."),
    rig: Path | None = typer.Option(
        None,
        "--rig",
        help="Rig file (default: the protocol's `rig`, else the built-in simulated rig).",
    ),
) -> None:
    """Validate a protocol and preflight it against the rig's limits; touches no hardware."""
    from rich.console import Console

    from labrig.protocol.check import format_plan
    from labrig.runner import preflight

    plan, _ = preflight(protocol, rig)
    Console().print(format_plan(plan))
    typer.echo(f"{protocol}: OK, {len(plan.steps)} entries, {plan.total_duration_s:.1f} s")


@app.command("run")
@friendly
def run(
    protocol: Path = typer.Argument(..., help="Protocol file (YAML)."),
    rig: Path | None = typer.Option(
        None,
        "--rig",
        help="Rig file (default: the protocol's `rig`, else the built-in simulated rig).",
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Run file to write (default: runs/NAME-DATE-TIME.h5)."
    ),
    seed: int | None = typer.Option(None, "--seed", help="Random seed of the simulated rig."),
    realtime: bool = typer.Option(False, "--realtime", help="Pace a simulated rig to the clock."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing --out file."),
) -> None:
    """Preflight a protocol, run it on the rig, and log every step to an HDF5 run file."""
    from labrig.cli_run import run_with_progress

    code = run_with_progress(protocol, rig, out, seed, realtime, overwrite)
    raise typer.Exit(code)


@app.command("info")
@friendly
def info(run_file: Path = typer.Argument(..., help="Run file (HDF5).")) -> None:
    """Summarise a run file: entries, status, durations, ranges."""
    from rich.console import Console

    from labrig.store import run_info

    Console().print(run_info(run_file))


@app.command("export")
@friendly
def export(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    csv: Path = typer.Option(..., "--csv", help="Directory for one CSV file per entry."),
) -> None:
    """Export every entry of a run file to CSV (header: column names with units)."""
    from labrig.store import export_csv

    for p in export_csv(run_file, csv):
        typer.echo(str(p))


@app.command("import")
@friendly
def import_(
    files: list[Path] = typer.Argument(..., help="Data files: delimited text or MATLAB .mat."),
    out: Path = typer.Option(..., "--out", help="Run file to write (HDF5)."),
    time: str | None = typer.Option(None, "--time", help="Time column: name or 1-based index."),
    voltage: str | None = typer.Option(None, "--voltage", help="Voltage column (name/index)."),
    strain: str | None = typer.Option(None, "--strain", help="Strain column (name/index)."),
    rate_hz: float | None = typer.Option(None, "--rate-hz", help="Sample rate if no time column."),
    voltage_scale: float = typer.Option(1.0, help="Multiply the voltage column (e.g. amp gain)."),
    voltage_offset: float = typer.Option(0.0, help="Then add this (V)."),
    strain_scale: float = typer.Option(1.0, help="Multiply the strain column (to ue)."),
    strain_offset: float = typer.Option(0.0, help="Then add this."),
    strain_units: str = typer.Option("ue", help="Units of the scaled strain column."),
    aux: list[str] = typer.Option(
        [],
        "--aux",
        help="Extra channel to keep: NAME or NAME=COLUMN "
        "(NAME like temperature_C gives name and unit).",
    ),
    delimiter: str | None = typer.Option(None, help="Column delimiter (default: detect)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing --out file."),
) -> None:
    """Bring measured data into a run file, one entry per input file (named after its stem)."""
    from labrig.importer import ImportOptions, import_files

    opt = ImportOptions(
        time=time, voltage=voltage, strain=strain, rate_hz=rate_hz,
        voltage_scale=voltage_scale, voltage_offset=voltage_offset,
        strain_scale=strain_scale, strain_offset=strain_offset, strain_units=strain_units,
        aux=list(aux), delimiter=delimiter,
    )  # fmt: skip
    for e in import_files(list(files), out, opt, overwrite):
        cols = ", ".join(f"{k}={v}" for k, v in e.columns.items())
        typer.echo(f"{e.name}: {e.voltage_V.size} samples at {e.rate_hz:g} Hz ({cols})")
    typer.echo(str(out))


@app.command("fit")
@friendly
def fit(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), recorded or imported."),
    entries: str | None = typer.Option(
        None, "--entries", help="Entries to fit, comma-separated (default: every complete one)."
    ),
    out: Path | None = typer.Option(None, "--out", help="Write the result as JSON to this file."),
    as_json: bool = typer.Option(False, "--json", help="Print only the JSON result on stdout."),
    method: str = typer.Option("global", "--method", help="global (default) or staged (seed 3.1)."),
    model: str = typer.Option(
        "dynamic", "--model", help="dynamic (ours), prandtl_ishlinskii or bouc_wen."
    ),
    warmup_s: float | None = WARMUP_OPTION,
    heldout: bool = HELDOUT_OPTION,
    offset: bool | None = OFFSET_OPTION,
    effect: list[str] = typer.Option(
        [],
        "--effect",
        help="Also fit this library effect with the model (repeatable), e.g. "
        "viscoelastic_creep (which compensation control inverts); see docs/diagnose.md.",
    ),
    memory: str = typer.Option(
        "return_point",
        "--memory",
        help="The hysteresis operator's memory: return_point (default; minor loops close and "
        "are forgotten) or last_reversal (the seed's single memory); docs/analysis.md.",
    ),
) -> None:
    """Identify the model (or a baseline) from a run file; print parameters and NRMSE."""
    from labrig.cli_analysis import run_fit

    run_fit(
        run_file, entries, out, as_json, method, model, warmup_s, heldout, offset, effect, memory
    )


@app.command("report")
@friendly
def report(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), recorded or imported."),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained)."),
    params: Path | None = typer.Option(
        None, "--params", help="Parameters from `labrig fit --out` (default: fit now)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the metrics table as JSON."),
    entries: str | None = typer.Option(
        None, "--entries", help="Entries to report, comma-separated (default: every complete one)."
    ),
    method: str = typer.Option(
        "global", "--method", help="Fit method when fitting: global|staged."
    ),
    warmup_s: float | None = WARMUP_OPTION,
    heldout: bool = HELDOUT_OPTION,
    offset: bool | None = OFFSET_OPTION,
) -> None:
    """Model versus measurement as one HTML file; baselines fitted on the same data."""
    from labrig.cli_analysis import run_report

    run_report(run_file, params, out, as_json, entries, warmup_s, heldout, offset, method)


@app.command("diagnose")
@friendly
def diagnose(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    params: Path | None = typer.Option(
        None, "--params", help="Start parameters (ModelParams JSON or `labrig fit` output)."
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Directory for diagnosis.json and diagnosis.html."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print only the JSON on stdout."),
    also: list[str] = typer.Option(
        [],
        "--also",
        help="Also try this structural effect (repeatable): remanence, viscoelastic_creep "
        "(not default candidates; docs/diagnose.md).",
    ),
    max_effects: int = typer.Option(
        2, "--max-effects", min=1, max=4, help="Add at most this many effects (1-4)."
    ),
) -> None:
    """Find what the model misses: residual evidence, candidate effects, held-out before/after."""
    from labrig.cli_diagnose import check_also, diagnose_command

    raise typer.Exit(
        diagnose_command(run_file, params, out, as_json, check_also(also), max_effects)
    )


@sim_app.command("serve")
@friendly
def sim_serve(
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (default: built-in sim rig)."),
) -> None:
    """Start the simulated amplifier (GCS) and conditioner (Modbus) servers; Ctrl-C stops."""
    from labrig.drivers.sim.serve import serve

    serve(rig)


if __name__ == "__main__":  # pragma: no cover
    app()
