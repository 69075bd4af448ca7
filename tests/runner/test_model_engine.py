"""Which code the simulated rig's model runs in a ``labrig run``: the numpy code for a run up to
:data:`labrig.runner.execute.LONG_SIMULATION_S` of protocol time (numba is never imported),
numba's compiled kernels for a longer one (loaded before the rig opens). docs/instruments.md,
"Which code runs the truth"."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from helpers import TINY

CODE = """
import sys
from pathlib import Path
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
seconds = sum(st.duration_s + st.rest_after_s for st in plan.steps)
for n, threshold in enumerate((seconds, seconds - 1e-6)):  # at the threshold, then just over
    ex.LONG_SIMULATION_S = threshold
    outcome = ex.execute(plan, rig, out.with_name(f"run{n}.h5"), seed=5)
    assert outcome.exit_code == 0, outcome.reason
    print(seen[-1], "numba" in sys.modules)
"""


def test_a_run_over_the_threshold_runs_the_compiled_model_and_a_shorter_one_never_imports_numba(
    tmp_path: Path,
) -> None:
    proto = tmp_path / "tiny.yaml"
    proto.write_text(TINY)
    res = subprocess.run(
        [sys.executable, "-c", CODE, str(proto), str(tmp_path / "run.h5")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    at, over = (line.split() for line in res.stdout.splitlines())
    assert at == ["numpy", "False"]
    assert over == ["compiled", "True"]
