"""The live view of a run (``labrig run --live``, ``labrig watch FILE``; docs/live.md): a page
on 127.0.0.1 that draws the current entry's loop and time series, the model's prediction, the
progress and the amplifier's state, read from the run file as it is written.

- :mod:`labrig.live.frames`: one verified read of a file being written (in a child process);
- :mod:`labrig.live.state`: the samples so far, the prediction, the page's JSON document;
- :mod:`labrig.live.server`: the HTTP server and its reader thread; ``static/`` the page;
- :mod:`labrig.live.launch`: the server as a process of its own beside ``labrig run``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from labrig.core.errors import InputFileError, InputIssue


def load_params(path: Path | None) -> Any:
    """The model parameters of a ``labrig fit --out`` file for the prediction (None: none)."""
    if path is None:
        return None
    from labrig.analysis.params_file import read_params_file

    return read_params_file(path, "the live view").params


def port_error(port: int, e: OSError, option: str = "--live-port") -> InputFileError:
    """A port that cannot be served on, as bad input (exit 2) naming the ``option`` that gave
    it (``run --live-port``, ``watch --port``)."""
    why = e.strerror or str(e)
    return InputFileError(
        [InputIssue(f"127.0.0.1:{port}", None, option, f"cannot serve there: {why}")]
    )
