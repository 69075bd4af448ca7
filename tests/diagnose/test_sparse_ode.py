"""The empirical step's sparse-ODE candidate (``labrig/analysis/diagnose/sparse_ode.py``): a
Duhem-type ODE identified by STLSQ, scored on the same held-out folds, judged by the same
acceptance rule, and adopted as an EMPIRICAL alternative base when it passes.

The rule tested: no record is called "unexplained" where a sparse ODE predicts the held-out data
at least 2x better than the base. Fast tests: the decision on a synthetic trial (2x better:
adopted; just under the 15 % rule: refused, and the verdict says why; just over: accepted).
``@pytest.mark.slow``: the real SmartHysteresis record decimated to 100 Hz (the base fitted, the
ODE cross-validated, about 6 s of CPU) and the whole kept record (2 periods at 1 kHz) through
``diagnose``.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from labrig.analysis.diagnose import diagnose, split_entries
from labrig.analysis.diagnose.acceptance import MIN_GAIN, Candidate, accept
from labrig.analysis.diagnose.evidence import collect_evidence
from labrig.analysis.diagnose.procedure import Diagnosis, fit_base
from labrig.analysis.diagnose.sparse_ode import (
    NAME,
    SparseOdeEffect,
    SparseOdeTrial,
    adopt,
    equation_text,
    sparse_ode_trial,
)
from labrig.analysis.diagnose.state import Settings
from labrig.analysis.extended import FitOutcome
from labrig.analysis.records import Record
from labrig.analysis.sindy import LIBRARY, SindyBaseline

SMART = (
    Path(__file__).resolve().parents[1]
    / "data"
    / "real"
    / "chandratue-SmartHysteresis"
    / "hysteresis_v_150_1hz_2cycles_1khz.csv"
)


def smart_records(step: int) -> list[Record]:
    """The kept record (every ``step``-th row), cut into 4 chained parts as diagnose cuts a
    single entry; displacement kept raw (um), as ``labrig import --strain-units raw`` reads it."""
    rows = np.loadtxt(SMART, delimiter=",", usecols=(1, 2, 3))[::step]
    rec = Record.from_arrays("smart", 1000.0 / step, rows[:, 2], rows[:, 1], hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def _xi(**terms: float) -> tuple[float, ...]:
    names = [t.name for t in LIBRARY]
    xi = [0.0] * len(names)
    for k, v in terms.items():
        xi[names.index(k.replace("_abs", "|V'|").replace("d", "V'"))] = v
    return tuple(xi)


# -- the decision, on a synthetic trial ---------------------------------------------------------


RECS = smart_records(20)
EV = collect_evidence(RECS, {r.name: r.strain_ue + 0.1 for r in RECS})
#: what adopt() reads of the setup and the settings
SETUP = SimpleNamespace(records=tuple(RECS))
SETTINGS = SimpleNamespace(warmup_s=0.0)


def _unexplained(held: float) -> Diagnosis:
    per = {r.name: held for r in RECS}
    scores = {"nrmse_pct": held, "heldout_nrmse_pct": held, "per_entry": per}
    return Diagnosis(
        before=dict(scores),
        after=dict(scores),
        effects_added=[],
        candidates=[],
        verdict="Unexplained: the base model's residual is 6 times the noise floor.",
        classification="unexplained",
        evidence_before=EV,
        evidence_after=EV,
        headline="Unexplained: nothing added.",
    )


def _trial(base: dict[str, float], ode: dict[str, float]) -> SparseOdeTrial:
    model = SindyBaseline(_xi(S=-0.256, V=0.0824, d=0.13, **{"|V'| S": 0.0012}), 1000.0, 0.01)
    fo = FitOutcome({}, {NAME: {}}, {}, {}, dict(ode), float("nan"))
    a = accept(SparseOdeEffect(model), fo, ode, base, MIN_GAIN)
    c = Candidate(NAME, 1, 0.0, tried=True)
    c.heldout_per_entry, c.heldout_nrmse_pct = ode, float(np.mean(list(ode.values())))
    c.judged(a)
    c.evidence = f"a sparse ODE, {equation_text(model)}"
    preds = {r.name: r.strain_ue.copy() for r in RECS}
    return SparseOdeTrial(model, dict(ode), dict(ode), preds, a, c)


def test_an_ode_twice_better_than_the_base_is_adopted_and_named_empirical():
    """Held-out 0.9 % -> 0.45 % in every fold: the rule accepts it, the class is no longer
    "unexplained", the verdict states the terms with their coefficients and says EMPIRICAL."""
    base = {r.name: 0.9 for r in RECS}
    d = adopt(_unexplained(0.9), _trial(base, {k: 0.45 for k in base}), SETUP, SETTINGS, EV)
    assert d.classification != "unexplained"
    assert d.effects_added[-1]["effect"] == NAME
    assert d.after["heldout_nrmse_pct"] == pytest.approx(0.45)
    for needle in ("EMPIRICAL", "-0.256 S", "+0.0824 V", "+0.13 V'", "+0.0012 |V'| S"):
        assert needle in d.verdict, needle
    assert NAME in d.headline and "Unexplained" not in d.headline


def test_an_ode_gaining_just_under_the_rule_is_refused_and_the_verdict_says_why():
    """Just outside the 15 % rule (14 % better in every fold): refused, the class stays, the
    verdict says why; just inside (16 %) it passes (same rule as every candidate)."""
    base = {r.name: 1.0 for r in RECS}
    out = _trial(base, {k: 0.86 for k in base})
    assert not out.acceptance.accepted
    d = adopt(_unexplained(1.0), out, SETUP, SETTINGS, EV)
    assert d.classification == "unexplained"
    assert "refused" in d.verdict and "below the 15 % minimum" in d.verdict
    assert d.effects_added == [] and d.candidates[-1]["effect"] == NAME
    assert _trial(base, {k: 0.84 for k in base}).acceptance.accepted


# -- the real record, short: base fitted, ODE cross-validated -----------------------------------


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_real_record_short_segment_the_ode_twice_better_is_refused_only_for_its_growth():
    """SmartHysteresis (bipolar +-150 V, 1 Hz), 2 periods at 100 Hz: the base's held-out NRMSE is
    more than twice the sparse ODE's, and the ODE passes the acceptance rule on its scores; it is
    refused because its free run grows under the record's own drive (its growth rate, positive,
    is the reason given), not for its score. Measured 2026-11-27: base 1.20 %, ODE 0.158 % (0.53 %
    before the working rate and the output-error refinement). About 5.6 s of CPU (the base fit
    1.1 s, the ODE's five identifications 4.5 s) and more under load: slow tier; the two tests
    above are its fast equivalents (the same decision on a synthetic trial) and
    test_sparse_ode_growth.py the growth rate's."""
    s = Settings(chain=True, offset=True, warmup_s=0.0, top_k=4, min_gain=MIN_GAIN)
    recs = smart_records(10)
    setup, base = fit_base(recs, s, ["offset_drift"], None, (), lambda _m: None, [])
    trial = sparse_ode_trial(setup, s, base, 0, lambda _m: None)
    assert base.heldout_pct is not None
    assert trial.heldout_pct <= 0.5 * base.heldout_pct, (trial.heldout_pct, base.heldout_pct)
    assert trial.acceptance.accepted, trial.candidate.evidence  # the rule on its scores
    assert not trial.candidate.accepted and "grows under" in trial.candidate.evidence
    kept = [t.name for x, t in zip(trial.model.coefficients, LIBRARY, strict=True) if x != 0]
    assert {"V'", "S"} <= set(kept) and len(kept) <= 8, kept


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_real_record_whole_kept_segment_is_not_called_unexplained():
    """The whole kept record (2 periods at 1 kHz) through diagnose: the sparse ODE predicts the
    held-out parts at less than half the base's error (0.199 %, under the 0.216 % a six-term ODE
    reached on the whole file) but grows under the record's own drive, so it is refused and the
    verdict says why, with its equation; the record is not called "unexplained" (a named effect
    explains part of it). Measured 2026-11-27: base 1.53 %, sensor_lowpass 0.70 %, sparse ODE
    0.199 % refused (growth +0.53 /s; floor 0.151 %), 25-29 s of CPU."""
    d = diagnose(smart_records(1), offset=True)
    ode = next(c for c in d.candidates if c["effect"] == NAME)
    assert ode["heldout_nrmse_pct"] <= 0.5 * d.before["heldout_nrmse_pct"]
    assert ode["heldout_nrmse_pct"] <= 0.216, ode["evidence"]
    assert d.classification != "unexplained", d.verdict
    assert all(e["effect"] != NAME for e in d.effects_added)
    assert "grows under" in d.verdict and "dS/dt =" in d.verdict
