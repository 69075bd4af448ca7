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
for effects in [(), tuple(sys.argv[2:])]:
    fit_run_file(Path(sys.argv[1]), heldout=False, effects=effects)
    print(' '.join(m for m in {WATCHED!r} if m in sys.modules) or '-')
"""


def loaded_after_fits(run: Path, *effects: str) -> list[set[str]]:
    """What a fresh process has imported after ``labrig fit`` of ``run`` without effects, and
    then (in the same process) after a fit with ``effects``."""
    out = subprocess.run(
        [sys.executable, "-c", CODE, str(run), *effects],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return [set(line.split()) - {"-"} for line in out.stdout.splitlines()]


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


def test_a_fit_imports_the_effect_library_only_with_an_effect(tmp_path: Path) -> None:
    """Without effects: neither the library nor scipy.stats, the peers' libraries or
    matplotlib; then, in the same process, a fit with the low-pass (a second-order filter)
    imports the library (the check can fail) and still not scipy.signal."""
    run = run_protocol(ONE_SINE, tmp_path, seed=1)
    plain, with_effect = loaded_after_fits(run, "sensor_lowpass")
    assert plain == set()
    assert with_effect == {"labrig.model.effects.thermal_drift"}
