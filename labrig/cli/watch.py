"""``labrig watch FILE``: the live view of a run file, from a second terminal while a run is
written (or of a finished file): the page ``labrig run --live`` serves (:mod:`labrig.live`)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import friendly


@friendly
def watch(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), being written or not."),
    port: int = typer.Option(
        0, "--port", min=0, max=65535, help="Port on 127.0.0.1 (default: a free one)."
    ),
    params: Path | None = typer.Option(
        None, "--params", help="Draw this model's prediction (a labrig fit --out file)."
    ),
) -> None:
    """Serve a live view of a run file on 127.0.0.1 until Ctrl-C (exit 0): the current entry's
    loop and time series during a run, every entry's loop once it has ended, the model's
    prediction, the progress and the amplifier (docs/live.md)."""
    import time

    from labrig.core.interrupts import Interrupted, interrupt_once
    from labrig.live import load_params, port_error
    from labrig.live.server import LiveServer
    from labrig.store import read_run

    read_run(run_file, load_data=False)  # a labrig run file, sound (exit 2 otherwise)
    model = load_params(params)
    try:
        server = LiveServer(run_file, model, port)
    except OSError as e:
        raise port_error(port, e, "--port") from None
    server.start()
    typer.echo(f"live view of {run_file}: {server.url} (Ctrl-C to stop)")
    # serve until a stop signal (Ctrl-C, SIGTERM, SIGHUP): stopping the view is how it ends
    with interrupt_once() as guard:
        try:
            there = True
            while True:
                time.sleep(0.5)
                if run_file.exists() != there:  # said once each time it goes or comes back
                    there = not there
                    typer.echo(
                        f"live view: {run_file} is back; reading it again"
                        if there
                        else f"live view: {run_file} is gone (deleted or renamed); the page "
                        "keeps the last state read",
                        err=True,
                    )
        except Interrupted:
            pass
        finally:
            with guard.defer():
                server.close()  # an open page is told, then the server stops (at most 3 s)
    typer.echo("live view: closed", err=True)
