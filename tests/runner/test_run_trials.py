"""What a new user's trial of ``labrig run`` left open, mended:

- a run killed (SIGKILL) in the middle of an entry, then resumed: the kept partial entry reads
  ``aborted`` with a reason, not ``running``, and has the ``end_time`` and ``duration`` of
  its samples, marked reconstructed; before the resume the file reads as it did (running,
  incomplete); the channels' CRC-32 for its seals is read in blocks, the whole array's;
- ``--live-hold`` refuses what would hang or means nothing (``inf``, ``nan``, negative,
  longer than a day): a usage error naming the option and the range; a day is accepted;
- a live view that stops during ``run --live`` (its process killed, or a thread of it failed)
  is said once on stderr, with why and without a traceback, and the run completes with its
  own exit code;
- a standard error that cannot be written (``2>/dev/full``) does not stop a run or change
  its exit code.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.runner import execute as runner
from labrig.store import RunFile, read_run
from labrig.store.format import STRING_DTYPE as STR

from helpers import fork_saying, invoke, reaped, slack

pytestmark = pytest.mark.timeout(120)

EXE = Path(sys.executable).parent / "labrig"

#: one short entry, written in the style of experiments/sweep.yaml
PROTOCOL = """\
name: trial
rate_hz: 500
steps:
  - kind: sine
    amplitude_V: 50
    frequency_hz: 5
    duration_s: {duration_s}
"""
ENTRY = "sine_50V_5Hz"


def protocol(tmp_path: Path, duration_s: float = 1.0) -> Path:
    p = tmp_path / "trial.yaml"
    p.write_text(PROTOCOL.format(duration_s=duration_s))
    return p


# -- 1. the entry a kill cut short, once a resume has taken the file over --------------------


def killed_in_the_entry(proto: Path, out: Path) -> None:
    """``proto`` run at the clock's pace into ``out`` in a fork of this process, SIGKILLed
    once a fifth of its entry is written."""

    def run(said: int) -> None:
        def progress(k, n, name, frac, left):
            if name == ENTRY and frac >= 0.2:
                os.write(said, b"playing\n")

        plan, rig = runner.preflight(proto, None)
        runner.execute(plan, rig, out, seed=1, realtime=True, progress=progress)

    pid, read_fd = fork_saying(run)
    try:
        assert select.select([read_fd], [], [], 60)[0], "the run never played its entry"
        os.kill(pid, signal.SIGKILL)
    finally:
        status = reaped(pid)
        os.close(read_fd)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


@pytest.fixture(scope="module")
def resumed(tmp_path_factory) -> tuple[Path, RunFile]:
    """A run SIGKILLed in its entry, then resumed: the file and how it read before the resume
    (killed once per module: the run plays at the clock's pace)."""
    where = tmp_path_factory.mktemp("killed")
    proto, out = protocol(where, 4.0), where / "run.h5"
    killed_in_the_entry(proto, out)
    before = read_run(out)  # never resumed: reads as it did (running, incomplete)
    assert before.status == "running" and before.incomplete and not before.being_written
    assert before[ENTRY].status == "running" and before[ENTRY].n_samples > 0

    res = invoke("run", proto, "--resume", out, "--seed", 2)
    assert res.exit_code == 0, res.output
    return out, before


def test_a_killed_entry_reads_aborted_once_a_resume_takes_the_file_over(resumed):
    out, before = resumed
    tmp_path = out.parent
    after = read_run(out)  # every sample and seal verified
    kept = after[f"{ENTRY}_partial1"]
    assert kept.status == "aborted"
    assert "ended while this entry was being written" in kept.reason
    assert "kept as recorded" in kept.reason and "resume 1" in kept.reason
    for channel, values in before[ENTRY].data.items():  # its samples as recorded
        np.testing.assert_array_equal(kept[channel], values)
    assert after[ENTRY].status == "complete" and after.status == "complete"
    listed = json.loads(invoke("runs", tmp_path, "--json").stdout)["runs"][0]["entries"]
    assert {e["name"]: e["status"] for e in listed} == {
        f"{ENTRY}_partial1": "aborted",
        ENTRY: "complete",
    }
    info = invoke("info", out)
    assert "running" not in info.stdout and "aborted" in info.stdout


def test_the_killed_entry_gets_the_end_time_and_duration_of_its_samples(resumed):
    """The resume closes the abandoned entry as an ended one is closed: ``duration`` the time
    from its first to its last kept sample, ``end_time`` its start plus that, both marked
    reconstructed (``@reconstructed``, and in the reason)."""
    out, before = resumed
    kept = read_run(out)[f"{ENTRY}_partial1"]
    n, rate = before[ENTRY].n_samples, before[ENTRY].rate_hz
    assert kept.n_samples == n > 1
    with h5py.File(out, "r") as f:
        g, ended = f[f"{ENTRY}_partial1"], f[ENTRY]
        assert set(g) == set(ended)  # every field an ended entry has
        duration = g["duration"]
        assert float(duration[()]) == pytest.approx((n - 1) / rate, abs=1e-12)
        assert float(duration[()]) == pytest.approx(kept.time[-1] - kept.time[0], abs=1e-12)
        for name in ("units", "long_name"):  # as finish() writes them
            assert duration.attrs[name] == ended["duration"].attrs[name]
        assert "reconstructed" not in ended["duration"].attrs
        assert "reconstructed" not in ended["end_time"].attrs
        assert "samples kept" in duration.attrs["reconstructed"]
        assert "start_time + duration" in g["end_time"].attrs["reconstructed"]
        started = datetime.fromisoformat(g["start_time"][()].decode())
        recorded = str(g["start_time"][()].decode())
    assert kept.end_time and kept.start_time == recorded
    ended_at = datetime.fromisoformat(kept.end_time)
    assert ended_at.utcoffset() == started.utcoffset()
    # ISO 8601 to the millisecond, as every time in the file
    assert abs((ended_at - started).total_seconds() - (n - 1) / rate) <= 0.0005
    assert "end_time and duration are reconstructed from the samples kept" in kept.reason


# -- 1b. a channel's CRC-32, read in blocks ------------------------------------------------------


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 15, 16, 17, 37])
def test_a_channels_crc_read_in_blocks_is_the_whole_arrays(tmp_path, n):
    """``samples_crc`` (the resume's and ``seal_all``'s seal of a channel) reads the samples
    8 at a time here: lengths under, at and over one and two blocks give ``data_crc`` of the
    whole array, the value the reader checks; chunks of 5 straddle the blocks."""
    from labrig.store.format import data_crc
    from labrig.store.writer import samples_crc

    values = np.random.default_rng(n).normal(size=n) * 1e3
    with h5py.File(tmp_path / "c.h5", "w") as f:
        ds = f.create_dataset("x", data=values, chunks=(5,), maxshape=(None,), fletcher32=True)
        assert samples_crc(ds, block=8) == (data_crc(values), n)
        assert samples_crc(ds, block=8) == (data_crc(ds[()]), n)
        assert samples_crc(ds) == samples_crc(ds, block=1) == (data_crc(values), n)
        with pytest.raises(ValueError):
            samples_crc(ds, block=0)


def test_an_abandoned_entry_is_ended_and_sealed_a_block_at_a_time(tmp_path, monkeypatch):
    """``end_abandoned_entry`` on a channel of one block and 3 samples (8 MB) and a shorter
    one: no read of more than a block (2**20 samples) of a channel, by it or by the
    ``seal_all`` after it; the seals the whole arrays' CRC; duration from the shortest
    channel, end time from the start time (its UTC offset kept, to the millisecond)."""
    from labrig.store.format import data_crc, sealed_data
    from labrig.store.writer import end_abandoned_entry, seal_all

    n, rate = 2**20 + 3, 3.0
    values = np.random.default_rng(1).normal(size=n)
    with h5py.File(tmp_path / "a.h5", "w") as f:
        g = f.create_group("e")
        g.create_dataset("sample_rate", data=rate)
        g.create_dataset("start_time", data="2026-01-02T03:04:05.678+02:00", dtype=STR)
        g.create_dataset("status", data="running", dtype=STR)
        data = g.create_group("data")
        for name, x in (("time", values), ("strain", values[:-2])):
            data.create_dataset(name, data=x, chunks=(4096,), maxshape=(None,))
        reads: list[int] = []
        getitem, read_direct = h5py.Dataset.__getitem__, h5py.Dataset.read_direct

        def counted_getitem(self, key, *args, **kwargs):
            out = getitem(self, key, *args, **kwargs)
            if self.parent.name == "/e/data":
                reads.append(np.size(out))
            return out

        def counted_read_direct(self, dest, source_sel=None, dest_sel=None):
            if self.parent.name == "/e/data":
                reads.append(dest.size if dest_sel is None else dest[dest_sel].size)
            return read_direct(self, dest, source_sel, dest_sel)

        monkeypatch.setattr(h5py.Dataset, "__getitem__", counted_getitem)
        monkeypatch.setattr(h5py.Dataset, "read_direct", counted_read_direct)
        end_abandoned_entry(g, "gone")
        seal_all(f)
        monkeypatch.undo()
        assert reads and max(reads) <= 2**20
        assert sealed_data(data["time"]) == (data_crc(values), n)
        assert sealed_data(data["strain"]) == (data_crc(values[:-2]), n - 2)
        assert g["status"][()] == b"aborted"
        assert g["status_reason"][()].decode().startswith("gone; its end_time and duration")
        assert float(g["duration"][()]) == pytest.approx((n - 3) / rate, abs=1e-12)
        assert g["duration"].attrs["units"] == "s"
        end = g["end_time"][()].decode()
    # 2**20 / 3 s = 349525.333 s = 4 d 1 h 5 min 25.333 s after the start
    assert end == "2026-01-06T04:09:31.011+02:00"


# -- 2. --live-hold ------------------------------------------------------------------------


def holds_seen(monkeypatch: pytest.MonkeyPatch) -> list:
    """``labrig run`` records the ``--live-hold`` it was given instead of running (a hold
    taken would otherwise be served: forever, for ``inf``)."""
    seen: list = []

    def fake(protocol, rig, out, seed, realtime, overwrite, extras):
        seen.append(extras.live_hold)
        return 0

    monkeypatch.setattr("labrig.cli.run_execute.run_with_progress", fake)
    return seen


@pytest.mark.parametrize("value", ["inf", "-inf", "nan", "1e300", "86400.5", "-1"])
def test_a_live_hold_that_would_hang_or_means_nothing_is_a_usage_error(
    monkeypatch, tmp_path, value
):
    seen = holds_seen(monkeypatch)
    res = invoke("run", protocol(tmp_path), "--out", tmp_path / "r.h5", f"--live-hold={value}")
    assert res.exit_code == 64, res.output
    assert "--live-hold" in res.output and "0 to 86400" in res.output
    assert "Traceback" not in res.output and seen == []


def test_a_live_hold_of_up_to_a_day_is_taken(monkeypatch, tmp_path):
    seen = holds_seen(monkeypatch)
    for value in ("0", "2.5", "86400"):
        res = invoke("run", protocol(tmp_path), "--live-hold", value)
        assert res.exit_code == 0, res.output
    assert seen == [0.0, 2.5, 86400.0]
    assert invoke("run", protocol(tmp_path), "--live-hold", "86401").exit_code == 64


# -- 3. a live view that stops while the run goes on ------------------------------------------


def test_a_live_view_killed_during_the_run_is_said_once_and_the_run_completes(
    monkeypatch, tmp_path
):
    from labrig.live.launch import LiveProcess

    follow = LiveProcess.follow

    def killed_then_follow(self, path):  # the run file exists: the run has begun
        self.proc.kill()
        self.proc.wait(timeout=10)
        follow(self, path)

    monkeypatch.setattr(LiveProcess, "follow", killed_then_follow)
    out = tmp_path / "r.h5"
    res = invoke(
        "run", protocol(tmp_path), "--out", out, "--seed", 1, "--live", "--no-realtime",
        "--live-hold", "0",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert res.stderr.count("live view stopped") == 1, res.stderr
    assert "killed by SIGKILL" in res.stderr and "Traceback" not in res.output
    assert "serving the finished run" not in res.stderr
    run = read_run(out)
    assert run.status == "complete" and run[ENTRY].complete


class _OpenInput:
    """A standard input that stays open (no command, no end) until :attr:`gate` is set."""

    def __init__(self) -> None:
        self.gate = threading.Event()

    def __iter__(self):
        self.gate.wait(5)
        return iter(())


def test_a_failed_thread_ends_the_view_process_with_why(monkeypatch, capsys):
    """``python -m labrig.live``'s loop, in-process: its file reader fails; the process says
    ``failed WHY`` on its output (for ``labrig run``), stops serving and exits 1."""
    from labrig.live import __main__ as live_main
    from labrig.live.server import LiveServer

    def broken(self) -> None:
        raise RuntimeError("boom")

    monkeypatch.setattr(LiveServer, "read_once", broken)
    monkeypatch.setattr(live_main.signal, "signal", lambda *a: None)
    stdin = _OpenInput()
    monkeypatch.setattr(sys, "stdin", stdin)
    t0 = time.monotonic()
    try:
        code = live_main.main([])
    finally:
        stdin.gate.set()
    said = capsys.readouterr().out.splitlines()
    assert code == 1 and time.monotonic() - t0 < slack(4.0)
    assert said[0].startswith("url http://127.0.0.1:")
    assert said[1] == "failed its file reader failed: RuntimeError: boom"
    port = int(said[0].rstrip("/").rsplit(":", 1)[1])
    with pytest.raises(OSError), socket.create_connection(("127.0.0.1", port), timeout=2):
        pass


def test_the_run_side_reads_why_the_view_failed_once(monkeypatch):
    from labrig.live import launch

    script = (
        "print('url http://127.0.0.1:9/', flush=True); "
        "print('failed its web server failed: OSError: gone', flush=True); "
        "raise SystemExit(1)"
    )
    command = [sys.executable, "-c", script]
    monkeypatch.setattr(launch, "server_command", lambda port, params: command)
    live = launch.LiveProcess()
    try:
        assert live.url == "http://127.0.0.1:9/"
        live.proc.wait(timeout=10)
        assert live.stopped() == "its web server failed: OSError: gone"
        assert live.stopped() == ""  # said once
    finally:
        live.close()


# -- 4. a standard error that cannot be written ------------------------------------------------


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_run_with_a_full_standard_error_completes_at_0_v_with_its_own_code(tmp_path):
    out = tmp_path / "r.h5"
    with open("/dev/full", "w") as full:
        res = subprocess.run(
            [str(EXE), "run", str(protocol(tmp_path, 0.4)), "--out", str(out), "--seed", "1"],
            stdout=subprocess.PIPE, stderr=full, text=True, timeout=120,
        )  # fmt: skip
        bad = subprocess.run(
            [str(EXE), "run", str(tmp_path / "none.yaml")], stderr=full, timeout=120
        )
    assert res.returncode == 0 and res.stdout.splitlines()[-1] == str(out)
    assert bad.returncode == 2  # a bad input stays exit 2, said or not
    with h5py.File(out, "r") as f:
        assert f["run/status"][()] == b"complete"
        assert int(f["run/exit_code"][()]) == 0
        assert abs(float(f["run/final_amplifier_voltage_V"][()])) < 0.5
    assert read_run(out)[ENTRY].complete
