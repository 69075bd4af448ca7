"""Which code the simulated rig's model runs in a ``labrig run``: the numpy code for a run whose
numpy excess (:func:`labrig.runner.execute.numpy_excess_s`) stays within numba's start
(numba is never imported), numba's compiled kernels for a longer one (loaded before the rig
opens). docs/instruments.md, "Which code runs the truth"."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from labrig.runner import execute as ex

#: one short sine: the threshold is set from the run itself, so any length will do
ONE_SINE = """\
name: one sine
rate_hz: 500
steps:
  - {kind: sine, amplitude_V: 60, frequency_hz: 2, cycles: 1}
"""

CODE = """
import sys
from pathlib import Path
import h5py
import labrig.runner.execute as ex

seen = []
real_open = ex.open_rig

def recording_open(path, seed):
    rig = real_open(path, seed)
    seen.append(rig.sim.bench.engine)
    return rig

ex.open_rig = recording_open
proto, out = Path(sys.argv[1]), Path(sys.argv[2])
plan, rig = ex.preflight(proto, None)
excess = ex.numpy_excess_s(plan.steps)
for n, start in enumerate((excess, excess * (1 - 1e-9))):  # at the threshold, then just under
    ex.NUMBA_START_S = start
    outcome = ex.execute(plan, rig, out.with_name(f"run{n}.h5"), seed=5)
    assert outcome.exit_code == 0, outcome.reason
    with h5py.File(outcome.path, "r") as f:
        recorded = f["run/instrument/bench/model_engine"][()].decode()
    print(seen[-1], "numba" in sys.modules, recorded)
"""


def test_a_run_over_the_threshold_runs_the_compiled_model_and_a_shorter_one_never_imports_numba(
    tmp_path: Path,
) -> None:
    proto = tmp_path / "one.yaml"
    proto.write_text(ONE_SINE)
    res = subprocess.run(
        [sys.executable, "-c", CODE, str(proto), str(tmp_path / "run.h5")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    at, over = (line.split() for line in res.stdout.splitlines())
    assert at == ["numpy", "False", "numpy"]  # the last: what the run file records
    assert over == ["compiled", "True", "compiled"]


def step(seconds: float, rest_s: float, rate_hz: float) -> SimpleNamespace:
    return SimpleNamespace(duration_s=seconds, rest_after_s=rest_s, rate_hz=rate_hz)


def test_the_excess_counts_blocks_and_samples() -> None:
    # 100 s at 1 kHz with a 10 s rest: 1 100 blocks of 0.1 s and 110 000 samples
    want = 1100 * ex.NUMPY_BLOCK_S + 110_000 * ex.NUMPY_SAMPLE_S
    assert ex.numpy_excess_s([step(100.0, 10.0, 1000.0)]) == pytest.approx(want, rel=1e-12)
    # the same time at 100 kHz: the same blocks, 100 times the samples
    want = 1100 * ex.NUMPY_BLOCK_S + 11_000_000 * ex.NUMPY_SAMPLE_S
    assert ex.numpy_excess_s([step(100.0, 10.0, 1e5)]) == pytest.approx(want, rel=1e-12)


def test_a_short_sweep_runs_numpy_and_a_long_fast_record_repays_the_kernels() -> None:
    # experiments/sweep.yaml's 69 s at 1 kHz; ten minutes at 1 kHz; one minute at 100 kHz
    assert not ex.repays_kernels([step(42.0, 27.0, 1000.0)])
    assert ex.repays_kernels([step(600.0, 0.0, 1000.0)])
    assert ex.repays_kernels([step(60.0, 0.0, 1e5)])
