"""The ``labrig`` command line (typer). Each command module parses its options, calls one
library function and prints; this module lists the commands, in the order ``--help`` shows them.

- :mod:`labrig.cli.check`: ``check`` (a protocol against the rig, its drivers loaded);
  :mod:`labrig.cli.run`: ``run`` (protocols on the rig)
- :mod:`labrig.cli.files`: ``info``, ``export``, ``import`` (run files in and out)
- :mod:`labrig.cli.fit`, :mod:`labrig.cli.report`, :mod:`labrig.cli.diagnose`,
  :mod:`labrig.cli.validate`: the analysis
- :mod:`labrig.cli.model`: ``model demo``, ``model figures``; :mod:`labrig.cli.sim`: ``sim serve``
- :mod:`labrig.cli.drivers`: ``drivers`` (the installed drivers); :mod:`labrig.cli.runs`:
  ``runs`` (the catalogue); :mod:`labrig.cli.watch`: ``watch`` (the live view of a run file)
- :mod:`labrig.cli.batch`: ``batch fit|diagnose|report`` (many run files, on Dask)
- :mod:`labrig.cli.common`: the error wrapper, shared options, the choices of options and the
  output convention (docs/outputs.md); :mod:`labrig.cli.typer_app`: the command classes (usage
  errors exit 64, plain metavars, the help layout of :mod:`labrig.cli.help_format`)
"""

from __future__ import annotations

import contextlib
import sys

import typer

from labrig.cli import check, diagnose, drivers, files, fit, report, run, validate
from labrig.cli.batch import batch_app
from labrig.cli.model import model_app
from labrig.cli.runs import runs as runs_command
from labrig.cli.sim import sim_app
from labrig.cli.typer_app import LabrigTyper
from labrig.cli.watch import watch as watch_command
from labrig.core.version import __version__

__all__ = ["app"]

app = LabrigTyper(
    name="labrig",
    help="Run piezo-actuator experiments on real or simulated rigs, log them to HDF5, and "
    "compare them with a fractional-order dynamic hysteresis model.",
    no_args_is_help=True,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"labrig {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_version,
        is_eager=True,
        metavar="",
        help="Print the version and exit.",
    ),
) -> None:
    """labrig: piezo rigs, HDF5 run files, and the fractional-order hysteresis model."""
    for stream in (sys.stdout, sys.stderr):  # a file name that is not UTF-8 prints as its bytes
        with contextlib.suppress(AttributeError, ValueError):
            stream.reconfigure(errors="surrogateescape")  # type: ignore[union-attr]


app.command("check")(check.check)
app.command("run")(run.run)
app.command("watch")(watch_command)
app.command("drivers")(drivers.drivers)
app.command("info")(files.info)
app.command("runs")(runs_command)
app.command("export")(files.export)
app.command("import")(files.import_)
app.command("fit")(fit.fit)
app.command("report")(report.report)
app.command("diagnose")(diagnose.diagnose)
app.command("validate")(validate.validate)
app.add_typer(model_app, name="model")
app.add_typer(sim_app, name="sim")
app.add_typer(batch_app, name="batch")
