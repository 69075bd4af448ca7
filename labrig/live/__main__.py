"""``python -m labrig.live``: the live view's server as a process of its own, for
``labrig run --live`` (:mod:`labrig.live.launch`). Prints ``url URL`` (or ``error MESSAGE`` and
exits 2), then reads commands on stdin: ``file PATH`` (read that file), ``end [PATH]`` (the run
ended, its file now at PATH: the server reads its final state and goes on serving it). At the
end of input it closes (:meth:`labrig.live.server.LiveServer.close`): once a page has fetched
the final state and been told, or :data:`labrig.live.server.LINGER_S` after the end of input,
whichever comes first.

When the view cannot serve any more (one of its threads failed or ended:
:attr:`labrig.live.server.LiveServer.failure`; or a command failed) it prints ``failed WHY``
(one line, no traceback), stops and exits 1: ``labrig run`` tells the person and goes on with
the run."""

from __future__ import annotations

import argparse
import contextlib
import queue
import signal
import sys
import threading
from pathlib import Path
from typing import TextIO

from labrig.core.errors import LabrigError
from labrig.live import load_params, port_error
from labrig.live.server import LiveServer

#: what the command loop waits for: ("command", line), ("failed", why) or ("end", "")
Event = tuple[str, str]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m labrig.live")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--params", type=Path, default=None)
    args = ap.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the run's Ctrl-C is the run's to handle
    events: queue.Queue[Event] = queue.Queue()
    try:
        params = load_params(args.params)
        try:
            server = LiveServer(None, params, args.port, lambda why: events.put(("failed", why)))
        except OSError as e:
            raise port_error(args.port, e) from None
    except LabrigError as e:
        print(f"error {e}", flush=True)
        return 2
    server.start()
    print(f"url {server.url}", flush=True)
    threading.Thread(target=_read_commands, args=(sys.stdin, events), daemon=True).start()
    try:
        why = _serve(server, events)
    except Exception as e:  # a command the view could not carry out: it stops, said once
        why = f"{type(e).__name__}: {e}".splitlines()[0][:200]
    if not why:
        return 0
    with contextlib.suppress(OSError, ValueError):  # (the run command may have gone)
        print(f"failed {why}", flush=True)
    server.stop()
    return 1


def _serve(server: LiveServer, events: queue.Queue[Event]) -> str:
    """Carry out the commands until the end of input (then close the view: ``""``) or until
    the view fails (its reason, the view not closed)."""
    while True:
        kind, text = events.get()
        if kind == "failed":
            return text
        if kind == "end":
            break
        command, _, arg = text.strip().partition(" ")
        if command == "file" and arg:
            server.follow(Path(arg))
        elif command == "end":
            server.end(Path(arg) if arg else None)
            server.read_once()  # the final state, read now (the reader thread goes on)
    # end of input: the run command is closing the view (or has gone)
    server.end()
    server.read_once()
    server.close()
    return ""


def _read_commands(stream: TextIO, events: queue.Queue[Event]) -> None:
    """Put each line of ``stream`` on ``events``, then its end (also when it cannot be read)."""
    try:
        for line in stream:
            events.put(("command", line))
    except (OSError, ValueError):  # input that cannot be read: as its end
        pass
    finally:
        events.put(("end", ""))


if __name__ == "__main__":
    sys.exit(main())
