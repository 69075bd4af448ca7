"""Reading a run file while it is written: ``labrig watch FILE`` from a second terminal (its
page's data, ``/frame``), ``labrig info`` saying the file is being written (and incomplete once
its writer is killed), and damaged reads skipped. The browser test is test_live_browser.py."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from labrig.live.frames import read_frame
from labrig.live.server import LiveServer
from labrig.store import RunWriter, read_run

pytestmark = pytest.mark.timeout(120)

#: a writer that appends a 100-sample block every 0.1 s (as labrig run does at 1 kHz)
WRITER = """
import sys, time, numpy as np
from labrig.store import RunWriter, read_run
path, blocks = sys.argv[1], int(sys.argv[2])
with RunWriter(path, "name: w\\n", "", {}, seed=1, protocol_name="watch test",
               planned_entries=["first", "second"]) as w:
    for name in ("first", "second"):
        e = w.begin_entry(name, {"kind": "sine", "n_samples": blocks * 100}, 1000.0,
                          ["command_voltage", "strain"])
        for b in range(blocks):
            k = np.arange(b * 100, (b + 1) * 100)
            v = 50 * (1 - np.cos(2 * np.pi * k / 500))
            e.append({"command_voltage": v, "strain": 9 * v})
            print("block", name, b, flush=True)
            time.sleep(0.1)
        e.finish("complete")
"""


def start_writer(path: Path, blocks: int) -> subprocess.Popen:
    p = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), str(blocks)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert p.stdout is not None
    assert p.stdout.readline().startswith("block first 0")
    return p


def labrig(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "labrig.cli", *args], capture_output=True, text=True, **kw
    )


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def test_watch_follows_a_run_being_written(tmp_path: Path):
    run = tmp_path / "run.h5"
    writer = start_writer(run, blocks=15)
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
        frames = []
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            frames.append(get(url + "frame"))
            time.sleep(0.1)
        running = [f for f in frames if f.get("status") == "running" and "entry" in f]
        assert len(running) >= 5
        samples = [f["entry"]["samples"] for f in running if f["entry"]["name"] == "first"]
        assert samples == sorted(samples) and samples[-1] > samples[0]  # it grows as written
        assert running[-1]["writing"] == "being written"
        assert running[-1]["progress"]["planned"] == 2
        seqs = {f["seq"] for f in running}
        assert len(seqs) / 2.0 >= 5  # at least 5 new states a second
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
        watch.send_signal(signal.SIGINT)
        assert watch.wait(timeout=10) == 130
    finally:
        for p in (writer, watch):
            if p.poll() is None:
                p.kill()
                p.wait()


def test_info_says_being_written_then_incomplete_after_a_kill(tmp_path: Path):
    run = tmp_path / "run.h5"
    writer = start_writer(run, blocks=100)
    try:
        r = labrig("info", str(run), timeout=60)
        assert r.returncode == 0, r.stderr
        assert "being written now by process" in r.stdout
        assert str(writer.pid) in r.stdout
    finally:
        os.kill(writer.pid, signal.SIGKILL)
        writer.wait()
    r = labrig("info", str(run), timeout=60)
    assert r.returncode == 0, r.stderr
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
