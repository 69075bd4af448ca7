"""The live view's server beside ``labrig run --live``: a process of its own
(``python -m labrig.live``), in a session of its own so that the terminal's Ctrl-C goes to the
run alone (which ramps to 0 V and records ``aborted``; the page then shows it). The server
never opens the run file for writing and reads it in children of its own
(:mod:`labrig.live.frames`), so nothing it does can disturb the writer."""

from __future__ import annotations

import contextlib
import select
import subprocess
import sys
import time
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue

#: how long (s) the server may take to start and print its address
START_TIMEOUT_S = 20.0
#: how long (s) the server may take to stop after the run ended (it lingers for a page)
STOP_TIMEOUT_S = 10.0


class LiveProcess:
    """The server process; :attr:`url` once started."""

    def __init__(self, port: int = 0, params: Path | None = None):
        cmd = [sys.executable, "-m", "labrig.live", "--port", str(port)]
        if params is not None:
            cmd += ["--params", str(params)]
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.url = self._first_line()

    def _first_line(self) -> str:
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], START_TIMEOUT_S)
        line = self.proc.stdout.readline().strip() if ready else ""
        kind, _, rest = line.partition(" ")
        if kind == "url":
            return rest
        self.close()
        why = rest if kind == "error" else "the live view did not start"
        raise InputFileError([InputIssue("--live", None, "", why)])

    def _send(self, line: str) -> None:
        with contextlib.suppress(OSError, ValueError):
            assert self.proc.stdin is not None
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()

    def follow(self, path: Path) -> None:
        """The run file exists: read it."""
        self._send(f"file {path}")

    def end(self, final_path: Path | None) -> None:
        """The run ended (its file now at ``final_path``): the server reads its final state
        and goes on serving it until :meth:`close`."""
        self._send(f"end {final_path}" if final_path is not None else "end")

    @property
    def alive(self) -> bool:
        """The server is still running."""
        return self.proc.poll() is None

    def close(self) -> None:
        """Stop the server: it serves until a page open on the run has fetched the final
        state (at most :data:`labrig.live.server.LINGER_S`), then exits; it is killed after
        :data:`STOP_TIMEOUT_S`."""
        with contextlib.suppress(OSError, ValueError):
            if self.proc.stdin is not None:
                self.proc.stdin.close()
        deadline = time.monotonic() + STOP_TIMEOUT_S
        while self.proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
