"""The one least-squares problem under every fit (labrig.analysis.engine and .forward).

- its exact Jacobian (forward sensitivities of the relaxors and the operator, differences of
  effects alone) against central differences of the residual itself, base alone and with an
  effect in each of the four places, on a chained run with rests and on a held start;
- the same residual whether a problem is built for the base fit or for the extended model;
- subsets (the folds of a leave-one-entry-out) share the parent's simulations: evaluating a fold
  where the parent was evaluated costs no new simulation;
- the cost stays the paper's ``sum_e (NRMSE_e / 100)^2``.
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.engine import LOOP_CURVATURE, LOOP_WIDTH, LoopScale, base_problem
from labrig.analysis.extended import ExtendedProblem
from labrig.analysis.metrics import nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import PARAM_NAMES, OperatorFamily, scored_sequences
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, QuasiStaticHysteresis
from labrig.model.effects import library

RATE = 1000.0


def _records(held: bool = False, seed: int = 2) -> list[Record]:
    """Three short unipolar sines (1, 10, 40 Hz) from the paper's model with noise, chained
    with 0.2 s rests; ``held``: a biased drive that starts at a held 20 V."""
    rng = np.random.default_rng(seed)
    model = DynamicHysteresisModel(PAPER_TABLE1)
    out = []
    for f, dur in ((1.0, 1.2), (10.0, 0.6), (40.0, 0.4)):
        t = np.arange(round(dur * RATE)) / RATE
        v = 40.0 * (1 - np.cos(2 * np.pi * f * t))
        if held:
            v = v + 20.0
        s = model.predict(v, RATE, rest_V=20.0 if held else 0.0) + rng.normal(0, 1.0, v.size)
        meta = {"frequency_hz": f, "rest_after_s": 0.2}
        if held:
            meta["rest_V"] = 20.0
        out.append(Record(f"sine_{f:g}Hz", RATE, t, v, s, {}, "zoh", meta))
    return out


START = {
    **PAPER_TABLE1.model_dump(),
    "alpha0_ue_per_V": 8.0,
    "gamma_ue_per_V": 9.0,
    "vc_V": 55.0,
    "lam_t": 0.2,
    "tau_t_s": 3e-4,
    "lam_d": 1.3,
    "tau_d_s": 2.5e-3,
}


def _check_columns(prob, z, base0, tol=1e-5, h=1e-4):
    J = prob.jacobian(z, base0)
    assert J.shape == (prob.n_scored, z.size)
    for j, (who, name) in enumerate(prob.coords.names):
        hj = (
            h * max(1.0, abs(z[j]))
            if who == "base"
            else max(h * (prob.coords.hi[j] - prob.coords.lo[j]), 1e-6)
        )
        zp, zm = z.copy(), z.copy()
        zp[j] += hj
        zm[j] -= hj
        col = (prob.residual(zp, base0) - prob.residual(zm, base0)) / (2 * hj)
        err = np.linalg.norm(J[:, j] - col)
        assert err <= tol * max(np.linalg.norm(col), 1e-12), (who, name, err / np.linalg.norm(col))


@pytest.mark.parametrize("held", [False, True])
def test_base_jacobian_against_differences(held: bool) -> None:
    recs = _records(held)
    prob = base_problem(
        scored_sequences(recs, [r.name for r in recs], 0.0, True), OperatorFamily(), offset=False
    )
    _check_columns(prob, prob.coords.z(START, strict=True), START)


@pytest.mark.parametrize(
    "effect", ["quadratic_term", "creep", "sensor_lowpass", "thermal_drift", "remanence"]
)
def test_extended_jacobian_against_differences(effect: str) -> None:
    """A voltage effect (quadratic_term), output effects (creep, sensor_lowpass, thermal_drift)
    and an operator effect (remanence), with an offset per entry and offset drift (nuisance)."""
    recs = _records()
    lib = library()
    eff = lib[effect]
    prob = ExtendedProblem(recs, [eff, lib["offset_drift"]], chain=True, offset=True)
    # the effect away from its null, inside its bounds
    p = {q.name: (q.init if q.init != q.null else 0.5 * (q.lo + q.hi)) for q in eff.params}
    if effect == "remanence":
        p = {"A_ue_per_V": 0.8, "beta_per_V": 0.05, "gamma_ratio": 0.3}
    z = prob.z_of(START, {effect: p})
    # effect parameters by differences of the effect alone: 1e-4 relative agreement
    _check_columns(prob, z, START, tol=1e-4)


def test_extended_without_effects_is_the_base_problem() -> None:
    """The two ways of building the base model's problem give the same residual (the offset as
    a nuisance basis or as the mean taken out)."""
    recs = _records()
    base = base_problem(
        scored_sequences(recs, [r.name for r in recs], 0.0, True), OperatorFamily(), offset=True
    )
    ext = ExtendedProblem(recs, [], chain=True, offset=True)
    r1, r2 = base.residual_at(START), ext.residual_at(START)
    np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-12 * np.max(np.abs(r1)))


def test_cost_is_the_sum_of_squared_nrmse() -> None:
    """0.5 r.r = 0.5 sum_e (NRMSE_e / 100)^2, the NRMSE computed by the metric on the
    engine's strain."""
    recs = _records()
    prob = base_problem(
        scored_sequences(recs, [r.name for r in recs], 0.0, False), OperatorFamily(), False
    )
    r = prob.residual_at(START)
    model = DynamicHysteresisModel(OperatorFamily().params(START))
    per = [nrmse_pct(x.strain_ue, model.predict(x.voltage_V, RATE)) for x in recs]
    assert 0.5 * float(r @ r) == pytest.approx(0.5 * sum((q / 100) ** 2 for q in per), rel=1e-9)


def test_folds_share_the_parents_simulations() -> None:
    recs = _records()
    prob = ExtendedProblem(recs, [], chain=True)
    z = prob.z_of(START, {})
    prob.jacobian(z, START)
    done = prob.evaluations
    fold = prob.fold([recs[0].name, recs[2].name])
    J = fold.jacobian(z, START)
    r = fold.residual(z, START)
    assert prob.evaluations == done  # no new simulation: the parent's is reused
    assert J.shape[0] == r.size == sum(recs[i].n for i in (0, 2))
    # and a new point is simulated once for residual and Jacobian together
    z2 = z + 1e-3
    fold.jacobian(z2, START)
    fold.residual(z2, START)
    assert prob.evaluations == done + 1


def test_every_base_parameter_has_a_column() -> None:
    recs = _records()
    prob = base_problem(
        scored_sequences(recs, [r.name for r in recs], 0.0, True), OperatorFamily(), False
    )
    J = prob.jacobian(prob.coords.z(START, strict=True), START)
    loop = [LOOP_WIDTH if n == "gamma_ue_per_V" else LOOP_CURVATURE if n == "vc_V" else n
            for n in PARAM_NAMES]  # fmt: skip
    assert [n for _, n in prob.coords.names] == loop
    assert prob.coords.base_free == PARAM_NAMES
    assert np.all(np.linalg.norm(J, axis=0) > 0)


def _opening_by_simulation(op, span: float) -> float:
    """The opening at mid-stroke of a unipolar loop 0 V -> ``span`` -> 0 V, by running the
    operator over two cycles of a triangle (no closed form used): the falling branch minus the
    rising branch, both at ``span / 2`` (a sample of each branch)."""
    n = 4001  # odd: mid-stroke is a sample
    up = np.linspace(0.0, span, n)
    u = np.concatenate([up, up[::-1], up, up[::-1]])
    s = op.apply(u)
    rising = s[2 * n : 3 * n][n // 2]
    falling = s[3 * n :][n // 2]
    return float(falling - rising)


@pytest.mark.parametrize("shape", ["exponential", "gaussian"])
@pytest.mark.parametrize("vc", [5.0, 65.0, 5000.0])
def test_loop_width_is_the_operators_opening(shape: str, vc: float) -> None:
    """The width coordinate is the opening of a full-stroke loop at mid-stroke, checked by
    running the operator itself; (W, q) -> (gamma, vc) round-trips; its Jacobian matches
    differences."""
    span = 100.0
    scale = LoopScale(span, shape)
    gamma = 7.8
    w, q = scale.to_loop(gamma, vc)
    op = QuasiStaticHysteresis(8.9, gamma, vc, shape)
    assert w == pytest.approx(_opening_by_simulation(op, span), rel=1e-6)
    assert q == pytest.approx(span / vc)
    g2, v2 = scale.to_native(w, q)
    assert g2 == pytest.approx(gamma, rel=1e-12) and v2 == pytest.approx(vc, rel=1e-12)
    T = scale.jacobian(w, q)
    h = 1e-6
    for j, (dw, dq) in enumerate(((h * w, 0.0), (0.0, h))):
        plus = np.array(scale.to_native(w + dw, q * np.exp(dq)))
        minus = np.array(scale.to_native(w - dw, q * np.exp(-dq)))
        col = (plus - minus) / (2 * (dw if j == 0 else dq))
        np.testing.assert_allclose(T[:, j], col, rtol=1e-5, atol=1e-12 * abs(col).max())


def test_a_narrow_loop_keeps_its_width() -> None:
    """vc 1000 times the stroke: gamma and vc alone are nearly one direction (only gamma / vc
    is seen), but the width coordinate is the loop's own opening and stays well determined."""
    scale = LoopScale(100.0, "exponential")
    gamma, vc = 7.8e3, 1e5
    w, q = scale.to_loop(gamma, vc)
    assert q == pytest.approx(1e-3)
    # the Rayleigh limit: opening = gamma / vc * A^2 with A half the stroke
    assert w == pytest.approx(gamma / vc * 50.0**2, rel=1e-3)


def test_relaxor_passes_are_reused_only_where_they_are_the_same() -> None:
    """The relaxor passes kept across evaluations (:func:`relaxed_input`'s ``memo``): a problem
    that reused passes from earlier evaluations (other starts, effect values, a residual
    before its Jacobian) gives bit for bit the residual and Jacobian of a problem that
    computed everything afresh, and runs fewer relaxor passes doing so; a pass is not reused
    for other relaxor parameters or another voltage."""
    import labrig.analysis.forward as fwd

    recs = _records()
    lib = library()
    effects = [lib["quadratic_term"], lib["offset_drift"]]
    shared = ExtendedProblem(recs, effects, chain=True, offset=True)
    eff = {"quadratic_term": {"c2": 0.02}}
    z = shared.z_of(START, eff)
    calls = {"n": 0}
    real_output = fwd.relaxor_output

    def counted(*a, **k):
        calls["n"] += 1
        return real_output(*a, **k)

    fwd.relaxor_output = counted
    try:
        # earlier evaluations: the same relaxors with other operator gains, other relaxors,
        # another voltage
        shared.residual(shared.z_of({**START, "alpha0_ue_per_V": 8.5}, eff), START)
        shared.residual(shared.z_of({**START, "tau_t_s": 4e-4}, eff), START)
        shared.jacobian(shared.z_of(START, {**eff, "quadratic_term": {"c2": 0.03}}), START)
        before = calls["n"]
        r1, J1 = shared.residual(z, START), shared.jacobian(z, START)
        reused = calls["n"] - before
        fresh = ExtendedProblem(recs, effects, chain=True, offset=True)
        before = calls["n"]
        r2, J2 = fresh.residual(z, START), fresh.jacobian(z, START)
        afresh = calls["n"] - before
    finally:
        fwd.relaxor_output = real_output
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(J1, J2)
    assert reused < afresh
    # other relaxor parameters or another voltage: other numbers, not a stale pass
    r3 = shared.residual(shared.z_of({**START, "tau_t_s": 4e-4}, eff), START)
    r4 = shared.residual(shared.z_of(START, {**eff, "quadratic_term": {"c2": 0.03}}), START)
    assert not np.array_equal(r3, r1) and not np.array_equal(r4, r1)
    fresh3 = ExtendedProblem(recs, effects, chain=True, offset=True)
    np.testing.assert_array_equal(
        r3, fresh3.residual(fresh3.z_of({**START, "tau_t_s": 4e-4}, eff), START)
    )
