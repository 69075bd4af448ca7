"""Reading a run file while it is written: ``labrig watch FILE`` from a second terminal (its
page's data, ``/frame``), ``labrig info`` saying the file is being written (and incomplete once
its writer is killed), and damaged reads skipped. The server's refusals (Host header, paths,
methods, sizes), the end-of-run documents (every entry's loop, the status) and the lifetime of
the view beside ``labrig run --live`` and ``labrig watch``. The browser test is
test_live_browser.py."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np
import pytest
from rich.console import Console

from labrig.cli.run_execute import serve_finished_run
from labrig.live import load_params
from labrig.live import server as live_server
from labrig.live.frames import EntryInfo, Frame, read_entry, read_frame
from labrig.live.launch import LiveProcess
from labrig.live.server import (
    ENTRY_READS_AT_ONCE,
    LINGER_S,
    MAX_TARGET,
    PAGE_GONE_S,
    REFUSALS_LOGGED,
    UPLOT_VERSION,
    LiveServer,
)
from labrig.live.state import (
    MAX_POINTS,
    MIN_OVERLAY_POINTS,
    OVERLAY_POINTS,
    POINTS_PER_PERIOD,
    LiveState,
    entry_view,
    loop_slice,
    overlay_points,
)
from labrig.model import DynamicHysteresisModel
from labrig.runner.execute import RunOutcome
from labrig.store import RunWriter, read_run

from helpers import fork_saying, invoke, slack

ROOT = Path(__file__).resolve().parents[2]
#: the vendored files as packed in the npm registry's uplot 1.6.32 (sha256, taken from the
#: tarball when it was vendored; static/vendor/README.md lists the same)
VENDORED = {
    "uPlot.iife.min.js": "19c8d4c6ad88929a79f4ae49d6f7161566dfd0ba3d15cc495e974f787eb78f1f",
    "uPlot.min.css": "df630c6a8d6f8eeaff264b50f73ce5b114f646ffd9a0bb74f049b0a00135fa04",
}

pytestmark = pytest.mark.timeout(120)


def _write(path: Path, blocks: int, said: int, hurry_fd: int) -> None:
    """Appends a 100-sample block every 0.1 s (as labrig run does at 1 kHz), saying so on the
    pipe ``said``, until a line on ``hurry_fd`` tells it to write the rest at once."""
    hurry = False
    with RunWriter(path, "name: w\n", "", {}, seed=1, protocol_name="watch test",
                   planned_entries=["first", "second"]) as w:  # fmt: skip
        for name in ("first", "second"):
            e = w.begin_entry(name, {"kind": "sine", "n_samples": blocks * 100}, 1000.0,
                              ["command_voltage", "strain"])  # fmt: skip
            for b in range(blocks):
                k = np.arange(b * 100, (b + 1) * 100)
                v = 50 * (1 - np.cos(2 * np.pi * k / 500))
                e.append({"command_voltage": v, "strain": 9 * v})
                with contextlib.suppress(OSError):  # (no one listening any more)
                    os.write(said, f"block {name} {b}\n".encode())
                hurry = hurry or bool(select.select([hurry_fd], [], [], 0.1)[0])
            e.finish("complete")


class Writer:
    """A run file being written by another process: a fork of this one (labrig loaded), with
    a process's ``pid``, ``poll``, ``wait`` and ``kill``; ``hurry`` tells it to write the rest
    of its blocks at once."""

    def __init__(self, path: Path, blocks: int):
        hurry_r, self._hurry = os.pipe()

        def write(said: int) -> None:
            os.close(self._hurry)
            _write(path, blocks, said, hurry_r)

        pid, said_r = fork_saying(write)
        os.close(hurry_r)
        self.pid, self.returncode = pid, None
        try:
            assert select.select([said_r], [], [], 30)[0], "the writer never wrote"
            assert os.read(said_r, 64).startswith(b"block first 0")
        finally:
            os.close(said_r)  # (its later lines are not read: it writes on regardless)

    def poll(self) -> int | None:
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float = 30) -> int:
        end = time.monotonic() + timeout
        while self.poll() is None:
            assert time.monotonic() < end, "the writer did not end"
            time.sleep(0.02)
        return self.returncode

    def hurry(self) -> None:
        with contextlib.suppress(OSError):  # (a writer that has ended)
            os.write(self._hurry, b"hurry\n")
        os.close(self._hurry)

    def kill(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.pid, signal.SIGKILL)


def start_writer(path: Path, blocks: int) -> Writer:
    return Writer(path, blocks)


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def test_watch_follows_a_run_being_written(tmp_path: Path):
    run = tmp_path / "run.h5"
    # long enough (8 s) that a loaded machine's slow start of the view still sees it written
    writer = start_writer(run, blocks=80)
    watch = subprocess.Popen(
        [sys.executable, "-m", "labrig.cli", "watch", str(run)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert watch.stdout is not None
        ready, _, _ = select.select([watch.stdout], [], [], 30)
        line = watch.stdout.readline() if ready else ""
        assert "http://127.0.0.1:" in line, (line, watch.stderr.read() if watch.poll() else "")
        url = line.split(": ", 1)[1].split()[0]
        # poll until the view has shown the entry growing through a few states (bounded:
        # the rate a loaded machine reaches is not this test's business, the browser test
        # measures it)
        frames: list[dict] = []
        t_end = time.monotonic() + 20.0
        while time.monotonic() < t_end:
            frames.append(get(url + "frame"))
            running = [f for f in frames if f.get("status") == "running" and "entry" in f]
            if len({f["seq"] for f in running}) >= 4 or writer.poll() is not None:
                break
            time.sleep(0.1)
        # seen written (or the writer done): the rest of its blocks at once, not at 10 a second
        writer.hurry()
        running = [f for f in frames if f.get("status") == "running" and "entry" in f]
        assert len({f["seq"] for f in running}) >= 3, frames[-3:]
        # the entry seen growing longest (on a loaded machine the view may come up late in
        # the first entry, or in the second)
        name = max(
            ("first", "second"),
            key=lambda n: len({f["entry"]["samples"] for f in running if f["entry"]["name"] == n}),
        )
        samples = [f["entry"]["samples"] for f in running if f["entry"]["name"] == name]
        assert samples == sorted(samples) and samples[-1] > samples[0]  # it grows as written
        assert running[-1]["writing"] == "being written"
        assert running[-1]["progress"]["planned"] == 2
        loop = running[-1]["entry"]["loop"]
        assert len(loop["voltage"]) == len(loop["strain"]) > 50
        # the strain is what the writer wrote (9 x the voltage), sample for sample
        assert all(
            abs(s - 9 * v) < 1e-3 * (1 + abs(s))
            for v, s in zip(loop["voltage"], loop["strain"], strict=True)
        )
        assert writer.wait(timeout=30) == 0
        time.sleep(0.5)
        final = get(url + "frame")
        assert final["status"] == "complete" and final["progress"]["complete"] == 2
        # the page and its scripts are served from the package
        with urllib.request.urlopen(url, timeout=5) as r:
            assert b"live.js" in r.read()
        watch.send_signal(signal.SIGINT)  # closing the view is how watch ends: exit 0
        assert watch.wait(timeout=10) == 0
    finally:
        for p in (writer, watch):
            if p.poll() is None:
                p.kill()
                p.wait()


def test_info_says_being_written_then_incomplete_after_a_kill(tmp_path: Path):
    run = tmp_path / "run.h5"
    writer = start_writer(run, blocks=100)
    try:
        # in-process: the writer is the other process here (the reading is a child anyway)
        r = invoke("info", run)
        assert r.exit_code == 0, r.output
        assert "being written now by process" in r.stdout
        assert str(writer.pid) in r.stdout
    finally:
        writer.kill()
        writer.wait()
    r = invoke("info", run)
    assert r.exit_code == 0, r.output
    assert "incomplete: the writer stopped without finishing the run" in r.stdout
    assert "being written" not in r.stdout


def test_a_closed_unfinished_file_is_not_being_written(tmp_path: Path):
    p = tmp_path / "r.h5"
    w = RunWriter(p, "", "", {}, seed=1)
    w.begin_entry("a", {}, 100.0, ["strain"]).append({"strain": [1.0, 2.0]})
    w.close()  # closed unfinished (a notebook that stopped): no writer any more
    run = read_run(p)
    assert run.incomplete and not run.being_written


def test_a_read_that_does_not_verify_is_skipped(tmp_path: Path):
    p = tmp_path / "r.h5"
    with RunWriter(p, "", "", {}, seed=1) as w:
        w.begin_entry("a", {}, 100.0, ["strain"]).append({"strain": [1.0, 2.0, 3.0]})
    frame = read_frame(p, None, 0, {})
    assert frame.status == "complete" and list(frame.samples["strain"]) == [1.0, 2.0, 3.0]
    data = bytearray(p.read_bytes())
    data[: len(data) // 2] = bytes(len(data) // 2)  # the first half zeroed
    bad = tmp_path / "bad.h5"
    bad.write_bytes(bytes(data))
    server = LiveServer(bad)
    server.read_once()
    assert server.state.skipped == 1 and server.state.frame is None
    assert server.state.document()["status"] == "waiting"
    server.httpd.server_close()


# -- the server's refusals ----------------------------------------------------------------------


def raw(port: int, request: bytes, timeout: float = 5.0) -> tuple[int, dict[str, str], bytes]:
    """Send ``request`` as it is (no header added) and parse the answer."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(request)
        data = b""
        while chunk := s.recv(1 << 16):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = {k.lower(): v.strip() for k, _, v in (x.partition(":") for x in lines[1:])}
    return int(lines[0].split()[1]), headers, body


def request(port: int, target: str, host: str | None, method: str = "GET", extra: str = ""):
    host_line = f"Host: {host}\r\n" if host is not None else ""
    return raw(
        port, f"{method} {target} HTTP/1.1\r\n{host_line}{extra}Connection: close\r\n\r\n".encode()
    )


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A finished run file of three entries whose samples are known (written here once; the
    tests only read it)."""
    path = write_run(tmp_path_factory.mktemp("finished") / "run.h5")
    before = path.read_bytes()
    yield path
    assert path.read_bytes() == before, "a test changed the shared run file"


#: the entries of write_run: name, drive frequency (Hz), samples (1 kHz), peak voltage (V)
ENTRIES = [("sine_100V_2Hz", 2.0, 2000, 100.0), ("sine_50V_5Hz", 5.0, 1000, 50.0)]
#: the last entry: 100 V at 1 Hz decaying to nothing in 2 s, then 3 s at 0 V
VANISHING = ("vanishing_100V_1Hz", 1.0, 5000, 100.0)


def vanishing_drive(k: np.ndarray) -> np.ndarray:
    t = k / 1000.0
    return np.where(t < 2.0, 100 * np.exp(-t) * 0.5 * (1 - np.cos(2 * np.pi * t)), 0.0)


def write_run(path: Path, status: str = "complete", reason: str | None = None) -> Path:
    names = [e[0] for e in (*ENTRIES, VANISHING)]
    with RunWriter(
        path, "name: t\n", "", {}, seed=1, protocol_name="end of run", planned_entries=names
    ) as w:
        for name, f, n, amp in (*ENTRIES, VANISHING):
            k = np.arange(n)
            if name == VANISHING[0]:
                v = vanishing_drive(k)
            else:
                v = amp / 2 * (1 - np.cos(2 * np.pi * f * k / 1000.0))
            step = {"kind": "sine", "frequency_hz": f, "n_samples": n}
            e = w.begin_entry(name, step, 1000.0, ["command_voltage", "strain"])
            for b in range(0, n, 100):
                e.append({"command_voltage": v[b : b + 100], "strain": 9 * v[b : b + 100]})
            e.finish("complete" if status == "complete" or name != VANISHING[0] else "aborted")
        if status != "complete":
            w.finish(status, reason)
    return path


@pytest.fixture
def served(finished_run: Path):
    server = LiveServer(finished_run)
    server.start()
    try:
        yield server
    finally:
        server.stop()


def test_only_this_servers_host_is_answered(served: LiveServer, caplog):
    port = served.port
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LOCALHOST:{port}"):
        code, _, body = request(port, "/frame", host)
        assert code == 200 and b'"seq"' in body, host
    refused = [
        None,  # no Host header at all
        f"evil.example:{port}",  # the right port, a foreign name (DNS rebinding)
        f"127.0.0.2:{port}",  # the right port, another loopback address
        f"127.0.0.1:{port + 1}",  # the right name, the wrong port
        f"localhost:{port}0",
        "127.0.0.1",  # no port
        f"[::1]:{port}",  # not bound
        f"127.0.0.1:{port}.evil.example",
        "",
    ]
    with caplog.at_level("WARNING", logger="labrig.live.server"):
        for host in refused:
            for target, method in (("/frame", "GET"), ("/", "HEAD"), ("/frame", "POST")):
                code, headers, body = request(port, target, host, method)
                assert code == 421, (host, method)
                assert b"seq" not in body and b"<html" not in body.lower()
                if method != "HEAD":
                    assert b"answers only Host 127.0.0.1:" in body and len(body) < 300
                assert headers["content-type"].startswith("text/plain")
    assert served.state.refused == 3 * len(refused)
    assert "refused GET '/frame' with Host 'evil.example:" in caplog.text
    assert "no Host header" in caplog.text
    # logged one by one up to a bound, then counted only
    assert caplog.text.count("live view: refused") == REFUSALS_LOGGED
    assert served.state.document()["refused"] == 3 * len(refused)


def test_two_host_headers_are_refused_even_when_one_names_this_server(served: LiveServer):
    port = served.port
    good, bad = f"127.0.0.1:{port}", f"evil.example:{port}"
    for first, second in ((good, bad), (bad, good), (good, good)):
        code, _, body = request(port, "/frame", first, extra=f"Host: {second}\r\n")
        assert code == 421 and b"2 Host headers" in body and b"seq" not in body


@pytest.mark.parametrize("whole", ["", "the request line"])
def test_a_request_trickled_a_byte_at_a_time_is_cut_off(
    finished_run: Path, monkeypatch, whole: str
):
    """Each wait for data is bounded (REQUEST_TIMEOUT_S) and so is the whole request, headers
    included: a client sending a byte every 0.2 s (after its request line, sent whole, or from
    the start) with a 0.6 s bound is disconnected within about 0.6 s, without an answer; a
    request sent whole within the bound is answered."""
    monkeypatch.setattr(live_server, "REQUEST_TIMEOUT_S", 0.6)
    server = LiveServer(finished_run)
    server.start()
    try:
        host = f"127.0.0.1:{server.port}"
        assert request(server.port, "/frame", host)[0] == 200
        line = "GET /frame HTTP/1.1\r\n"
        text = f"Host: {host}\r\n" + "X-Slow: " + "x" * 40
        t0 = time.monotonic()
        got = b"?"
        with socket.create_connection(("127.0.0.1", server.port), timeout=5) as c:
            if whole:
                c.sendall(line.encode())
            else:
                text = line + text
            try:
                for ch in text:
                    c.sendall(ch.encode())
                    time.sleep(0.2)
                    ready, _, _ = select.select([c], [], [], 0)
                    if ready:
                        got = c.recv(100)
                        break
            except OSError:  # the server closed it while a byte was being sent
                got = b""
        assert got == b"" and time.monotonic() - t0 < 0.6 + slack(1.0)
    finally:
        server.stop()


def test_entry_reads_beyond_the_bound_are_told_to_ask_again(finished_run: Path):
    """At most ENTRY_READS_AT_ONCE entries are read at once (each in a child process): one more
    ask is answered 503 with Retry-After; an entry already read is served all the same."""
    server = LiveServer(finished_run)
    server.start()
    try:
        host = f"127.0.0.1:{server.port}"
        server.read_once()
        first, second = ENTRIES[0][0], ENTRIES[1][0]
        assert request(server.port, f"/entry?name={first}", host)[0] == 200
        for _ in range(ENTRY_READS_AT_ONCE):
            server.entry_reads.acquire()
        code, headers, body = request(server.port, f"/entry?name={second}", host)
        assert code == 503 and headers["retry-after"] == "1" and b"ask again" in body
        assert request(server.port, f"/entry?name={first}", host)[0] == 200  # kept
        server.entry_reads.release()  # one read free: the entry is read
        assert request(server.port, f"/entry?name={second}", host)[0] == 200
    finally:
        server.stop()


def test_unlisted_paths_methods_and_sizes_are_refused(served: LiveServer):
    port, host = served.port, f"127.0.0.1:{served.port}"
    for target in (
        "/nothing",
        "/../etc/passwd",
        "/%2e%2e/%2e%2e/etc/passwd",
        "/vendor/../live.js",
        "/static/live.js",
        "/live.js/",
        "/vendor/",
        "/vendor/README.md",  # in the package, not a listed path
        "http://127.0.0.1/frame",  # absolute form: not a path
        "//live.js",  # http.server reduces "//" to "/": the target as sent is not listed
        "///frame",
        "//vendor/uPlot.iife.min.js",
        "//",
    ):
        code, _, body = request(port, target, host)
        assert code == 404, target
        assert body.startswith(b"404 Not Found") and len(body) < 100
    # the listed files, with their types and the headers that keep other sites out
    code, headers, body = request(port, "/vendor/uPlot.iife.min.js", host)
    assert code == 200 and headers["content-type"].startswith("text/javascript")
    assert hashlib.sha256(body).hexdigest() == VENDORED["uPlot.iife.min.js"]
    assert headers["x-content-type-options"] == "nosniff"
    assert "default-src 'self'" in headers["content-security-policy"]
    assert "frame-ancestors 'none'" in headers["content-security-policy"]
    code, _, body = request(port, "/vendor/LICENSE", host)
    assert code == 200 and b"MIT License" in body
    # HEAD: the headers of GET, no body
    code, headers, body = request(port, "/", host, "HEAD")
    assert code == 200 and body == b"" and int(headers["content-length"]) > 100
    # other methods: 405 naming the allowed ones; an unknown method: 501
    for method in ("POST", "PUT", "DELETE", "PATCH", "OPTIONS", "TRACE"):
        code, headers, _ = request(port, "/frame", host, method)
        assert code == 405 and headers["allow"] == "GET, HEAD", method
    assert request(port, "/frame", host, "BREW")[0] == 501
    # the request target: at most MAX_TARGET characters (just inside: not refused for length)
    inside = "/" + "a" * (MAX_TARGET - 1)
    assert request(port, inside, host)[0] == 404
    assert request(port, inside + "a", host)[0] == 414
    assert request(port, "/frame?" + "x" * MAX_TARGET, host)[0] == 414
    # the standard library's bounds: a request line over 64 KiB, a header line over 64 KiB,
    # more than 100 headers
    assert request(port, "/" + "a" * 70_000, host)[0] == 414
    assert request(port, "/", host, extra="X-Big: " + "b" * 70_000 + "\r\n")[0] == 431
    many = "".join(f"X-{i}: {i}\r\n" for i in range(101))
    assert request(port, "/", host, extra=many)[0] == 431
    assert request(port, "/", host, extra="".join(f"X-{i}: {i}\r\n" for i in range(90)))[0] == 200
    # garbage instead of a request line (a TLS hello): the standard library's one line of
    # text, with no status line (as HTTP/0.9 answers), and nothing served
    for garbage in (b"\x16\x03\x01\x00\xa5\x01\x00\x00\r\n\r\n", b"GARBAGE\r\n\r\n"):
        with socket.create_connection(("127.0.0.1", port), timeout=5) as c:
            c.sendall(garbage)
            answer = c.recv(1000)
        assert answer.startswith(b"400 Bad request syntax") and len(answer) < 200


def test_a_silent_connection_neither_blocks_the_page_nor_the_stop(finished_run: Path):
    server = LiveServer(finished_run)
    server.start()
    idle = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    idle.sendall(b"GET /frame HTTP/1.1\r\n")  # and nothing more
    try:
        code, _, _ = request(server.port, "/frame", f"127.0.0.1:{server.port}")
        assert code == 200
    finally:
        t0 = time.monotonic()
        server.stop()
        assert time.monotonic() - t0 < slack(3.0)
        idle.close()


def test_the_vendored_library_is_the_recorded_release():
    """static/vendor/ holds uPlot as packed by the npm registry (README.md there: the hashes
    of the package's files, taken from the tarball when it was vendored)."""
    vendor = Path(__file__).resolve().parents[2] / "labrig" / "live" / "static" / "vendor"
    readme = (vendor / "README.md").read_text()
    assert f"uPlot {UPLOT_VERSION}" in readme
    for name, digest in VENDORED.items():
        assert hashlib.sha256((vendor / name).read_bytes()).hexdigest() == digest
        assert digest in readme
    assert f"(v{UPLOT_VERSION})" in (vendor / "uPlot.iife.min.js").read_text()[:100]
    assert "MIT License" in (vendor / "LICENSE").read_text()


# -- the end-of-run documents --------------------------------------------------------------------


def read_all(server: LiveServer) -> None:
    """The reads the server's threads make, made here: the frame, then every ended entry."""
    server.read_once()
    for _ in range(10):
        if server.read_ended_entry() is None:
            break


def test_the_end_of_run_documents_hold_every_entrys_loop(finished_run: Path):
    server = LiveServer(finished_run)
    try:
        read_all(server)
        doc = json.loads(server.document())
        assert doc["status"] == "complete" and doc["final"] is True
        assert [e["name"] for e in doc["progress"]["entries"]] == [
            e[0] for e in (*ENTRIES, VANISHING)
        ]
        loops = json.loads(server.loops_document())["entries"]
        assert [e["name"] for e in loops] == [e[0] for e in (*ENTRIES, VANISHING)]
        peak = {
            **{e[0]: e[3] for e in ENTRIES},
            VANISHING[0]: vanishing_drive(np.arange(5000)).max(),
        }
        for e, (name, f, n, _) in zip(loops, (*ENTRIES, VANISHING), strict=True):
            v, s = np.array(e["loop"]["voltage"]), np.array(e["loop"]["strain"])
            assert e["status"] == "complete" and e["samples"] == n
            # the whole loop: from 0 V to the entry's peak (not the last block's values)
            assert v.min() < 0.01 * peak[name] and v.max() > 0.98 * peak[name], name
            np.testing.assert_allclose(s, 9 * v, rtol=1e-4, atol=1e-6)
            # at least POINTS_PER_PERIOD points a period: every k-th sample, k = 1000/f/40
            t = np.array(e["loop"]["t"])
            assert np.allclose(np.diff(t), max(1, int(1000 / f / POINTS_PER_PERIOD)) / 1000)
        # the last entry's view: the whole record, not its decayed tail
        detail = json.loads(server.entry_document(VANISHING[0]))
        assert detail["series"]["t"][0] == 0.0 and detail["samples"] == VANISHING[2]
        assert max(detail["loop"]["voltage"]) > 0.98 * peak[VANISHING[0]]
        assert len(detail["series"]["t"]) == 5000  # under ENTRY_SERIES_POINTS: every sample
        assert server.entry_document("no such entry") is None
    finally:
        server.httpd.server_close()


def test_an_aborted_run_shows_its_reason_and_the_entries_it_has(tmp_path: Path):
    path = write_run(tmp_path / "a.h5", "aborted", "interrupted (Ctrl-C, SIGINT)")
    server = LiveServer(path)
    try:
        read_all(server)
        doc = json.loads(server.document())
        assert doc["status"] == "aborted" and doc["reason"] == "interrupted (Ctrl-C, SIGINT)"
        assert doc["final"] is True
        loops = json.loads(server.loops_document())["entries"]
        assert [e["status"] for e in loops] == ["complete", "complete", "aborted"]
    finally:
        server.httpd.server_close()


def test_loops_are_read_once_an_entry_or_the_run_has_ended():
    state = LiveState()

    def frame(run: str, *entries: tuple[str, str]) -> Frame:
        infos = [EntryInfo(n, i, st, 100, 100, n) for i, (n, st) in enumerate(entries)]
        return Frame(run, "", "", ["a", "b"], infos, infos[-1].name, 100)

    state.take(frame("running", ("a", "running")), 1.0)
    assert state.ended_entries() == [] and not state.is_final()
    state.take(frame("running", ("a", "complete"), ("b", "running")), 1.0)
    assert state.ended_entries() == [("a", (100, "complete"))] and not state.is_final()
    state.take_entry((100, "complete"), {"name": "a"})
    assert state.ended_entries() == []
    # the run ended (aborted) with b still marked running: b is read all the same
    state.take(frame("aborted", ("a", "complete"), ("b", "running")), 1.0)
    assert state.ended_entries() == [("b", (100, "running"))] and not state.is_final()
    state.take_entry((100, "running"), {"name": "b"})
    assert state.is_final() and state.document()["final"] is True
    assert [e["name"] for e in state.loops_document()["entries"]] == ["a", "b"]


def test_the_entry_view_predicts_as_the_model_does(finished_run: Path):
    params = load_params(ROOT / "experiments" / "hybrid-params.json")
    overlay, detail = entry_view(read_entry(finished_run, VANISHING[0]), params)
    assert "model" not in overlay["loop"]
    v = vanishing_drive(np.arange(VANISHING[2]))
    expected = DynamicHysteresisModel(params).predict(v, 1000.0, method="fast")
    np.testing.assert_allclose(detail["series"]["model"], expected, rtol=1e-4, atol=1e-3)
    # and as the live view drew it, block by block while the entry was written
    state = LiveState(params)
    for k in range(0, VANISHING[2], 700):
        state.take(frame_of(v[k : k + 700], k), 1.0)
    live = state.entry.array("model") if state.entry is not None else np.empty(0)
    np.testing.assert_allclose(detail["series"]["model"], live, rtol=1e-4, atol=1e-3)


def frame_of(v: np.ndarray, start: int) -> Frame:
    info = EntryInfo("e", 0, "running", start + v.size, None, "e", 1000.0, 1.0)
    t = (start + np.arange(v.size)) / 1000.0
    return Frame(
        "running", "", "", ["e"], [info], "e", start, {"time": t, "command_voltage": v, "strain": v}
    )


@pytest.mark.parametrize(
    ("n", "rate", "freq", "whole", "expected"),
    [
        (5000, 1000.0, 1.0, True, slice(0, 5000, 25)),  # 1000 / 40 = 25 samples a step
        (5000, 1000.0, 25.0, True, slice(3500, 5000, 1)),  # 40 samples a period: every one
        (5000, 1000.0, 1000 / 80, True, slice(2000, 5000, 2)),  # 80 a period: every other
        (5000, 1000.0, 1000 / 79, True, slice(3500, 5000, 1)),  # 79: every one (floor)
        (10_000, 1000.0, None, False, slice(4000, 10_000, 4)),  # live: the last 6000
        (10_000, 1000.0, None, True, slice(0, 10_000, 7)),  # ended: all, at most 1500 points
        (0, 1000.0, 1.0, True, slice(0, 0)),
    ],
)
def test_which_samples_a_loop_draws(n, rate, freq, whole, expected):
    got = loop_slice(n, rate, freq, MAX_POINTS, whole)
    assert got == expected
    assert len(range(n)[got]) <= MAX_POINTS


def test_the_overlay_shares_its_points_among_the_entries():
    assert overlay_points(1) == MAX_POINTS
    assert overlay_points(OVERLAY_POINTS // MAX_POINTS) == MAX_POINTS
    assert overlay_points(OVERLAY_POINTS // MAX_POINTS + 1) < MAX_POINTS
    assert overlay_points(10_000) == MIN_OVERLAY_POINTS


def test_the_entry_route_checks_its_query(served: LiveServer):
    port, host = served.port, f"127.0.0.1:{served.port}"
    for _ in range(50):
        if json.loads(request(port, "/frame", host)[2]).get("final"):
            break
        time.sleep(0.1)
    code, _, body = request(port, f"/entry?name={ENTRIES[0][0]}", host)
    assert code == 200 and json.loads(body)["name"] == ENTRIES[0][0]
    assert request(port, "/entry?name=nope", host)[0] == 404
    assert request(port, "/entry?name=../../etc/passwd", host)[0] == 404
    for query in ("", "?", "?name=a&name=b", "?other=1", "?name"):
        assert request(port, "/entry" + query, host)[0] == 400, query


# -- the lifetime of the view -----------------------------------------------------------------


@pytest.mark.slow  # about 7-10 s: a labrig process and a run; fast: below
def test_the_view_process_serves_the_ended_run_until_its_input_closes(finished_run: Path):
    live = LiveProcess()
    try:
        live.follow(finished_run)
        live.end(finished_run)
        time.sleep(LINGER_S + 0.5)  # past the linger: still serving, the run has ended
        assert live.alive
        doc = get(live.url + "frame")
        assert doc["status"] == "complete" and doc["ended"] is True
        t0 = time.monotonic()
        live.close()
        assert not live.alive and time.monotonic() - t0 < LINGER_S + slack(2.0)
    finally:
        if live.alive:
            live.proc.kill()
    with pytest.raises(OSError):
        get(live.url + "frame")


TINY_LIVE = """\
name: tiny live
rate_hz: 1000
steps:
  - {kind: sine, amplitude_V: 50, frequency_hz: 5, duration_s: %s}
"""


def start_live_run(tmp_path: Path, duration_s: float, *options: str) -> subprocess.Popen:
    proto = tmp_path / "tiny.yaml"
    proto.write_text(TINY_LIVE % duration_s)
    cmd = [sys.executable, "-m", "labrig.cli", "run", str(proto), "--out", str(tmp_path / "r.h5")]
    return subprocess.Popen(
        [*cmd, "--seed", "1", "--live", *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def read_until(proc: subprocess.Popen, prefix: str, timeout: float = 60) -> str:
    assert proc.stderr is not None
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stderr], [], [], 0.5)
        if ready:
            line = proc.stderr.readline()
            seen.append(line)
            if line.startswith(prefix):
                return line
        if proc.poll() is not None and not ready:
            break
    pytest.fail(f"no line starting {prefix!r}: {seen}")


@pytest.mark.slow  # about 7-10 s: a labrig process and a run; fast: below
def test_run_live_paces_the_rig_then_serves_the_finished_run_until_ctrl_c(tmp_path: Path):
    proc = start_live_run(tmp_path, 1.0)
    try:
        line = read_until(proc, "live view: serving the finished run at ")
        assert "until Ctrl-C" in line
        url = line.split(" at ", 1)[1].split()[0]
        # the run file is complete and closed before Ctrl-C
        run = read_run(tmp_path / "r.h5", load_data=False)
        assert run.status == "complete" and not run.being_written
        with h5py.File(tmp_path / "r.h5") as f:  # paced by the clock (--live: --realtime)
            start = datetime.fromisoformat(f["run/start_time"][()].decode())
            end = datetime.fromisoformat(f["run/end_time"][()].decode())
        assert (end - start).total_seconds() >= 1.0
        for _ in range(50):  # the end-of-run page's documents
            doc = get(url + "frame")
            if doc.get("final"):
                break
            time.sleep(0.1)
        assert doc["status"] == "complete" and doc["final"]
        assert len(get(url + "loops")["entries"]) == 1
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
        assert proc.stdout is not None and proc.stdout.read().strip() == str(tmp_path / "r.h5")
        with pytest.raises(OSError):
            get(url + "frame")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow  # about 7-10 s: a labrig process and a run; fast: below
def test_run_live_no_realtime_and_a_bounded_hold(tmp_path: Path):
    proc = start_live_run(tmp_path, 4.0, "--no-realtime", "--live-hold", "0.5")
    try:
        assert proc.wait(timeout=60) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.stderr is not None
    err = proc.stderr.read()
    assert "serving the finished run at" in err and "for 0.5 s" in err
    with h5py.File(tmp_path / "r.h5") as f:  # not paced: well under the 4 s of protocol time
        start = datetime.fromisoformat(f["run/start_time"][()].decode())
        end = datetime.fromisoformat(f["run/end_time"][()].decode())
    assert (end - start).total_seconds() < 4.0


@pytest.mark.slow  # about 7-10 s: a labrig process and a run; fast: below
def test_ctrl_c_during_a_live_run_stops_it_and_is_not_held(tmp_path: Path):
    proc = start_live_run(tmp_path, 30.0)
    try:
        url = read_until(proc, "live view: ").split(": ", 1)[1].strip()
        for _ in range(100):  # the run is going: the view has its first samples
            if get(url + "frame").get("status") == "running":
                break
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 130
        assert proc.stderr is not None
        assert "serving the finished run" not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with h5py.File(tmp_path / "r.h5") as f:
        assert f["run/status"][()] == b"aborted"
        assert f["run/final_amplifier_voltage_V"][()] == 0.0


def test_watch_serves_a_finished_run_until_ctrl_c(finished_run: Path, tmp_path: Path):
    """... and says on its terminal when the file is deleted (and in the page's footer)."""
    path = tmp_path / "run.h5"
    path.write_bytes(finished_run.read_bytes())
    watch = subprocess.Popen(
        [sys.executable, "-m", "labrig.cli", "watch", str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert watch.stdout is not None
        ready, _, _ = select.select([watch.stdout], [], [], 30)
        line = watch.stdout.readline() if ready else ""
        assert "(Ctrl-C to stop)" in line, line
        url = line.split(": ", 1)[1].split()[0]
        for _ in range(50):
            doc = get(url + "frame")
            if doc.get("final"):
                break
            time.sleep(0.1)
        assert doc["status"] == "complete" and doc["final"]
        assert len(get(url + "loops")["entries"]) == 3
        path.unlink()
        assert watch.stderr is not None
        ready, _, _ = select.select([watch.stderr], [], [], 10)
        said = watch.stderr.readline() if ready else ""
        assert f"{path} is gone (deleted or renamed)" in said, said
        for _ in range(50):
            doc = get(url + "frame")
            if doc["error"]:
                break
            time.sleep(0.1)
        assert "no such file now" in doc["error"] and doc["status"] == "complete"
        # the view's reading process (one, long-lived) ends with the view
        tasks = Path(f"/proc/{watch.pid}/task").glob("*/children")  # (a thread started it)
        children = [c for t in tasks for c in t.read_text().split()]
        assert len(children) == 1, children
        watch.send_signal(signal.SIGINT)
        assert watch.wait(timeout=10) == 0
        deadline = time.monotonic() + 5
        while Path(f"/proc/{children[0]}").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not Path(f"/proc/{children[0]}").exists(), "the reading process outlived watch"
    finally:
        if watch.poll() is None:
            watch.kill()
            watch.wait()


# -- the same lifetime, in-process (the fast tier) --------------------------------------------


class FakeLive:
    """What ``serve_finished_run`` uses of :class:`LiveProcess`."""

    url = "http://127.0.0.1:9/"

    def __init__(self, alive: bool = True):
        self.closed_at: float | None = None if alive else 0.0

    @property
    def alive(self) -> bool:
        return self.closed_at is None

    def close(self) -> None:
        self.closed_at = time.monotonic()


def serve_finished(exit_code: int, hold: float | None, live: FakeLive) -> tuple[str, float]:
    out = io.StringIO()
    outcome = RunOutcome(Path("r.h5"), "complete" if exit_code == 0 else "aborted", "", exit_code)
    t0 = time.monotonic()
    serve_finished_run(Console(file=out, width=200), live, outcome, hold)
    return out.getvalue(), time.monotonic() - t0


def test_a_finished_run_is_served_until_ctrl_c_then_closed():
    live = FakeLive()
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        said, took = serve_finished(0, None, live)  # Ctrl-C ends it, raising nothing
    finally:
        timer.cancel()
    assert "serving the finished run at http://127.0.0.1:9/ until Ctrl-C" in said
    assert "live view: closed" in said
    assert live.closed_at is not None and 0.25 < took < 5


def test_a_bounded_hold_ends_by_itself():
    live = FakeLive()
    said, took = serve_finished(0, 0.3, live)
    assert "for 0.3 s (Ctrl-C to stop sooner)" in said and live.closed_at is not None
    assert 0.3 <= took < 5
    live = FakeLive()
    said, took = serve_finished(3, 0.0, live)  # 0: not held at all
    assert said == "" and live.closed_at is not None and took < 0.2


@pytest.mark.parametrize("code", [129, 130, 131, 143])
def test_a_run_stopped_by_a_signal_is_not_held(code: int):
    live = FakeLive()
    said, took = serve_finished(code, None, live)
    assert said == "" and live.closed_at is not None and took < 0.2


def test_a_view_that_died_is_not_waited_for():
    said, took = serve_finished(0, None, FakeLive(alive=False))
    assert said == "" and took < 0.2


def test_a_failed_run_is_held_like_a_complete_one():
    live = FakeLive()
    said, _ = serve_finished(3, 0.1, live)  # a device fault: exit 3, kept on view
    assert "serving the finished run" in said


@pytest.mark.parametrize(
    ("options", "realtime", "live"),
    [
        ([], False, False),
        (["--realtime"], True, False),
        (["--live"], True, True),  # a live view is watched: paced by the clock
        (["--live", "--no-realtime"], False, True),
        (["--live-port", "0"], True, True),
        (["--live-hold", "0"], True, True),
        (["--live-hold", "2.5", "--no-realtime"], False, True),
    ],
)
def test_live_paces_a_simulated_rig_unless_told(monkeypatch, options, realtime, live):
    seen: dict = {}

    def fake(protocol, rig, out, seed, rt, overwrite, extras):
        seen.update(realtime=rt, live=extras.live, hold=extras.live_hold)
        return 0

    monkeypatch.setattr("labrig.cli.run_execute.run_with_progress", fake)
    res = invoke("run", ROOT / "experiments" / "sweep.yaml", *options)
    assert res.exit_code == 0, res.output
    assert (seen["realtime"], seen["live"]) == (realtime, live)
    if "--live-hold" in options:
        assert seen["hold"] == float(options[options.index("--live-hold") + 1])


def test_a_negative_hold_is_a_usage_error():
    res = invoke("run", ROOT / "experiments" / "sweep.yaml", "--live-hold", "-1")
    assert res.exit_code == 64 and "--live-hold" in res.output


def test_the_view_process_goes_on_after_the_end_until_its_input_closes(
    monkeypatch, finished_run: Path
):
    """``python -m labrig.live``'s command loop, in-process: ``end`` does not stop it; the end
    of its input does."""
    from labrig.live import __main__ as live_main

    made: list[LiveServer] = []
    events: list[str] = []

    class Recording(LiveServer):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self)

        def end(self, final_path: Path | None = None) -> None:
            events.append(f"end {final_path} stopped={self.stopping.is_set()}")
            super().end(final_path)

        def stop(self) -> None:
            events.append("stop")
            super().stop()

    monkeypatch.setattr(live_main, "LiveServer", Recording)
    monkeypatch.setattr(live_main.signal, "signal", lambda *a: None)
    monkeypatch.setattr(sys, "stdin", io.StringIO(f"file {finished_run}\nend {finished_run}\n"))
    assert live_main.main([]) == 0
    assert events == [f"end {finished_run} stopped=False", "end None stopped=False", "stop"]
    assert made[0].state.frame is not None and made[0].state.frame.status == "complete"


def page_has_the_final_state(server: LiveServer) -> None:
    """What an open page does: ask /frame until final, then /loops and the last entry."""
    port, host = server.port, f"127.0.0.1:{server.port}"
    for _ in range(100):
        if json.loads(request(port, "/frame", host)[2]).get("final"):
            break
        time.sleep(0.05)
    assert request(port, "/loops", host)[0] == 200
    assert request(port, f"/entry?name={VANISHING[0]}", host)[0] == 200


def test_closing_tells_an_open_page_then_stops(finished_run: Path):
    server = LiveServer(finished_run)
    server.start()
    server.end()
    page_has_the_final_state(server)
    closer = threading.Thread(target=server.close)
    closer.start()
    try:
        time.sleep(0.3)
        assert closer.is_alive()  # it waits for the page to be told
        doc = json.loads(request(server.port, "/frame", f"127.0.0.1:{server.port}")[2])
        assert doc["closing"] is True and doc["final"] is True
        t0 = time.monotonic()
        closer.join(timeout=LINGER_S)
        assert not closer.is_alive() and time.monotonic() - t0 < slack(1.5)
    finally:
        closer.join(timeout=10)


def test_closing_waits_at_most_linger_s_and_not_for_a_page_that_has_gone(finished_run: Path):
    server = LiveServer(finished_run)
    server.start()
    server.end()
    port, host = server.port, f"127.0.0.1:{server.port}"
    # a page that asks for the state but has not fetched the loops yet: waited for, up to
    # LINGER_S
    stop_asking = threading.Event()

    def ask() -> None:
        while not stop_asking.is_set():
            try:
                request(port, "/frame", host)
            except OSError:  # the server has stopped
                return
            time.sleep(0.2)

    asker = threading.Thread(target=ask)
    asker.start()
    try:
        time.sleep(0.3)
        t0 = time.monotonic()
        server.close()
        took = time.monotonic() - t0
    finally:
        stop_asking.set()
        asker.join(timeout=10)
    assert LINGER_S - 0.1 <= took < LINGER_S + slack(1.0)
    # a page that had the final state and went away: not waited for after PAGE_GONE_S
    gone = LiveServer(finished_run)
    gone.start()
    gone.end()
    page_has_the_final_state(gone)
    t0 = time.monotonic()
    gone.close()
    # (stop() itself takes up to 0.5 s: the server loop's poll interval)
    assert time.monotonic() - t0 < PAGE_GONE_S + slack(1.0)
    # and no page ever: no wait
    quiet = LiveServer(finished_run)
    quiet.start()
    t0 = time.monotonic()
    quiet.close()
    assert time.monotonic() - t0 < slack(1.0)


def test_ended_entries_are_taken_as_they_were_not_read_again(finished_run: Path):
    """A frame takes the entries seen ended before as given (their facts and seals were most
    of a frame's reading in a campaign of many entries): a changed copy passed in comes back
    as is; the others are read, and a frame with the read ones equals a frame read whole."""
    whole = read_frame(finished_run, None, 0, {})
    first = whole.entries[0]
    marked = EntryInfo(**{**first.__dict__, "title": "taken as given"})
    fid = whole.file_id
    frame = read_frame(finished_run, None, 0, {}, {first.name: marked}, fid)
    assert frame.entries[0] is not first and frame.entries[0].title == "taken as given"
    assert frame.entries[1:] == whole.entries[1:]
    # facts said to be of another file (the path replaced since) are not taken
    other = (fid[0], fid[1] + 1)
    assert read_frame(finished_run, None, 0, {}, {first.name: marked}, other).entries[0] == first
    again = read_frame(finished_run, None, 0, {}, {e.name: e for e in whole.entries}, fid)
    assert again.entries == whole.entries and again.status == whole.status
    for c in whole.samples:
        assert np.array_equal(again.samples[c], whole.samples[c])


def test_the_view_forgets_what_it_knew_of_a_replaced_file(tmp_path: Path, finished_run: Path):
    """The server keeps the ended entries and step facts of the file it reads; another file
    at the path (a run replaced with --overwrite: written beside, renamed) is read anew."""
    path = tmp_path / "run.h5"
    path.write_bytes(finished_run.read_bytes())
    server = LiveServer(path)
    try:
        server.read_once()
        names = [e[0] for e in ENTRIES] + [VANISHING[0]]
        assert sorted(server.state.ended) == sorted(names)
        other = tmp_path / "other.h5"
        with RunWriter(other, "", "", {}, seed=1) as w:
            w.begin_entry("only", {}, 100.0, ["strain"]).append({"strain": [1.0, 2.0, 3.0]})
        os.replace(other, path)
        server.read_once()
        assert list(server.state.ended) == ["only"] and list(server.state.step_facts) == ["only"]
        assert [e.name for e in server.state.frame.entries] == ["only"]
    finally:
        server.httpd.server_close()


@pytest.mark.parametrize("how", ["renamed", "copied over"])
def test_a_run_replaced_by_one_of_the_same_entries_is_shown_as_it_is_now(
    tmp_path: Path, finished_run: Path, how: str
):
    """``labrig run --overwrite`` of the same protocol (the new file renamed into place), or
    another run's file copied over this one (``cp``: the same inode): the new file has the old
    one's entry names, lengths and statuses and other samples. The view drops the old file's
    loops at the first frame of the new one and serves the new samples for every entry (the
    loops of the overlay and ``/entry``), not what it kept of the old file."""
    path = tmp_path / "run.h5"
    path.write_bytes(finished_run.read_bytes())
    name = ENTRIES[0][0]
    server = LiveServer(path)
    try:
        server.read_once()
        while server.read_ended_entry():
            pass
        old_strain = server.state.loops[name]["loop"]["strain"]
        assert json.loads(server.entry_document(name) or b"")["loop"]["strain"] == old_strain
        other = tmp_path / "other.h5"
        other.write_bytes(finished_run.read_bytes())
        with h5py.File(other, "r+") as f:
            f[name]["data"]["strain"][...] = -2.0 * f[name]["data"]["strain"][...]
            f.attrs["file_time"] = "2026-11-29T10:00:00.000+00:00"  # another run's file
        if how == "renamed":
            os.replace(other, path)
        else:
            shutil.copyfile(other, path)
        server.read_once()
        assert server.state.loops == {} and server.state.ended_entries()
        assert json.loads(server.document())["files"] == 1  # the page's cue to drop its entry
        while server.read_ended_entry():
            pass
        # the page's numbers have 5 significant digits: both sides rounded once
        new_strain = [-2.0 * x for x in old_strain]
        loop = server.state.loops[name]["loop"]["strain"]
        np.testing.assert_allclose(loop, new_strain, rtol=1e-4)
        served = json.loads(server.entry_document(name) or b"")["loop"]["strain"]
        np.testing.assert_allclose(served, new_strain, rtol=1e-4)
    finally:
        server.httpd.server_close()


def test_a_deleted_run_file_is_said_to_be_gone(tmp_path: Path, finished_run: Path):
    """The file watched is deleted: the frame says so (not a silent "running" forever), and
    the view reads it again once a file is back at the path."""
    path = tmp_path / "run.h5"
    path.write_bytes(finished_run.read_bytes())
    server = LiveServer(path)
    try:
        server.read_once()
        assert server.state.last_error == ""
        path.unlink()
        server.read_once()
        doc = json.loads(server.document())
        assert "no such file now" in doc["error"] and str(path) in doc["error"]
        path.write_bytes(finished_run.read_bytes())
        server.read_once()
        assert json.loads(server.document())["error"] == ""
    finally:
        server.httpd.server_close()
