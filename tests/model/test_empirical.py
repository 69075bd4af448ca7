"""EmpiricalTerms: an output effect made of selected terms, inside labrig's extended-model engine.

The end-to-end test plants a cubic term ``c (V / V_ref)^3`` in the measured strain of a small
synthetic campaign on the virtual bench (the paper's model with 2 ue gauge noise), fits the base
model, selects terms from its residual, refits the model with the selected terms and scores it
with diagnose's held-out acceptance rule. The reference is the planted ``c``; the tolerance
(5 %) is about 8 standard errors of the fitted coefficient on this campaign (measured: 0.35 ue
on 60 ue with the engine's Jacobian linearising the effect, 2.5 ue without).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from labrig.analysis.diagnose.acceptance import accept
from labrig.analysis.extended import ExtendedProblem
from labrig.analysis.fit import PARAM_NAMES, fit_model
from labrig.analysis.simulate import build_sequences
from labrig.analysis.terms import (
    TermScales,
    empirical_effect,
    regression_data,
    select_terms,
    term_library,
)
from labrig.model.effects.base import Context
from labrig.model.effects.empirical import EMPIRICAL_NOTE, EmpiricalTerms
from labrig.studies.campaign import bench_campaign

SCALES = TermScales(100.0, 2e4, 1000.0)
#: a small campaign: 100 and 50 V at 1 and 10 Hz, 1 s rests (6 s recorded)
ENTRIES = ((100.0, 1.0, 2.0), (100.0, 10.0, 1.0), (50.0, 1.0, 2.0), (50.0, 10.0, 1.0))


def context(n: int = 800) -> tuple[Context, np.ndarray]:
    t = np.arange(n) / 1000.0
    v = 50 * (1 - np.cos(2 * np.pi * 2 * t))
    s = 9.0 * v + 40 * np.sin(2 * np.pi * 2 * t)
    return Context(1000.0, v, {"e": slice(0, n)}), s


def test_apply_adds_each_term_at_its_full_scale() -> None:
    ctx, s = context()
    eff = empirical_effect(["V3", "S_absS", "absdVdt_S"], SCALES)
    p = {"c_V3": -50.0, "c_S_absS": 20.0, "c_absdVdt_S": 7.0}
    # a DAQ-held (zero-order hold) drive acts at t_n with the sample held since t_(n-1)
    v_act = np.r_[ctx.v[0], ctx.v[:-1]]
    dv = np.gradient(v_act) * ctx.rate_hz
    want = (
        s
        - 50.0 * (v_act / 100.0) ** 3
        + 20.0 * s * np.abs(s) / 1000.0**2
        + 7.0 * np.abs(dv) * s / (2e4 * 1000.0)
    )
    np.testing.assert_allclose(eff.apply(s, ctx, p), want, rtol=1e-12)
    np.testing.assert_array_equal(eff.apply(s, ctx, eff.null), s)  # null: the model itself


def test_tangent_is_the_derivative_of_apply() -> None:
    ctx, s = context()
    eff = empirical_effect(["V3", "S_absS", "V_S", "V2"], SCALES)
    p = {"c_V3": -50.0, "c_S_absS": 30.0, "c_V_S": -12.0, "c_V2": 8.0}
    dx = np.cos(np.arange(s.size) / 37.0)
    h = 1e-4
    fd = (eff.apply(s + h * dx, ctx, p) - eff.apply(s - h * dx, ctx, p)) / (2 * h)
    np.testing.assert_allclose(eff.tangent(s, dx, ctx, p), fd, rtol=1e-7, atol=1e-9)


def test_parameters_and_description() -> None:
    eff = empirical_effect(["V3", "V2", "absdVdt"], SCALES)
    assert eff.where == "output" and eff.name == "empirical_terms"
    for q in eff.params:
        assert (q.null, q.sign, q.lo, q.hi, q.unit) == (0.0, 0, -1000.0, 1000.0, "ue")
        assert q.init != 0.0  # the ranking probes the effect at its start
    text = eff.describe({"c_V3": -52.0, "c_V2": 3.0, "c_absdVdt": 1.0}, {"c_V3": 0.4})
    assert text.startswith(EMPIRICAL_NOTE) and "not a physical attribution" in text
    assert "V^3: -52 +- 0.4 ue at full scale (-5.2e-05 ue per V^3)" in text
    assert "cf. field_saturation" in text and "cf. quadratic_term" in text
    assert [c[2] for c in eff.correspondences()] == ["field_saturation", "quadratic_term"]
    assert eff.caveats({}, 1.0) and EMPIRICAL_NOTE in eff.caveats({}, 1.0)[0]
    with pytest.raises(ValueError, match="at least one"):
        EmpiricalTerms([], 1.0)
    lib = term_library(SCALES)
    with pytest.raises(ValueError, match="repeated"):
        EmpiricalTerms([lib["V3"], lib["V3"]], 1.0)


def jacobian_basis(prob: ExtendedProblem, z: np.ndarray, base: dict) -> np.ndarray:
    J = prob.jacobian(z, base)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    u, s, _ = np.linalg.svd(J / scale, full_matrices=False)
    return u[:, s > s[0] * 1e-8]


@pytest.fixture(scope="module")
def cubic_campaign():
    """The campaign with -60 ue of (V / 100 V)^3 planted, its base fit and engine problem."""
    records = bench_campaign(seed=3, entries=ENTRIES)
    for r in records:
        r.strain_ue = r.strain_ue - 60.0 * (r.voltage_V / 100.0) ** 3
    fr = fit_model(records, chain=True, heldout=False)
    seqs = build_sequences(records, True)
    prob = ExtendedProblem(records, [], chain=True, base_free=fr.free, sequences=seqs)
    fo = prob.fit({n: float(getattr(fr.params, n)) for n in PARAM_NAMES})
    return records, fr, seqs, prob, fo


def test_a_planted_cubic_term_is_found_refitted_and_accepted(cubic_campaign) -> None:
    records, fr, seqs, prob, fo = cubic_campaign
    scales = TermScales.from_records(records)
    terms = list(term_library(scales).values())
    data = regression_data(prob, fo.base, fo.effects, terms)
    # the rows are the engine's residual vector (weighted, model - measured)
    np.testing.assert_allclose(-data.weights * data.residual, prob.residual(fo.z, fo.base))
    sel = select_terms(
        data.residual, data.columns, terms, data.weights, jacobian_basis(prob, fo.z, fo.base)
    )
    assert sel.keys == ["V3"]
    assert sel.terms[0].sign == -1 and sel.terms[0].effect == "field_saturation"
    assert sel.terms[0].coefficient_ue == pytest.approx(-60.0, rel=0.05)
    assert {"V", "S"} <= set(sel.absorbed)  # the model's gain takes these

    eff = empirical_effect(sel.keys, scales)
    ext = ExtendedProblem(records, [eff], chain=True, base_free=fr.free, sequences=seqs)
    fit = ext.fit(fo.base, {eff.name: sel.start()})
    assert fit.effects[eff.name]["c_V3"] == pytest.approx(-60.0, rel=0.05)
    assert fit.nrmse_pct < 0.45 < fo.nrmse_pct  # the noise floor is about 0.35 %

    held_base = prob.heldout(fo)
    held = ext.heldout(fit)
    verdict = accept(eff, fit, held, held_base)
    assert verdict.accepted, verdict.reasons
    assert verdict.gain > 0.5  # held-out NRMSE more than halved
    assert any(EMPIRICAL_NOTE in s for s in verdict.suspicious)


def test_nothing_is_selected_without_a_planted_term() -> None:
    records = bench_campaign(seed=4, entries=ENTRIES)
    fr = fit_model(records, chain=True, heldout=False)
    prob = ExtendedProblem(records, [], chain=True, base_free=fr.free)
    fo = prob.fit({n: float(getattr(fr.params, n)) for n in PARAM_NAMES})
    terms = list(term_library(TermScales.from_records(records)).values())
    data = regression_data(prob, fo.base, fo.effects, terms)
    B = jacobian_basis(prob, fo.z, fo.base)
    sel = select_terms(data.residual, data.columns, terms, data.weights, B)
    assert sel.terms == []


def test_engine_jacobian_linearises_the_empirical_effect(cubic_campaign) -> None:
    records, fr, seqs, _, fo = cubic_campaign
    eff = empirical_effect(["V3", "S_absS"], TermScales.from_records(records))
    ext = ExtendedProblem(records, [eff], chain=True, base_free=fr.free, sequences=seqs)
    eff0 = {eff.name: {"c_V3": -60.0, "c_S_absS": 20.0}}
    z = ext.z_of(fo.base, eff0)
    J = ext.jacobian(z, fo.base)
    j = [n for _, n in ext.names].index("tau_d_s")
    h = 1e-5
    zp, zm = z.copy(), z.copy()
    zp[j] += h
    zm[j] -= h
    fd = (ext.residual(zp, fo.base) - ext.residual(zm, fo.base)) / (2 * h)
    assert np.linalg.norm(J[:, j] - fd) < 0.01 * np.linalg.norm(fd)


def test_terms_are_written_in_the_records_strain_unit() -> None:
    """An import that kept a sensor's numbers (``--strain-units raw``): the terms' scales take
    the records' unit, and the effect's parameters and sentences are in ``raw``, never ``ue``
    (a simulated run's records state ``ue``, records that state nothing are read as ``ue``)."""
    from labrig.analysis.records import Record

    t = np.arange(400) / 200.0
    rec = Record.from_arrays("r", 200.0, 3 * np.sin(2 * np.pi * t), 20 * np.sin(2 * np.pi * t))
    assert TermScales.from_records([rec]).strain_unit == "ue"
    rec.meta["units"] = {"time": "s", "command_voltage": "V", "strain": "raw"}
    scales = TermScales.from_records([rec])
    assert scales.strain_unit == "raw"
    lib = term_library(scales)
    assert (lib["S"].unit, lib["S_absS"].unit, lib["V_S"].unit) == ("raw", "raw^2", "V raw")
    eff = empirical_effect(["S_absS", "V"], scales)
    assert {p.unit for p in eff.params} == {"raw"}
    text = eff.describe({p.name: 0.5 for p in eff.params}, {})
    assert "0.5 raw at full scale" in text and "raw per raw^2" in text
    assert not re.search(r"\bue\b", text), text
