"""The structural candidates of the base model (``labrig diagnose --also NAME``): each is
accepted by the command, and each is recovered from a small simulated record where it is
planted (simulated with the library's own form on the paper's base model, 0.5 ue of noise).

Fast: the command reaches the diagnosis with each name (the diagnosis a recorder), and a fit of
base + effect from a perturbed base and the effect's start recovers the planted values (each
well under a second). Slow (``-m slow``): the whole diagnosis names the planted effect first
(3-10 s of CPU each).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

import labrig.analysis.diagnose as diagnosis
import labrig.analysis.load as load
from labrig.analysis.extended import ExtendedProblem
from labrig.analysis.records import Record
from labrig.cli import app
from labrig.model import PAPER_TABLE1
from labrig.model.effects import EFFECT_NAMES, library
from labrig.studies.campaign import bench_campaign

from helpers import planted_records

NEW = (
    "amplifier_bandwidth",
    "mechanical_resonance",
    "negative_field_asymmetry",
    "rate_hysteresis",
    "sensor_drift",
)
TRUTH = PAPER_TABLE1.model_dump()


def _drives(kind: str, fs: float) -> list[tuple[str, np.ndarray]]:
    """Named drives (V): ``sines`` (unipolar, 20-300 Hz, two amplitudes at 100 Hz),
    ``bipolar`` (+-100 V at 1, 3 and 10 Hz), ``edges`` (two PRBS at 10-90 V and a 50 Hz
    triangle)."""
    out = []
    if kind == "sines":
        for f, a, dur in ((20.0, 100.0, 0.25), (100.0, 100.0, 0.1), (100.0, 50.0, 0.1),
                          (300.0, 100.0, 0.05)):  # fmt: skip
            t = np.arange(round(dur * fs)) / fs
            out.append((f"sine_{f:g}Hz_{a:g}V", 0.5 * a * (1 - np.cos(2 * np.pi * f * t))))
    elif kind == "bipolar":
        for f, dur in ((1.0, 1.0), (10.0, 0.3), (3.0, 0.5)):
            t = np.arange(round(dur * fs)) / fs
            out.append((f"bipolar_{f:g}Hz", 100 * np.sin(2 * np.pi * f * t)))
    else:
        rng = np.random.default_rng(0)
        for i in range(2):
            n = round(0.2 * fs)
            bits = rng.integers(0, 2, n // 20)
            out.append((f"prbs_{i}", np.repeat(bits, 20)[:n] * 80.0 + 10.0))
        t = np.arange(round(0.1 * fs)) / fs
        out.append(
            ("triangle_50Hz", 50 * (1 + (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * 50 * t))))
        )
    return out


#: effect -> (planted parameters, drive, sampling rate)
CASES: dict[str, tuple[dict[str, float], str, float]] = {
    "amplifier_bandwidth": ({"tau_amp_s": 3e-4, "rise": 0.5}, "sines", 10_000.0),
    "mechanical_resonance": (
        {"tau_r_s": 1 / (2 * np.pi * 800.0), "zeta": 0.05, "internal": 0.6},
        "edges",
        10_000.0,
    ),
    "negative_field_asymmetry": ({"a": 0.2}, "bipolar", 2000.0),
    "rate_hysteresis": (
        {"A_ue_per_V": -1.0, "beta_per_V": 0.02, "tau_h_s": 2e-3},
        "sines",
        10_000.0,
    ),
    "sensor_drift": ({"c1_ue": 20.0, "c2_ue": -10.0, "c3_ue": 5.0}, "bipolar", 2000.0),
}


def planted(name: str, seed: int = 1) -> list[Record]:
    """A chained record (0.05 s rests) of the paper's model with ``name`` at its planted
    parameters (the library's form), 0.5 ue of noise."""
    p, kind, fs = CASES[name]
    rng = np.random.default_rng(seed)
    return planted_records(_drives(kind, fs), fs, name, p, rng, offset=True)


#: relative (or, for parameters planted at 0-ish scales, absolute) tolerance of the recovery
TOL = {
    "tau_amp_s": 0.02,
    "rise": 0.05,
    "internal": 0.05,
    "tau_r_s": 0.01,
    "zeta": 0.05,
    "a": 0.02,
    "A_ue_per_V": 0.1,
    "beta_per_V": 0.1,
    "tau_h_s": 0.1,
    "c1_ue": 0.05,
    "c2_ue": 0.05,
    "c3_ue": 0.1,
}


@pytest.mark.parametrize("name", NEW)
def test_a_planted_effect_is_recovered_by_the_fit(name):
    """Base + effect fitted from a base 3 % off in gain and 5 % in ``vc`` and the effect's own
    start: the planted values within :data:`TOL`, and the fit at least 25 % better in-sample
    than the base alone (the effect is not absorbed by the base)."""
    recs = planted(name)
    start = {**TRUTH, "alpha0_ue_per_V": 1.03 * TRUTH["alpha0_ue_per_V"],
             "vc_V": 0.95 * TRUTH["vc_V"]}  # fmt: skip
    eff = library()[name]
    with_effect = ExtendedProblem(recs, [eff], chain=True, offset=True).fit(start, sd=False)
    alone = ExtendedProblem(recs, [], chain=True, offset=True).fit(start, sd=False)
    want = CASES[name][0]
    got = with_effect.effects[name]
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=TOL[k]), (k, got)
    assert with_effect.nrmse_pct <= 0.75 * alone.nrmse_pct


#: known short of the planted values within the diagnosis' refit budget (60 evaluations,
#: ``MAX_NFEV``; with 120 both pass): docs/diagnose.md, "structural candidates". Strict: a change
#: that makes them pass fails here until the mark is removed.
SHORT_OF_BUDGET = pytest.mark.xfail(
    strict=True, reason="the refit's evaluation budget ends short of the planted values"
)


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=SHORT_OF_BUDGET)
        if n in ("negative_field_asymmetry", "sensor_drift")
        else n
        for n in NEW
    ],
)
def test_diagnose_names_a_planted_structural_effect(name):
    """The whole diagnosis, the effect asked for (``--also``): it is added first, its values
    within twice :data:`TOL`, the held-out NRMSE cut by at least 40 % (measured: 0.185 -> 0.097 %
    for rate_hysteresis, whose planted term the base half absorbs, 8 to 40 times for the
    others; 3-10 s of CPU each; negative_field_asymmetry leaves a little for the empirical
    terms)."""
    from labrig.analysis.diagnose import diagnose

    d = diagnose(planted(name), effects=(name,), max_effects=1, always=(name,))
    doc = d.to_json()
    assert doc["effects_added"] and doc["effects_added"][0]["effect"] == name, doc["verdict"]
    got = doc["effects_added"][0]["params"]
    for k, v in CASES[name][0].items():
        assert got[k] == pytest.approx(v, rel=2 * TOL[k]), (k, got)
    assert doc["after"]["heldout_nrmse_pct"] <= 0.6 * doc["before"]["heldout_nrmse_pct"]


@pytest.fixture
def recorded(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Any run file reads as a small bench campaign; the diagnosis' keyword arguments are
    recorded and it stops there (what reaches it is the point here)."""
    recs = bench_campaign([], seed=6)
    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: recs)
    calls: list[dict[str, Any]] = []

    class StopDiagnosisError(Exception):
        pass

    def fake(records, params=None, **kw):
        calls.append(kw)
        raise StopDiagnosisError

    monkeypatch.setattr(diagnosis, "diagnose", fake)
    return calls


@pytest.mark.parametrize("name", NEW)
def test_diagnose_also_accepts_each_structural_candidate(recorded, tmp_path: Path, name):
    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--also", name, "--json"])
    assert recorded, res.output  # the diagnosis was reached (then stopped by the recorder)
    (call,) = recorded
    assert call["effects"] == (*EFFECT_NAMES, name)
    assert name in call["always"]


def test_diagnose_also_refuses_a_name_that_is_not_a_candidate(recorded, tmp_path: Path):
    """The check above can fail: a misspelt name is a usage error naming the valid ones."""
    from labrig.cli.typer_app import EXIT_USAGE

    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--also", "resonance"])
    assert res.exit_code == EXIT_USAGE and not recorded
    assert "mechanical_resonance" in res.output
