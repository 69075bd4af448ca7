"""Crash safety, for real: SIGKILL a process writing a run file, then read the file back.

The writer (a fork of the test's process) says ``flushed K ENTRY N`` after every ``append``
(which flushes before it returns). After the kill, every block reported flushed must be in the
file, intact, and the run must read as incomplete (status ``running``).
"""

from __future__ import annotations

import os
import random
import signal
from pathlib import Path

import numpy as np
import pytest

from labrig.store import RunWriter, read_run

from helpers import fork_saying, pipe_lines, reaped

N_ENTRIES, N_BLOCKS, BLOCK = 3, 300, 200


def _write(path: Path, said: int) -> None:
    """The writer: ``flushed K ENTRY N`` on the pipe ``said`` after every block appended."""
    w = RunWriter(
        str(path),
        "name: crash\n",
        "",
        {"daq": {"identity": {"model": "sim"}}},
        seed=7,
        planned_entries=[f"entry{i}" for i in range(N_ENTRIES)],
    )
    k = 0
    for i in range(N_ENTRIES):
        e = w.begin_entry(
            f"entry{i}", {"i": i}, 1000.0, ["command_voltage", "strain", "temperature"]
        )
        for b in range(N_BLOCKS):
            g = np.arange(b * BLOCK, (b + 1) * BLOCK, dtype=float)
            e.append({"command_voltage": g, "strain": g + i * 1e6, "temperature": -g})
            k += 1
            os.write(said, f"flushed {k} {i} {e.n_samples}\n".encode())
        e.finish("complete")
    w.finish("complete")
    os.write(said, b"done\n")


def _kill_and_check(path: Path, target: int) -> None:
    """The writer runs in a fork of this process (labrig already loaded; a SIGKILL ends it
    as it would any process)."""
    pid, read_fd = fork_saying(lambda said: _write(path, said))
    reported: dict[int, int] = {}  # entry -> samples reported flushed
    killed = False
    try:
        for line in pipe_lines(read_fd, 60):
            if line.startswith("flushed"):
                _, k, i, n = line.split()
                reported[int(i)] = int(n)
                if int(k) >= target and not killed:
                    os.kill(pid, signal.SIGKILL)  # while it goes on writing
                    killed = True
            # lines written between our read and the kill were reported flushed too: read on
            # to the end of the pipe
    finally:
        os.close(read_fd)
        status = reaped(pid)
    assert killed and os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status

    run = read_run(path)
    assert run.status == "running" and run.incomplete
    assert run.seed == 7
    for i, n in reported.items():
        e = run[f"entry{i}"]
        assert e.n_samples >= n, f"entry{i}: {e.n_samples} samples, {n} reported flushed"
        g = np.arange(e.n_samples, dtype=float)
        np.testing.assert_array_equal(e["command_voltage"], g)
        np.testing.assert_array_equal(e["strain"], g + i * 1e6)
        np.testing.assert_array_equal(e["temperature"], -g)
        np.testing.assert_allclose(e.time, g / 1000.0)
    last = max(reported)
    assert run[f"entry{last}"].status in ("running", "complete")


@pytest.mark.parametrize("target", [1, 150, N_BLOCKS + 1, 2 * N_BLOCKS - 3])
def test_sigkill_keeps_every_flushed_block(tmp_path, target):
    _kill_and_check(tmp_path / "run.h5", target)


@pytest.mark.slow
def test_sigkill_many_times(tmp_path):
    rng = random.Random(1234)
    for trial in range(40):
        _kill_and_check(tmp_path / f"run{trial}.h5", rng.randint(1, N_ENTRIES * N_BLOCKS - 1))
