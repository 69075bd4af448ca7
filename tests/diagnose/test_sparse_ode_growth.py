"""The sparse ODE's growth under its own drive (:func:`~labrig.analysis.diagnose.sparse_ode.
growth_rate`), checked against what it claims to be: the rate at which two free runs started a
little apart separate, measured by running the compiled free run twice."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from labrig.analysis.baseline_kernels import sindy_free_run
from labrig.analysis.diagnose.sparse_ode import growth_rate
from labrig.analysis.sindy import SindyBaseline
from labrig.studies.smart_standin import TRUTH_XI

RATE = 1000.0


def _drive(periods: int = 3) -> np.ndarray:
    t = np.arange(periods * int(RATE)) / RATE
    return 150.0 * np.sin(2 * np.pi * t)


def _separation_rate(xi: np.ndarray, v: np.ndarray) -> float:
    """log(|run2 - run1| at the end / their start gap) / duration: two free runs from strains
    1e-6 ue apart (the ODE is linear in S for these coefficients, so the gap is exactly the
    disturbance)."""
    vp = np.concatenate(([0.0], v))
    a = sindy_free_run(xi, vp, RATE, 0.0, np.inf)
    b = sindy_free_run(xi, vp, RATE, 1e-6, np.inf)
    if a is None or b is None:
        pytest.skip("numba not available")
    return float(np.log(abs(b[-1] - a[-1]) / 1e-6) / (v.size / RATE))


@pytest.mark.parametrize("scale", [1.0, 0.1])
def test_growth_rate_is_the_rate_two_free_runs_separate(scale: float) -> None:
    """The SmartHysteresis-like truth (|V'| S coefficient 0.0012 /V) grows under a 150 V 1 Hz
    drive (about +0.5 /s: mean |V'| is 600 V/s); with a tenth of that coefficient it decays.
    Both measured by two free runs, within 2 %."""
    xi = np.array(TRUTH_XI, dtype=float)
    k = [i for i, x in enumerate(xi) if x != 0][-1]  # the |V'| S term, last of the truth's
    xi[k] *= scale
    v = _drive()
    seq = SimpleNamespace(voltage_V=v, rest_V=0.0, rate_hz=RATE)
    items = [(seq, [SimpleNamespace(lo=0, hi=v.size)])]
    got = growth_rate(SindyBaseline(tuple(xi), RATE, 0.0), items)
    want = _separation_rate(xi, v)
    assert got == pytest.approx(want, rel=0.02, abs=1e-3)
    assert (got > 0) is (scale == 1.0)
