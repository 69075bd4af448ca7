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


def test_the_v_prime_s_term_adds_no_long_run_growth() -> None:
    """``V' S`` integrates to ``xi (V_end - V_start)``, bounded however long the drive: on a
    record of 1.25 periods (the voltage ends 150 V above where it started, so that term weighs
    0.004 x 150 / 1.25 s = 0.48 /s there) the growth rate is still the rate at which two free
    runs separate over 10 whole periods of the same drive, within 2 %."""
    names = ["1", "S", "V", "V'", "|V'|", "V' S", "V' V", "|V'| S", "|V'| V", "S|S|"]
    xi = np.zeros(len(names))
    for name, value in (("S", -0.6), ("V", 0.15), ("V'", 0.11), ("V' S", 0.004)):
        xi[names.index(name)] = value
    short = _drive(2)[: int(1.25 * RATE)]
    seq = SimpleNamespace(voltage_V=short, rest_V=0.0, rate_hz=RATE)
    items = [(seq, [SimpleNamespace(lo=0, hi=short.size)])]
    got = growth_rate(SindyBaseline(tuple(xi), RATE, 0.0), items)
    want = _separation_rate(xi, _drive(10))
    assert got == pytest.approx(want, rel=0.02)
    assert _separation_rate(xi, short) > want + 0.4  # the short record's own: the boundary term
