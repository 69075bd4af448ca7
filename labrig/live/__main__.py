"""``python -m labrig.live``: the live view's server as a process of its own, for
``labrig run --live`` (:mod:`labrig.live.launch`). Prints ``url URL`` (or ``error MESSAGE`` and
exits 2), then reads commands on stdin: ``file PATH`` (read that file), ``end [PATH]`` (the run
ended, its file now at PATH: the server reads its final state and goes on serving it). At the
end of input it closes (:meth:`labrig.live.server.LiveServer.close`): once a page has fetched
the final state and been told, or :data:`labrig.live.server.LINGER_S` after the end of input,
whichever comes first."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from labrig.core.errors import LabrigError
from labrig.live import load_params, port_error
from labrig.live.server import LiveServer


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m labrig.live")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--params", type=Path, default=None)
    args = ap.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the run's Ctrl-C is the run's to handle
    try:
        params = load_params(args.params)
        try:
            server = LiveServer(None, params, args.port)
        except OSError as e:
            raise port_error(args.port, e) from None
    except LabrigError as e:
        print(f"error {e}", flush=True)
        return 2
    server.start()
    print(f"url {server.url}", flush=True)
    for line in sys.stdin:
        command, _, arg = line.strip().partition(" ")
        if command == "file" and arg:
            server.follow(Path(arg))
        elif command == "end":
            server.end(Path(arg) if arg else None)
            server.read_once()  # the final state, read now (the reader thread goes on)
    # end of input: the run command is closing the view (or has gone)
    server.end()
    server.read_once()
    server.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
