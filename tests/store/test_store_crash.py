"""Crash safety, for real: SIGKILL a process writing a run file, then read the file back.

The writer prints ``flushed K ENTRY N`` after every ``append`` (which flushes before it
returns). After the kill, every block reported flushed must be in the file, intact, and the
run must read as incomplete (status ``running``).
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from labrig.store import read_run

ROOT = Path(__file__).resolve().parents[2]
N_ENTRIES, N_BLOCKS, BLOCK = 3, 300, 200

WRITER = f"""
import sys
import numpy as np
from labrig.store import RunWriter

w = RunWriter(sys.argv[1], "name: crash\\n", "", {{"daq": {{"identity": {{"model": "sim"}}}}}},
              seed=7, planned_entries=[f"entry{{i}}" for i in range({N_ENTRIES})])
k = 0
for i in range({N_ENTRIES}):
    e = w.begin_entry(f"entry{{i}}", {{"i": i}}, 1000.0,
                      ["command_voltage", "strain", "temperature"])
    for b in range({N_BLOCKS}):
        g = np.arange(b * {BLOCK}, (b + 1) * {BLOCK}, dtype=float)
        e.append({{"command_voltage": g, "strain": g + i * 1e6, "temperature": -g}})
        k += 1
        print(f"flushed {{k}} {{i}} {{e.n_samples}}", flush=True)
    e.finish("complete")
w.finish("complete")
print("done", flush=True)
"""


def _kill_and_check(path: Path, target: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    reported: dict[int, int] = {}  # entry -> samples reported flushed
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("flushed"):
                _, k, i, n = line.split()
                reported[int(i)] = int(n)
                if int(k) >= target:
                    proc.send_signal(signal.SIGKILL)  # while it goes on writing
                    break
        # lines printed between our read and the kill were reported flushed too
        for line in proc.stdout:
            if line.startswith("flushed"):
                _, k, i, n = line.split()
                reported[int(i)] = int(n)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read() if proc.stderr else ""

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
