"""The live view's server beside ``labrig run --live``: a process of its own
(``python -m labrig.live``), in a session of its own so that the terminal's Ctrl-C goes to the
run alone (which ramps to 0 V and records ``aborted``; the page then shows it). The server
never opens the run file for writing and reads it in children of its own
(:mod:`labrig.live.frames`), so nothing it does can disturb the writer.

A server that stops by itself (its process killed or crashed, or ended after one of its
threads failed: it then prints ``failed WHY``, :mod:`labrig.live.__main__`) is found by
:meth:`LiveProcess.stopped`, which says why once; the run goes on without it."""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue

#: how long (s) the server may take to start and print its address
START_TIMEOUT_S = 20.0
#: how long (s) the server may take to stop after the run ended (it lingers for a page)
STOP_TIMEOUT_S = 10.0


def server_command(port: int, params: Path | None) -> list[str]:
    """The command line of the server process."""
    cmd = [sys.executable, "-m", "labrig.live", "--port", str(port)]
    return [*cmd, "--params", str(params)] if params is not None else cmd


class LiveProcess:
    """The server process; :attr:`url` once started."""

    def __init__(self, port: int = 0, params: Path | None = None):
        self.proc = subprocess.Popen(
            server_command(port, params),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            start_new_session=True,
        )
        #: what the server printed and has not been taken yet (bytes: read without blocking)
        self._said = b""
        #: the server was told to close (:meth:`close`); its stop was said (:meth:`stopped`)
        self._closing = self._told = False
        self.url = self._first_line()

    def _read_said(self, timeout: float) -> bool:
        """Add what the server has printed to :attr:`_said`, waiting at most ``timeout`` s for
        it: False when nothing came (or its output has ended)."""
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        try:
            if not select.select([fd], [], [], max(0.0, timeout))[0]:
                return False
            chunk = os.read(fd, 65536)
        except (OSError, ValueError):
            return False
        self._said += chunk
        return bool(chunk)

    def _first_line(self) -> str:
        deadline = time.monotonic() + START_TIMEOUT_S
        while b"\n" not in self._said and self._read_said(deadline - time.monotonic()):
            pass
        line, _, self._said = self._said.partition(b"\n")
        kind, _, rest = line.decode("utf-8", "replace").strip().partition(" ")
        if kind == "url":
            return rest
        self.close()
        why = rest if kind == "error" else "the live view did not start"
        raise InputFileError([InputIssue("--live", None, "", why)])

    def _send(self, line: str) -> None:
        with contextlib.suppress(OSError, ValueError):
            assert self.proc.stdin is not None
            self.proc.stdin.write(line.encode() + b"\n")
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

    def stopped(self) -> str:
        """Why the server stopped by itself, said once: its ``failed`` line, else how its
        process ended (killed by a signal, an exit code); "" while it runs, once said, and
        after :meth:`close`. Waits for nothing (a check per block of the run)."""
        if self._told or self._closing or self.alive:
            return ""
        self._told = True
        while self._read_said(0.0):  # what it printed before it ended
            pass
        for line in self._said.decode("utf-8", "replace").splitlines():
            kind, _, why = line.strip().partition(" ")
            if kind == "failed" and why:
                return why
        code = self.proc.returncode
        if code < 0:
            with contextlib.suppress(ValueError):
                return f"its process was killed by {signal.Signals(-code).name}"
            return f"its process was killed by signal {-code}"
        return f"its process ended with exit code {code}"

    def close(self) -> None:
        """Stop the server: it serves until a page open on the run has fetched the final
        state (at most :data:`labrig.live.server.LINGER_S`), then exits; it is killed after
        :data:`STOP_TIMEOUT_S`."""
        self._closing = True
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
