"""``labrig fit`` imports what the fit needs only: the effect library only when ``--effect`` names
an effect, never scipy.signal with scipy.stats (about 1.5 s of CPU to import; the library's
filters do without it), and none of the peers' or the report's libraries (pysindy with
scikit-learn and pandas, matplotlib: about 2 s more) unless ``--model sindy`` asks for SINDy.
Whole-command CPU and the floor of a fresh process: ``benchmarks/bench_commands.py [--floor]``
and ``benchmarks/bench_speed.py phases``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from helpers import run_protocol

#: modules a fit of our model does not need (each costs 0.1-1 s of CPU to import)
WATCHED = (
    "scipy.signal",
    "scipy.stats",
    "labrig.model.effects.thermal_drift",
    "pysindy",
    "sklearn",
    "pandas",
    "matplotlib",
)

CODE = f"""
import sys
from pathlib import Path
from labrig.commands.fit import fit_run_file
fit_run_file(Path(sys.argv[1]), model=sys.argv[2], heldout=False, effects=tuple(sys.argv[3:]))
print(' '.join(m for m in {WATCHED!r} if m in sys.modules))
"""


def loaded_after_fit(run: Path, *effects: str, model: str = "dynamic") -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", CODE, str(run), model, *effects],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return set(out.stdout.split())


def test_fit_without_effects_does_not_import_the_effect_library(tiny_run: Path) -> None:
    # nor scipy.stats, the peers' libraries or matplotlib
    assert loaded_after_fit(tiny_run) == set()


#: one entry (what is imported does not depend on how much data the fit reads; a fit of the
#: low-pass effect to this entry takes about half the CPU of one to the three of TINY)
ONE_SINE = """\
name: one sine
rate_hz: 500
steps:
  - kind: sine
    amplitude_V: 100
    frequency_hz: 2
    cycles: 2
"""


def test_fit_with_an_effect_imports_the_library(tmp_path: Path) -> None:
    # the same check sees the library when it is needed (the test above can fail)
    run = run_protocol(ONE_SINE, tmp_path, seed=1)
    # the low-pass, a second-order filter, without scipy.signal
    assert loaded_after_fit(run, "sensor_lowpass") == {"labrig.model.effects.thermal_drift"}
