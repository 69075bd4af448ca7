"""A sensor low-pass fitted to a resonance is refused (labrig.model.effects.sensor_lowpass,
:meth:`SensorLowpass.refusals` through the acceptance rule).

``sensor_lowpass``'s damping may end on its upper bound (5: the first-order limit) but not on
its lower one (0.2, a 2.55x peak at the cutoff): a fit that wants less damping is a mechanical
resonance in the low-pass's form, and its cutoff means nothing. Checked on constructed fit
outcomes at the bound and just inside it, and on fits: the low-pass alone fitted to a planted
resonance ends on the lower bound and is refused, fitted to a planted Butterworth low-pass it is
not. A cutoff known to no better than half its value is reported as poorly determined.
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.diagnose import MAX_NFEV, accept
from labrig.analysis.extended import ExtendedProblem, FitOutcome
from labrig.analysis.records import Record
from labrig.model import PAPER_TABLE1
from labrig.model.effects import library

from helpers import planted_records

LP = library()["sensor_lowpass"]
LO = LP.params[1].lo
TAU = 1 / (2 * np.pi * 250.0)


def outcome(zeta: float, tau_sd: float = 0.05 * TAU) -> FitOutcome:
    return FitOutcome(
        base={},
        effects={LP.name: {"tau_s": TAU, "zeta": zeta}},
        sd={LP.name: {"tau_s": tau_sd, "zeta": 0.01}},
        base_sd={},
        per_entry={},
        cost=0.0,
    )


def passing_folds() -> tuple[dict[str, float], dict[str, float]]:
    """Every fold 30 % better: the held-out part of the rule passes."""
    names = [f"e{k}" for k in range(5)]
    return dict.fromkeys(names, 0.7), dict.fromkeys(names, 1.0)


@pytest.mark.parametrize(
    ("zeta", "refused"),
    [
        (LO, True),
        (LO + 0.5 * LP.AT_LOWER_DAMPING, True),
        (LO + 2 * LP.AT_LOWER_DAMPING, False),
        (0.71, False),
        (LP.params[1].hi, False),
    ],
)
def test_a_damping_at_its_resonant_end_is_refused(zeta, refused):
    """At the lower bound (and within 1e-4 of it) refused, naming the resonance; 2e-4 inside,
    a Butterworth section and the first-order end (5) are accepted."""
    held, ref = passing_folds()
    a = accept(LP, outcome(zeta), held, ref)
    assert a.accepted is not refused
    assert any("resonant end" in r and "mechanical_resonance" in r for r in a.reasons) is refused


@pytest.mark.parametrize(("rel_sd", "flagged"), [(0.45, False), (0.55, True), (4.0, True)])
def test_a_cutoff_known_to_no_better_than_half_is_poorly_determined(rel_sd, flagged):
    """The cutoff's 1-sigma over half its value (here 4x: 54 +- 388 Hz-like) makes the low-pass
    doubtful (the verdict then says "partially explained"); 55 % too, 45 % does not."""
    held, ref = passing_folds()
    a = accept(LP, outcome(0.71, rel_sd * TAU), held, ref)
    assert a.accepted
    poorly = any(s.startswith("tau_s is poorly determined") for s in a.suspicious)
    assert poorly is flagged


FS = 2000.0
TRUTH = PAPER_TABLE1.model_dump()


def _records(name: str, p: dict[str, float]) -> list[Record]:
    """Three chained entries (a PRBS, a 25 Hz triangle, a 10 Hz sine; 0.05 s rests) of the
    paper's model with ``name`` at ``p`` (the library's form), 0.5 ue of noise."""
    rng = np.random.default_rng(4)
    bits = rng.integers(0, 2, 60)
    t = np.arange(600) / FS
    drives = {
        "prbs": np.repeat(bits, 10) * 80.0 + 10.0,
        "triangle": 50 * (1 + (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * 25 * t))),
        "sine": 50 * (1 - np.cos(2 * np.pi * 10 * t)),
    }
    return planted_records(list(drives.items()), FS, name, p, rng)


@pytest.mark.parametrize(
    ("planted", "p", "refused"),
    [
        ("mechanical_resonance", {"tau_r_s": TAU, "zeta": 0.05, "internal": 1.0}, True),
        ("sensor_lowpass", {"tau_s": TAU, "zeta": 0.71}, False),
    ],
)
def test_the_low_pass_fitted_to_a_resonance_ends_at_its_resonant_end(planted, p, refused):
    """The low-pass alone fitted (from its own start) to a 250 Hz, zeta 0.05 resonance ends on
    its lower damping bound and its refusal names it; fitted to a 250 Hz Butterworth low-pass
    it recovers the damping (within 0.05) and is not refused. The fit stops where a diagnosis'
    refits stop (``MAX_NFEV`` evaluations): the damping is on its bound well before (without
    the limit the same bound is reached after about 900 evaluations, 12 s of CPU)."""
    recs = _records(planted, p)
    fo = ExtendedProblem(recs, [LP], chain=True).fit(TRUTH, sd=False, max_nfev=MAX_NFEV)
    got = fo.effects[LP.name]
    assert bool(LP.refusals(got, {})) is refused, got
    if refused:
        assert got["zeta"] == pytest.approx(LO, abs=LP.AT_LOWER_DAMPING)
    else:
        assert got["zeta"] == pytest.approx(0.71, abs=0.05)


def test_an_over_damped_fit_is_described_by_its_real_poles():
    """Damping 3.23 and fc 59 Hz (the low-pass fitted to the real SmartHysteresis record): the
    section ``1 / (1 + 2 zeta tau s + (tau s)^2)`` is two first-order lags, whose corners are the
    roots of its denominator (numpy.roots, 1e-9): the slow one (9.4 Hz) is what the fit means,
    not the poorly determined fc; a Butterworth section (0.71) has no real poles."""
    tau, zeta = 1 / (2 * np.pi * 59.0), 3.23
    slow, fast = LP.real_corners_hz({"tau_s": tau, "zeta": zeta})
    roots = np.sort(np.abs(np.roots([tau * tau, 2 * zeta * tau, 1.0]))) / (2 * np.pi)
    np.testing.assert_allclose([slow, fast], roots, rtol=1e-9)
    assert 9.0 < slow < 9.5
    text = LP.describe({"tau_s": tau, "zeta": zeta}, {"tau_s": 8 * tau})
    assert "two real poles" in text and f"{slow:.3g}" in text
    assert LP.real_corners_hz({"tau_s": tau, "zeta": 0.71}) is None
    assert "real poles" not in LP.describe({"tau_s": tau, "zeta": 0.71}, {})
