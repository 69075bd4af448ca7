"""``labrig fit`` imports what the fit needs only: the effect library (and with it scipy.signal,
about 1.5 s of CPU to import) only when ``--effect`` names an effect. Whole-command CPU:
``benchmarks/bench_commands.py`` and ``benchmarks/bench_speed.py phases``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

CODE = """
import sys
from pathlib import Path
from labrig.commands.fit import fit_run_file
fit_run_file(Path(sys.argv[1]), heldout=False, effects=tuple(sys.argv[2:]))
print(' '.join(m for m in ('scipy.signal', 'labrig.model.effects.thermal_drift')
               if m in sys.modules))
"""


def loaded_after_fit(run: Path, *effects: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", CODE, str(run), *effects],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return set(out.stdout.split())


def test_fit_without_effects_does_not_import_the_effect_library(tiny_run: Path) -> None:
    assert loaded_after_fit(tiny_run) == set()


def test_fit_with_an_effect_imports_the_library(tiny_run: Path) -> None:
    # the same check sees the library when it is needed (the test above can fail)
    assert loaded_after_fit(tiny_run, "sensor_lowpass") == {
        "scipy.signal",
        "labrig.model.effects.thermal_drift",
    }
