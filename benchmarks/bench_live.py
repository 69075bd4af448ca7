"""The live view's reading: CPU per frame, read in a child forked for each frame against one
long-lived reading process (:class:`labrig.store.isolated.IsolatedWorker`), the same frames.

The file: the paper campaign's shape (11 entries of 5 000 samples at 1 kHz, 5 channels), the
last entry still running (the file closed unfinished, so that this process may read it); each
frame reads the run's status and entries (the ten ended ones taken as known, as the view does)
and the current entry's last 100 samples, as a view that keeps up does at 12 frames a second.
CPU: this process's plus the reading child's (for the fork, the reaped children; for the
worker, its own counters from /proc, its start reported apart).
Run: ``python -m benchmarks.bench_live`` (``--frames N``).
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.yardstick import yardstick_s
from labrig.live.frames import read_frame_here
from labrig.store import RunWriter
from labrig.store.isolated import IsolatedWorker, call_isolated

ENTRIES, SAMPLES = 11, 5000


def paper_shaped_file(path: Path) -> Path:
    """A run file of :data:`ENTRIES` entries, the last one still running."""
    chans = ["command_voltage", "amplifier_voltage", "gauge_raw", "strain"]
    w = RunWriter(path, "name: p\n", "", {"daq": {"rate_hz": 1000}}, 1, protocol_name="p")
    v = 50 + 50 * np.sin(np.arange(SAMPLES) / 50.0)
    for k in range(ENTRIES):
        e = w.begin_entry(f"sine_{k}", {"kind": "sine", "n_samples": SAMPLES}, 1000.0, chans)
        for b in range(0, SAMPLES, 500):
            part = v[b : b + 500]
            e.append({"command_voltage": part, "amplifier_voltage": part,
                      "gauge_raw": part / 100, "strain": 9 * part})  # fmt: skip
        if k < ENTRIES - 1:
            e.finish("complete")
    w.close()  # closed unfinished: the last entry and the run read as running
    return path


def _cpu_self() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _cpu_of(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    n = ap.parse_args().frames
    with tempfile.TemporaryDirectory() as d:
        path = paper_shaped_file(Path(d) / "run.h5")
        whole = read_frame_here(str(path), None, 0, {})
        ended = {e.name: e for e in whole.entries[:-1]}
        args = (str(path), whole.current, SAMPLES - 100, {}, ended, whole.file_id)
        size = path.stat().st_size
        yard = yardstick_s()

        s0, c0 = _cpu_self(), _cpu_children()
        for _ in range(n):
            call_isolated(read_frame_here, *args, size_bytes=size, wall_s=2.0)
        fork_ms = 1e3 * (_cpu_self() - s0 + _cpu_children() - c0) / n

        worker = IsolatedWorker()
        t0 = time.perf_counter()
        worker.call(read_frame_here, *args, size_bytes=size, wall_s=2.0)
        start_wall = time.perf_counter() - t0
        pid = worker.pid
        assert pid is not None
        start_cpu = _cpu_of(pid)
        s0, w0 = _cpu_self(), _cpu_of(pid)
        for _ in range(n):
            worker.call(read_frame_here, *args, size_bytes=size, wall_s=2.0)
        worker_ms = 1e3 * (_cpu_self() - s0 + _cpu_of(pid) - w0) / n
        worker.close()
    load = os.getloadavg()[0]
    print(f"{n} frames, load {load:.2f}, yardstick {1e3 * yard:.1f} ms")
    print(f"fork per frame:   {fork_ms:6.1f} ms CPU per frame ({fork_ms / (1e3 * yard):.2f} x)")
    print(f"one worker:       {worker_ms:6.1f} ms CPU per frame ({worker_ms / (1e3 * yard):.2f} x)")
    print(f"worker's start:   {start_cpu:6.2f} s CPU (its own), {start_wall:.2f} s wall")
    print(f"ratio fork/worker {fork_ms / worker_ms:.1f}")


if __name__ == "__main__":
    main()
