"""The live view's web server: a page and its data, on 127.0.0.1 only (docs/live.md).

A reader thread reads the run file about :data:`READ_HZ` times a second while the run goes on
(:data:`READ_HZ_ENDED` once it has ended; :func:`labrig.live.frames.read_frame`, each read in a
child process with a time limit; a read that fails or does not verify is skipped) into a
:class:`~labrig.live.state.LiveState`. A second thread reads every entry that has ended once,
whole (:func:`labrig.live.frames.read_entry`), for the overlay of earlier entries and the
end-of-run page. The page (``static/``: HTML, JavaScript and the vendored uPlot, no network)
asks ``/frame`` for the state's JSON document :data:`PAGE_POLL_MS` apart and redraws when its
``seq`` changed; ``/loops`` gives every ended entry's loop, ``/entry?name=NAME`` one entry's
time series and loop.

Only requests whose ``Host`` header names this server (``127.0.0.1:PORT`` or
``localhost:PORT``) are answered: any other (a page of another site whose name was rebound to
127.0.0.1, "DNS rebinding") gets 421 with a short text and no data, and is logged. Only the
listed paths are served (no file system path is ever formed from a request), only GET and
HEAD (405 otherwise), request targets of at most :data:`MAX_TARGET` characters (414).

:class:`LiveServer` serves one run file; the file may not exist yet (``labrig run --live``
starts the server before the run and names the file once it exists: :meth:`LiveServer.follow`).
:meth:`LiveServer.close` tells the pages that the view is closing and keeps serving until a page
has fetched the run's final state and that word (at most :data:`LINGER_S`), so a page open on
the run shows how it ended and stops asking. A thread of the view that fails, or ends before
:meth:`LiveServer.stop`, leaves the view unable to serve: :attr:`LiveServer.failure` says why
and ``on_failure`` is told once (``python -m labrig.live`` then ends and tells ``labrig run``,
which says so and goes on with the run: :mod:`labrig.live.launch`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs

from labrig.live.frames import FileKey, read_entry, read_frame
from labrig.live.state import FINAL, LiveState, entry_view, overlay_points

log = logging.getLogger(__name__)

HOST = "127.0.0.1"
#: the vendored plotting library (static/vendor/README.md)
UPLOT_VERSION = "1.6.32"
#: the host names a request's Host header may give (with this server's port)
HOST_NAMES = ("127.0.0.1", "localhost")
#: reads of the run file per second while it is written (the writer flushes every 0.1 s)
READ_HZ = 12.0
#: reads per second once the run has ended (a file finished, or `labrig watch` on one)
READ_HZ_ENDED = 1.0
#: how often the page asks for the state (ms); it redraws only when something changed
PAGE_POLL_MS = 80
#: after the run ends, serve at most this long (s) for a page to fetch the final state
LINGER_S = 3.0
#: a page that has not asked for this long (s) has gone: closing does not wait for it (an open
#: page asks every PAGE_POLL_MS, once a second after the run has ended)
PAGE_GONE_S = 1.5
#: the longest request target (path and query) answered (characters; longer: 414)
MAX_TARGET = 1024
#: a connection that sends no complete request within this time (s) is closed, however it
#: trickles its bytes (the same bound applies to each wait for data)
REQUEST_TIMEOUT_S = 10.0
#: ended entries read at once for ``/entry`` (each in a child process); more asks at once are
#: answered 503 with ``Retry-After`` (a page asks for one entry at a time)
ENTRY_READS_AT_ONCE = 2
#: refused requests logged one by one (after that only counted, shown in the page's footer)
REFUSALS_LOGGED = 20
#: ended entries whose page view (``/entry``) is kept; others are read again when asked for
ENTRY_CACHE = 16
#: a kept entry view's key: the file, the entry's name, samples and status when read
EntryKey = tuple[FileKey | None, str, int, str]
#: after a failed read of an ended entry, wait this long (s) before trying again
ENTRY_RETRY_S = 1.0

#: the page's files, served from the package (no other path is served)
STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/live.js": ("live.js", "text/javascript; charset=utf-8"),
    "/live.css": ("live.css", "text/css; charset=utf-8"),
    "/vendor/uPlot.iife.min.js": ("vendor/uPlot.iife.min.js", "text/javascript; charset=utf-8"),
    "/vendor/uPlot.min.css": ("vendor/uPlot.min.css", "text/css; charset=utf-8"),
    "/vendor/LICENSE": ("vendor/LICENSE", "text/plain; charset=utf-8"),
}
#: headers of every answer: nothing cached, no other site may frame or embed the page
SECURITY_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "Content-Security-Policy": (
        "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'; "
        "base-uri 'none'; form-action 'none'"
    ),
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Resource-Policy": "same-origin",
}


def static_file(name: str) -> bytes:
    return resources.files("labrig.live").joinpath("static", *name.split("/")).read_bytes()


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    #: connections waiting to be accepted (the standard library's 5 made a burst of a few
    #: hundred requests wait on TCP's retries, tens of seconds)
    request_queue_size = 128

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A connection that failed (a client gone, one cut off at the deadline) is not a
        traceback on the terminal."""
        log.debug("live view: a connection from %s failed", client_address, exc_info=True)


class EntryReadsBusyError(Exception):
    """As many ``/entry`` reads as :data:`ENTRY_READS_AT_ONCE` are going on: ask again."""


class LiveServer:
    """Serves the live view of one run file (module docstring)."""

    def __init__(
        self,
        path: Path | None,
        params: Any = None,
        port: int = 0,
        on_failure: Callable[[str], None] | None = None,
    ):
        self.state = LiveState(params, source=str(path or ""))
        self.params = params
        self.path = path
        self.lock = threading.Lock()
        self.ended = threading.Event()
        self.stopping = threading.Event()
        self.final_served = threading.Event()
        #: the view is closing (its run command is done with it); a page told so stops asking
        self.closing = threading.Event()
        self.closing_served = threading.Event()
        self._final_parts: set[str] = set()
        self.clients = 0
        self.last_ask = 0.0  # time.monotonic() of the last /frame request
        self._entries: OrderedDict[EntryKey, bytes] = OrderedDict()
        self.entry_reads = threading.BoundedSemaphore(ENTRY_READS_AT_ONCE)
        self.httpd = _Server((HOST, port), _handler(self))
        self._threads: list[threading.Thread] = []
        #: why the view stopped serving by itself ("" while it serves: :meth:`_guarded`)
        self.failure = ""
        self._on_failure = on_failure

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/"

    def host_allowed(self, host: str | None) -> bool:
        """Whether a request's ``Host`` header names this server (``127.0.0.1:PORT`` or
        ``localhost:PORT``, the name in any case); a missing header is not."""
        if host is None:
            return False
        return host.strip().lower() in {f"{h}:{self.port}" for h in HOST_NAMES}

    def start(self) -> None:
        threads = {
            "web server": self.httpd.serve_forever,
            "file reader": self._read_loop,
            "entry reader": self._entry_loop,
        }
        for what, target in threads.items():
            t = threading.Thread(target=self._guarded, args=(what, target), daemon=True)
            t.start()
            self._threads.append(t)

    def _guarded(self, what: str, target: Callable[[], None]) -> None:
        """Run ``target``, the view's ``what`` thread; if it fails, or ends before
        :meth:`stop`, the view cannot serve: record why in :attr:`failure` (the first cause
        only) and tell ``on_failure``, instead of a traceback on the terminal."""
        try:
            target()
        except BaseException as e:
            why = f"its {what} failed: {_described(e)}"
        else:
            if self.stopping.is_set():
                return
            why = f"its {what} stopped"
        with self.lock:
            first, self.failure = not self.failure, self.failure or why
        if first and self._on_failure is not None:
            self._on_failure(why)

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
        """After :meth:`end` and with :attr:`closing` set: wait until a page has fetched the
        final state and been told that the view is closing (if any page ever connected), at
        most :data:`LINGER_S`; not for a page that has not asked for :data:`PAGE_GONE_S`)."""
        deadline = time.monotonic() + LINGER_S
        while self.clients and time.monotonic() < deadline:
            if self.final_served.is_set() and self.closing_served.is_set():
                return
            if time.monotonic() - self.last_ask > PAGE_GONE_S:
                return  # no page is asking any more
            time.sleep(0.05)

    def close(self) -> None:
        """Close the view: tell the pages (``closing`` in ``/frame``: they keep their last
        picture and stop asking), :meth:`linger` for them, then :meth:`stop`."""
        self.closing.set()
        self.linger()
        self.stop()

    def stop(self) -> None:
        self.stopping.set()
        self.httpd.shutdown()
        self.httpd.server_close()

    # -- reading ----------------------------------------------------------------------------
    def _read_loop(self) -> None:
        while not self.stopping.is_set():
            t0 = time.monotonic()
            self.read_once()
            with self.lock:
                f = self.state.frame
                hz = READ_HZ_ENDED if f is not None and f.status in FINAL else READ_HZ
            self.stopping.wait(max(0.0, 1.0 / hz - (time.monotonic() - t0)))

    def read_once(self) -> None:
        """One read of the file into the state (a failed read is counted and skipped)."""
        with self.lock:
            path = self.path
        if path is None:
            return
        with self.lock:
            entry, start = self.state.next_request()
            known = dict(self.state.step_facts)
            ended = dict(self.state.ended)
            file_id = self.state.file_id
        t0 = time.perf_counter()
        try:
            frame = read_frame(path, entry, start, known, ended, file_id)
        except Exception as e:  # a torn read, a damaged file, no file: skip this frame
            if isinstance(e, FileNotFoundError):
                why = f"{path}: no such file now (deleted or renamed); showing the last state read"
            else:
                why = (str(e).splitlines() or [type(e).__name__])[0][:200]
            with self.lock:
                self.state.skipped += 1
                self.state.last_error = why
            return
        with self.lock:
            self.state.path = str(path)
            self.state.take(frame, (time.perf_counter() - t0) * 1e3)
            self.state.last_error = ""

    def _entry_loop(self) -> None:
        while not self.stopping.is_set():
            done = self.read_ended_entry()
            self.stopping.wait(0.05 if done else ENTRY_RETRY_S if done is False else 0.1)

    def read_ended_entry(self) -> bool | None:
        """Read one ended entry whose loop the overlay lacks (:func:`entry_view`): True when
        one was read, False when the read failed (it is tried again later), None when there
        was none to read."""
        with self.lock:
            todo = self.state.ended_entries()
            path, points = self.path, overlay_points(self.state.planned_count())
        if not todo or path is None:
            return None
        name, key = todo[0]
        try:
            data = read_entry(path, name)
            overlay, detail = entry_view(data, self.params, points)
        except Exception as e:  # a damaged entry: say so in the footer, try again later
            with self.lock:
                self.state.skipped += 1
                self.state.last_error = f"{name}: " + (str(e).splitlines() or ["?"])[0][:180]
            return False
        body = _json(detail)
        with self.lock:
            # an entry of another file (the path replaced meanwhile) is not this run's
            if self.state.take_entry((detail["samples"], detail["status"]), overlay, data.file_id):
                self._cache((data.file_id, name, *key), body)
        return True

    def _cache(self, key: EntryKey, body: bytes) -> None:
        self._entries[key] = body
        self._entries.move_to_end(key)
        while len(self._entries) > ENTRY_CACHE:
            self._entries.popitem(last=False)

    # -- the documents ----------------------------------------------------------------------
    def document(self) -> bytes:
        with self.lock:
            doc = self.state.document()
        doc["ended"] = self.ended.is_set()
        doc["poll_ms"] = PAGE_POLL_MS
        doc["closing"] = closing = self.closing.is_set()
        self._served("frame", bool(doc.get("final")))
        if closing:
            self.closing_served.set()
        return _json(doc)

    def loops_document(self) -> bytes:
        with self.lock:
            doc = self.state.loops_document()
            final = self.state.is_final()
        if not doc["entries"]:
            self._served("entry", final)  # nothing to choose: the loops are all there is
        self._served("loops", final)
        return _json(doc)

    def entry_document(self, name: str) -> bytes | None:
        """An entry's page view (:func:`~labrig.live.state.entry_view`), read now unless kept;
        None when the run file has no such entry."""
        with self.lock:
            if not self.state.known_entry(name) or self.state.frame is None:
                return None
            info = next(e for e in self.state.frame.entries if e.name == name)
            key = (self.state.file_id, name, info.samples, info.status)
            body = self._entries.get(key)
            path, final = self.path, self.state.is_final()
        if body is None:
            if path is None:
                return None
            if not self.entry_reads.acquire(blocking=False):
                raise EntryReadsBusyError(f"{ENTRY_READS_AT_ONCE} entries are being read now")
            try:
                data = read_entry(path, name)
                _, detail = entry_view(data, self.params)
            finally:
                self.entry_reads.release()
            body = _json(detail)
            if data.file_id == key[0]:  # kept only under the file it was read from
                with self.lock:
                    self._cache(key, body)
        self._served("entry", final)
        return body

    def _served(self, part: str, final: bool) -> None:
        """The page fetched ``part`` of the final state (the run ended): once it has the
        frame, the loops and an entry, :meth:`linger` may stop waiting."""
        if not (final and self.ended.is_set()):
            return
        with self.lock:
            self._final_parts.add(part)
            if {"frame", "loops", "entry"} <= self._final_parts:
                self.final_served.set()

    def refused(self, what: str) -> None:
        """Count (and log the first :data:`REFUSALS_LOGGED`) requests refused."""
        with self.lock:
            self.state.refused += 1
            n = self.state.refused
        if n <= REFUSALS_LOGGED:
            log.warning("live view: refused %s", what)
        if n == REFUSALS_LOGGED:
            log.warning("live view: further refused requests are counted only (page footer)")


def _described(e: BaseException) -> str:
    """An exception in one line: its type and its message's first line (at most 200
    characters)."""
    text = (str(e).strip().splitlines() or [""])[0][:200]
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _json(doc: dict[str, Any]) -> bytes:
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def _handler(server: LiveServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        timeout = REQUEST_TIMEOUT_S
        server_version = "labrig-live"
        sys_version = ""
        # the standard library's own refusals (a malformed request line, headers too long or
        # too many, an unknown method) as one line of text
        error_content_type = "text/plain; charset=utf-8"
        error_message_format = "%(code)d %(message)s: %(explain)s\n"

        def setup(self) -> None:
            super().setup()
            # the whole request, not only each wait for data, within REQUEST_TIMEOUT_S: a
            # client trickling a byte at a time is cut off (:meth:`parse_request` ends it)
            self._cut_off = False
            self._deadline = threading.Timer(REQUEST_TIMEOUT_S, self._cut)
            self._deadline.daemon = True
            self._deadline.start()

        def _cut(self) -> None:
            self._cut_off = True
            with contextlib.suppress(OSError):
                self.connection.shutdown(socket.SHUT_RDWR)

        def parse_request(self) -> bool:
            ok = super().parse_request()  # (reads the headers: still under the deadline)
            self._deadline.cancel()
            if self._cut_off:  # what arrived before the cut is not a request to answer
                self.close_connection = True
                return False
            return ok

        def finish(self) -> None:
            self._deadline.cancel()
            with contextlib.suppress(OSError):
                super().finish()

        def do_GET(self) -> None:
            self._answer(with_body=True)

        def do_HEAD(self) -> None:
            self._answer(with_body=False)

        def _other_method(self) -> None:
            if self._host_checked():
                self._text(
                    HTTPStatus.METHOD_NOT_ALLOWED,
                    f"the live view answers GET and HEAD only, not {self.command}",
                    {"Allow": "GET, HEAD"},
                )

        do_POST = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = do_TRACE = do_CONNECT = _other_method

        def _host_checked(self) -> bool:
            hosts = self.headers.get_all("Host") or []
            host = hosts[0] if len(hosts) == 1 else None
            if server.host_allowed(host):
                return True
            if len(hosts) > 1:
                shown = f"{len(hosts)} Host headers"
            elif host is None:
                shown = "no Host header"
            else:
                shown = f"Host {host[:100]!r}"
            server.refused(f"{self.command} {self.path[:100]!r} with {shown}")
            self._text(
                HTTPStatus.MISDIRECTED_REQUEST,
                f"this live view answers only Host 127.0.0.1:{server.port} or "
                f"localhost:{server.port} ({shown})",
            )
            return False

        def _answer(self, with_body: bool) -> None:
            if not self._host_checked():
                return
            if len(self.path) > MAX_TARGET:
                server.refused(f"a request target of {len(self.path)} characters")
                self._text(HTTPStatus.REQUEST_URI_TOO_LONG, f"at most {MAX_TARGET} characters")
                return
            # http.server reduces a target's leading "//" to "/": answer the target as sent,
            # so that only the listed paths, spelled as listed, are served
            words = self.requestline.split()
            route, _, query = (words[1] if len(words) == 3 else self.path).partition("?")
            if route == "/frame":
                server.clients += 1
                server.last_ask = time.monotonic()
                self._send(server.document(), "application/json", with_body)
            elif route == "/loops":
                self._send(server.loops_document(), "application/json", with_body)
            elif route == "/entry":
                self._entry(query, with_body)
            elif route in STATIC:
                name, kind = STATIC[route]
                self._send(static_file(name), kind, with_body)
            else:
                self._text(HTTPStatus.NOT_FOUND, "no such page", with_body=with_body)

        def _entry(self, query: str, with_body: bool) -> None:
            try:
                names = parse_qs(query, strict_parsing=True, max_num_fields=2).get("name", [])
            except ValueError:
                names = []
            if len(names) != 1:
                self._text(HTTPStatus.BAD_REQUEST, "give one entry: /entry?name=NAME")
                return
            try:
                body = server.entry_document(names[0])
            except EntryReadsBusyError as e:
                self._text(
                    HTTPStatus.SERVICE_UNAVAILABLE,
                    f"busy: {e}; ask again in a second",
                    {"Retry-After": "1"},
                )
                return
            except Exception as e:  # a damaged entry (the page says so)
                why = (str(e).splitlines() or [type(e).__name__])[0][:200]
                self._text(HTTPStatus.SERVICE_UNAVAILABLE, f"cannot read it now: {why}")
                return
            if body is None:
                self._text(HTTPStatus.NOT_FOUND, "the run file has no such entry")
                return
            self._send(body, "application/json", with_body)

        def _text(
            self,
            code: HTTPStatus,
            text: str,
            headers: dict[str, str] | None = None,
            with_body: bool = True,
        ) -> None:
            body = f"{int(code)} {code.phrase}: {text}\n".encode()
            self._send(body, "text/plain; charset=utf-8", with_body, code, headers)

        def _send(
            self,
            body: bytes,
            kind: str,
            with_body: bool = True,
            code: HTTPStatus = HTTPStatus.OK,
            headers: dict[str, str] | None = None,
        ) -> None:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            for k, v in {**SECURITY_HEADERS, **(headers or {})}.items():
                self.send_header(k, v)
            self.end_headers()
            if with_body:
                with contextlib.suppress(OSError):  # the page went away
                    self.wfile.write(body)

        def log_message(self, format: str, *args: Any) -> None:
            """Quiet: no line per request (refusals are logged by :meth:`LiveServer.refused`)."""

    return Handler
