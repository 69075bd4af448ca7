"""The live view's web server: a page and its data, on 127.0.0.1 only (docs/live.md).

A reader thread reads the run file about :data:`READ_HZ` times a second
(:func:`labrig.live.frames.read_frame`, each read in a child process with a time limit; a read
that fails or does not verify is skipped) into a :class:`~labrig.live.state.LiveState`. The
page (``static/``: plain HTML and JavaScript, no network) asks ``/frame`` for the state's JSON
document :data:`PAGE_POLL_MS` apart and redraws when its ``seq`` changed.

:class:`LiveServer` serves one run file; the file may not exist yet (``labrig run --live``
starts the server before the run and names the file once it exists: :meth:`LiveServer.follow`).
After :meth:`LiveServer.end`, :meth:`LiveServer.linger` keeps serving until a page has fetched
the run's final state (at most :data:`LINGER_S`), so a page open on the run shows how it ended.
"""

from __future__ import annotations

import contextlib
import json
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any

from labrig.live.frames import read_frame
from labrig.live.state import LiveState

HOST = "127.0.0.1"
#: reads of the run file per second (the writer flushes a block every 0.1 s)
READ_HZ = 12.0
#: how often the page asks for the state (ms); it redraws only when something changed
PAGE_POLL_MS = 80
#: after the run ends, serve at most this long (s) for a page to fetch the final state
LINGER_S = 3.0

#: the page's files, served from the package
STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/live.js": ("live.js", "text/javascript; charset=utf-8"),
    "/plot.js": ("plot.js", "text/javascript; charset=utf-8"),
    "/live.css": ("live.css", "text/css; charset=utf-8"),
}


def static_file(name: str) -> bytes:
    return resources.files("labrig.live").joinpath("static", name).read_bytes()


class LiveServer:
    """Serves the live view of one run file (module docstring)."""

    def __init__(self, path: Path | None, params: Any = None, port: int = 0):
        self.state = LiveState(params, source=str(path or ""))
        self.path = path
        self.lock = threading.Lock()
        self.ended = threading.Event()
        self.stopping = threading.Event()
        self.final_served = threading.Event()
        self.clients = 0
        self.httpd = ThreadingHTTPServer((HOST, port), _handler(self))
        self.httpd.daemon_threads = True
        self._threads: list[threading.Thread] = []

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.httpd.server_address[1]}/"

    def start(self) -> None:
        for target in (self.httpd.serve_forever, self._read_loop):
            t = threading.Thread(target=target, daemon=True)
            t.start()
            self._threads.append(t)

    def follow(self, path: Path) -> None:
        """Read ``path`` from now on (the run file once it exists, or where it was renamed)."""
        with self.lock:
            self.path = path
            self.state.source = str(path)

    def end(self, final_path: Path | None = None) -> None:
        """The run has ended (its file renamed to ``final_path``, if given)."""
        if final_path is not None:
            self.follow(final_path)
        self.ended.set()

    def linger(self) -> None:
        """After :meth:`end`: wait until a page fetched the final state (if any page ever
        connected), at most :data:`LINGER_S`."""
        deadline = time.monotonic() + LINGER_S
        while self.clients and time.monotonic() < deadline and not self.final_served.is_set():
            time.sleep(0.05)

    def stop(self) -> None:
        self.stopping.set()
        self.httpd.shutdown()
        self.httpd.server_close()

    # -- reading ----------------------------------------------------------------------------
    def _read_loop(self) -> None:
        period = 1.0 / READ_HZ
        while not self.stopping.is_set():
            t0 = time.monotonic()
            self.read_once()
            self.stopping.wait(max(0.0, period - (time.monotonic() - t0)))

    def read_once(self) -> None:
        """One read of the file into the state (a failed read is counted and skipped)."""
        with self.lock:
            path = self.path
            entry, start = self.state.next_request()
            known = dict(self.state.planned_samples)
        if path is None or not path.exists():
            return
        t0 = time.perf_counter()
        try:
            frame = read_frame(path, entry, start, known)
        except Exception as e:  # a torn read, a damaged file: skip this frame
            with self.lock:
                self.state.skipped += 1
                self.state.last_error = (str(e).splitlines() or [type(e).__name__])[0][:200]
            return
        with self.lock:
            self.state.path = str(path)
            self.state.take(frame, (time.perf_counter() - t0) * 1e3)
            self.state.last_error = ""

    def document(self) -> bytes:
        with self.lock:
            doc = self.state.document()
            final = doc.get("status") in ("complete", "aborted", "failed")
        doc["ended"] = self.ended.is_set()
        doc["poll_ms"] = PAGE_POLL_MS
        body = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()
        if final and self.ended.is_set():
            self.final_served.set()
        return body


def _handler(server: LiveServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            route = self.path.split("?", 1)[0]
            if route == "/frame":
                server.clients += 1
                self._send(server.document(), "application/json")
            elif route in STATIC:
                name, kind = STATIC[route]
                self._send(static_file(name), kind)
            else:
                self.send_error(HTTPStatus.NOT_FOUND)

        def _send(self, body: bytes, kind: str) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            with contextlib.suppress(OSError):  # the page went away
                self.wfile.write(body)

        def log_message(self, format: str, *args: Any) -> None:
            """Quiet: no line per request."""

    return Handler
