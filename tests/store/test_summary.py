"""The summary a run file carries for listings (``/run/summary``): written when the writer closes
the file, absent while it is written or after a writer died, removed by a resume until its
close, left out when the disk has no room, and always what a full read of the file gives."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.catalogue.read import file_record_here
from labrig.core.metadata import RunMetadata
from labrig.store import RunWriter, read_run
from labrig.store import writer as writer_module
from labrig.store.summary import read_summary_here

STEP = {"kind": "sine", "amplitude_V": 20.0, "frequency_hz": 5.0}


def begin(path: Path, seed: int = 2**63 - 25) -> RunWriter:
    meta = RunMetadata({"operator": "ana", "sample": "P-888 #3"})
    return RunWriter(path, "name: s\n", "", {"daq": {"rate_hz": 100.0}}, seed,
                     protocol_name="s", planned_entries=["e0", "e1"], metadata=meta)  # fmt: skip


def entry(w: RunWriter, name: str, n: int = 50) -> None:
    e = w.begin_entry(name, STEP, 100.0, ["command_voltage", "strain"])
    v = np.linspace(0.0, 20.0, n)
    e.append({"command_voltage": v, "strain": 9.0 * v})
    e.finish()


def has_summary(path: Path) -> bool:
    """Read by another process, as a reader does while the writer holds the file open."""
    script = (
        "import sys, h5py\n"
        "with h5py.File(sys.argv[1], 'r', locking=False) as f:\n"
        "    print('summary' in f['run'])\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip() == "True"


def has_summary_closed(path: Path) -> bool:
    """:func:`has_summary` of a file no writer holds open any more, read in this process."""
    with h5py.File(path, "r", locking=False) as f:
        return "summary" in f["run"]


def wait_for(pid: int, timeout_s: float) -> int:
    """The exit code of the child ``pid``, which must end within ``timeout_s`` (else killed)."""
    end = time.monotonic() + timeout_s
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        if time.monotonic() > end:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise AssertionError("the writer did not end")
        time.sleep(0.01)


def test_written_at_the_close_and_equal_to_a_full_read(tmp_path: Path):
    path = tmp_path / "run.h5"
    w = begin(path)
    entry(w, "e0")
    assert not has_summary(path)  # being written: readers read the file itself
    entry(w, "e1", 70)
    w.finish("complete")
    assert not has_summary(path)
    w.close()
    summary = read_summary_here(path)
    assert summary is not None and summary["seed"] == 2**63 - 25
    assert [(e["name"], e["samples"]) for e in summary["entries"]] == [("e0", 50), ("e1", 70)]
    assert summary["metadata"]["sample/name"] == "P-888 #3"
    assert file_record_here(path) == file_record_here(path, full=True)
    assert read_run(path).additions == []  # the summary is labrig's own, sealed


def test_a_resume_removes_it_until_its_close(tmp_path: Path):
    path = tmp_path / "run.h5"
    w = begin(path)
    entry(w, "e0")
    w.close()  # closed unfinished: a summary that says so
    assert read_summary_here(path)["status"] == "running"
    again = RunWriter.reopen(path)
    assert not has_summary(path)
    entry(again, "e1")
    again.finish("complete")
    again.close()
    summary = read_summary_here(path)
    assert summary["status"] == "complete" and len(summary["entries"]) == 2
    assert file_record_here(path) == file_record_here(path, full=True)


def test_no_room_no_summary_and_the_file_reads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    path = tmp_path / "run.h5"
    w = begin(path)
    entry(w, "e0")
    w.finish("complete")
    monkeypatch.setattr(writer_module, "free_bytes", lambda _path: 1000)
    w.close()
    assert not has_summary_closed(path)
    assert read_run(path).status == "complete"  # every seal still matches
    assert file_record_here(path)["status"] == "complete"  # read in full


def test_a_writer_that_dies_leaves_no_summary(tmp_path: Path):
    path = tmp_path / "run.h5"
    pid = os.fork()  # the writer: a fork of this process (labrig loaded)
    if pid == 0:  # the child: never returns to the test, whatever happens
        code = 1
        try:
            w = RunWriter(path, "name: s", "", {}, 1, protocol_name="s")
            e = w.begin_entry("e0", {"kind": "hold"}, 100.0, ["strain"])
            e.append({"strain": np.zeros(30)})
            code = 0
        finally:
            os._exit(code)  # no close, as after kill -9
    assert wait_for(pid, timeout_s=60) == 0
    assert not has_summary_closed(path)
    record = file_record_here(path)
    assert record["status"] == "running" and record["entries"][0]["samples"] == 30


def test_the_summary_is_plain_json_with_exact_integers(tmp_path: Path):
    path = tmp_path / "run.h5"
    with begin(path, seed=5400616385192348103) as w:
        entry(w, "e0")
    with h5py.File(path, "r") as f:
        text = f["run/summary"][()].decode()
    assert '"seed":5400616385192348103' in text
    assert json.loads(text)["entries"][0]["step"] == STEP


def test_ctrl_c_while_the_summary_is_written_closes_the_file_without_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    path = tmp_path / "run.h5"
    w = begin(path)
    entry(w, "e0")
    w.finish("complete")

    def interrupted(_path: object, f: h5py.File) -> None:
        f["run"].create_dataset("summary", data="{half")
        raise KeyboardInterrupt

    monkeypatch.setattr(writer_module, "write_summary", interrupted)
    with pytest.raises(KeyboardInterrupt):
        w.close()
    assert not has_summary(path)
    assert read_run(path).status == "complete"  # closed, and every seal matches
