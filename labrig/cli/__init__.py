"""The ``labrig`` command line (typer). Each command module parses its options, calls one
library function and prints; this module lists the commands, in the order ``--help`` shows them.

- :mod:`labrig.cli.run`: ``check``, ``run`` (protocols on the rig)
- :mod:`labrig.cli.files`: ``info``, ``export``, ``import`` (run files in and out)
- :mod:`labrig.cli.fit`, :mod:`labrig.cli.report`, :mod:`labrig.cli.diagnose`: the analysis
- :mod:`labrig.cli.model`: ``model demo``, ``model figures``; :mod:`labrig.cli.sim`: ``sim serve``
- :mod:`labrig.cli.common`: the error wrapper, shared options and the choices of options
"""

from __future__ import annotations

import typer

from labrig import __version__
from labrig.cli import diagnose, files, fit, report, run
from labrig.cli.batch import batch_app
from labrig.cli.model import model_app
from labrig.cli.runs import runs as runs_command
from labrig.cli.sim import sim_app
from labrig.cli.watch import watch as watch_command

__all__ = ["app"]

app = typer.Typer(
    name="labrig",
    help="Run piezo-actuator experiments on real or simulated rigs, log them to HDF5, and "
    "compare them with a fractional-order dynamic hysteresis model.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
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


app.command("check")(run.check)
app.command("run")(run.run)
app.command("watch")(watch_command)
app.command("info")(files.info)
app.command("runs")(runs_command)
app.command("export")(files.export)
app.command("import")(files.import_)
app.command("fit")(fit.fit)
app.command("report")(report.report)
app.command("diagnose")(diagnose.diagnose)
app.add_typer(model_app, name="model")
app.add_typer(sim_app, name="sim")
app.add_typer(batch_app, name="batch")
