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

from helpers import SMART_CSV

SMART = SMART_CSV


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
def test_real_record_short_segment_a_contracting_ode_twice_better_is_adopted():
    """SmartHysteresis (bipolar +-150 V, 1 Hz), 2 periods at 100 Hz: the sparse ODE predicts the
    held-out parts at less than half the base's error, passes the acceptance rule and is
    adopted: it contracts under the record's own drive (its growth rate there is negative, and
    two free runs 1 ue apart are closer after 20 periods of the drive, the compiled kernel
    checking it, not the formula). Before the contracting stage the ODE found here grew (+0.5
    /s) and was refused for it. Measured 2026-11-27: base 1.20 %, ODE 0.221 % (the growing one
    0.158 %). About 6-8 s of CPU and more under load: slow tier; the fast equivalents are the
    synthetic trials above and tests/diagnose/test_sparse_ode_contraction.py."""
    from labrig.analysis.baseline_kernels import sindy_free_run
    from labrig.analysis.diagnose.sparse_ode import growth_rate
    from labrig.analysis.sindy import equilibrium

    s = Settings(chain=True, offset=True, warmup_s=0.0, top_k=4, min_gain=MIN_GAIN)
    recs = smart_records(10)
    setup, base = fit_base(recs, s, ["offset_drift"], None, (), lambda _m: None, [])
    trial = sparse_ode_trial(setup, s, base, 0, lambda _m: None)
    assert base.heldout_pct is not None
    assert trial.heldout_pct <= 0.5 * base.heldout_pct, (trial.heldout_pct, base.heldout_pct)
    assert trial.acceptance.accepted and trial.candidate.accepted, trial.candidate.evidence
    assert "grows under" not in trial.candidate.evidence
    assert "contracts under the records' own drive" in trial.candidate.evidence
    xi = np.asarray(trial.model.coefficients)
    v = 150.0 * np.sin(2 * np.pi * np.arange(2000) / 100.0)  # 20 periods at 100 Hz
    vp = np.concatenate(([0.0], v))
    s0 = equilibrium(xi, 0.0)
    a, b = sindy_free_run(xi, vp, 100.0, s0, np.inf), sindy_free_run(xi, vp, 100.0, s0 + 1, np.inf)
    if a is None or b is None:
        pytest.skip("numba not available")
    assert abs(b[-1] - a[-1]) < 1.0
    items = [
        (
            SimpleNamespace(voltage_V=v, rest_V=0.0, rate_hz=100.0),
            [SimpleNamespace(lo=0, hi=v.size)],
        )
    ]
    assert growth_rate(trial.model, items) < 0.0
    kept = [t.name for x, t in zip(trial.model.coefficients, LIBRARY, strict=True) if x != 0]
    assert {"V'", "S"} <= set(kept), kept


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_real_record_whole_kept_segment_is_explained_by_a_contracting_ode():
    """The whole kept record (2 periods at 1 kHz) through diagnose: the sparse ODE predicts the
    held-out parts at less than half the base's error and under the 0.216 % a six-term ODE
    reached on the whole file, does not grow under the record's own drive, and is adopted as the
    EMPIRICAL alternative base ("partially explained"). Measured 2026-11-27 (sixth round): base
    1.53 %, a named effect about 0.66-0.70 %, the sparse ODE 0.19-0.21 % adopted depending on
    how the record is read (benchmarks/RESULTS.md, "Sixth round"; floor 0.151 %). Its lag and
    ``|V'| S`` terms hold a disturbance back only while a sustained drive's mean |V'| stays below
    ``-xi_S / xi_{|V'|S}`` (680-700 V/s, a 150 V sine up to about 1.15 Hz), a negative ``S|S|``
    term further; the verdict gives that limit."""
    d = diagnose(smart_records(1), offset=True)
    ode = next(c for c in d.candidates if c["effect"] == NAME)
    assert ode["heldout_nrmse_pct"] <= 0.5 * d.before["heldout_nrmse_pct"]
    assert ode["heldout_nrmse_pct"] <= 0.216, ode["evidence"]
    assert d.classification == "partially_explained", d.verdict
    assert d.effects_added[-1]["effect"] == NAME, d.verdict
    assert "grows under" not in d.verdict and "EMPIRICAL alternative base" in d.verdict
    # its contraction holds for slow enough drives only, and the verdict says up to where: a
    # 150 V sine 10 % faster than that rate drives two free runs 1 ue apart apart (the compiled
    # kernel, 40 periods), 10 % slower brings them closer
    from labrig.analysis.baseline_kernels import sindy_free_run
    from labrig.analysis.diagnose.contraction import critical_rate
    from labrig.analysis.sindy import equilibrium

    params = d.effects_added[-1]["params"]
    names = [t.name for t in LIBRARY]
    xi = np.zeros(len(names))
    for term, x in zip(params["terms"], params["coefficients"], strict=True):
        xi[names.index(term)] = x
    crit = critical_rate(SindyBaseline(tuple(xi), 1000.0, 0.0))
    assert f"mean |V'| stays below {crit:.3g} V/s" in d.verdict, d.verdict
    # the limit is the lag's and the |V'| S term's: with the S|S| term (a saturation, <= 0, which
    # can only hold the run back further) left out, the runs part above it, not below
    lag_only = xi.copy()
    lag_only[names.index("S|S|")] = 0.0
    for model, k, closer in ((xi, 0.9, True), (lag_only, 0.9, True), (lag_only, 1.1, False)):
        f = k * crit / 600.0  # mean |V'| of a 150 V sine: 600 f V/s
        t = np.arange(round(40 / f * 1000.0)) / 1000.0
        vp = np.concatenate(([0.0], 150.0 * np.sin(2 * np.pi * f * t)))
        s0 = equilibrium(model, 0.0)
        a = sindy_free_run(model, vp, 1000.0, s0, np.inf)
        b = sindy_free_run(model, vp, 1000.0, s0 + 1.0, np.inf)
        if a is None or b is None:
            pytest.skip("numba not available")
        assert (abs(b[-1] - a[-1]) < 1.0) == closer, (k, abs(b[-1] - a[-1]))
    assert xi[names.index("S|S|")] <= 0.0
