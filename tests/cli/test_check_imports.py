"""``labrig check`` loads the drivers without importing scipy.signal (about 0.7 s of CPU): the
simulated bench imports it where it filters, and the protocol code where it makes a PRBS, so a
check of a protocol without PRBS entries never pays for it."""

from __future__ import annotations

import subprocess
import sys

from helpers import ROOT

CODE = """
import runpy, sys
sys.argv = ['labrig', 'check', sys.argv[1]]
try:
    runpy.run_module('labrig', run_name='__main__')
except SystemExit as end:
    assert end.code in (0, None), end.code
print('scipy.signal' in sys.modules)
"""


def scipy_signal_imported_by_check(protocol: str) -> bool:
    out = subprocess.run(
        [sys.executable, "-c", CODE, str(ROOT / "experiments" / protocol)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return out.stdout.split()[-1] == "True"


def test_a_sine_sweep_is_checked_without_scipy_signal() -> None:
    assert not scipy_signal_imported_by_check("sweep.yaml")


def test_a_prbs_protocol_imports_it_to_make_its_bits() -> None:
    # the same check sees the import when the protocol needs it (the test above can fail)
    assert scipy_signal_imported_by_check("wideband.yaml")
