"""Identification of the dynamic hysteresis model (labrig.analysis.fit).

Synthetic campaigns are simulated with ``DynamicHysteresisModel(PAPER_TABLE1).predict`` (the
paper's unipolar sines, 1 kHz, ZOH drive) plus Gaussian noise of known RMS; the fit starts from a
perturbed guess, never the truth.

Noise level and record lengths are chosen so the pass criteria are about three standard
deviations or more of the estimator's spread: with the equal weighting of entries the fit uses,
``vc`` is the least determined parameter (1-sigma 0.46 % for the fast campaign at 1 ue, 0.67 %
for the slow full campaign at 2 ue, from the Jacobian at the truth and confirmed by repeated noise
draws), against the 2 % criterion.

Entries recorded in one run are simulated with the truth's streaming evaluator, never reset, and
fitted with ``chain=True`` (the model's memory spans the 0 V rests between entries).
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.engine import base_problem
from labrig.analysis.fit import (
    PARAM_NAMES,
    FitResult,
    fit_model,
    predict_record,
)
from labrig.analysis.metrics import nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import OperatorFamily, scored_sequences
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, ModelParams

from helpers import FIT_JSON_KEYS

RATE = 1000.0
TRUTH = PAPER_TABLE1
START = TRUTH.model_copy(
    update={
        "alpha0_ue_per_V": 7.5,
        "gamma_ue_per_V": 9.5,
        "vc_V": 50.0,
        "lam_t": 0.25,
        "tau_t_s": 5e-5,
        "lam_d": 1.2,
        "tau_d_s": 3e-3,
    }
)
JSON_KEYS = set(FIT_JSON_KEYS)


def sine(amp: float, f: float, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    n = round(duration_s * RATE)
    t = np.arange(n) / RATE
    return t, amp / 2 * (1 - np.cos(2 * np.pi * f * t))  # unipolar, from 0 V


def campaign(
    params: ModelParams,
    freqs: tuple[float, ...],
    amps: tuple[float, ...],
    duration_s: dict[float, float],
    noise_ue: float,
    seed: int,
    envelope: bool = False,
) -> list[Record]:
    rng = np.random.default_rng(seed)
    model = DynamicHysteresisModel(params)
    out = []
    for a in amps:
        for f in freqs:
            t, v = sine(a, f, duration_s[f])
            s = model.predict(v, RATE, method="fast", hold="zoh") + rng.normal(0, noise_ue, v.size)
            meta = {"frequency_hz": f, "amplitude_V": a}
            out.append(Record(f"sine_{a:g}V_{f:g}Hz", RATE, t, v, s, {}, "zoh", meta))
    if envelope:  # 1 Hz carrier vanishing over 5 s, then 0 V held for 5 s
        t, v = sine(100.0, 1.0, 10.0)
        v = v * np.clip(1 - t / 5.0, 0, None)
        s = model.predict(v, RATE, method="fast", hold="zoh") + rng.normal(0, noise_ue, v.size)
        out.append(Record("envelope", RATE, t, v, s, {}, "zoh", {}))
    return out


def noise_floor_pct(records: list[Record], noise_ue: float) -> float:
    """Mean NRMSE of a perfect model: noise RMS over each entry's strain span."""
    return float(np.mean([100 * noise_ue / np.ptp(r.strain_ue) for r in records]))


def check_recovery(p: ModelParams, truth: ModelParams, static=0.02, order=0.03, tau=0.25):
    for k in ("alpha0_ue_per_V", "gamma_ue_per_V", "vc_V"):
        assert getattr(p, k) == pytest.approx(getattr(truth, k), rel=static), k
    for k in ("lam_t", "lam_d"):
        assert getattr(p, k) == pytest.approx(getattr(truth, k), abs=order), k
    for k in ("tau_t_s", "tau_d_s"):
        assert getattr(p, k) == pytest.approx(getattr(truth, k), rel=tau), k


# -- the reduced campaign (fast suite) ---------------------------------------------------------

FAST_NOISE = 1.0
FAST_FREQS = (1.0, 5.0, 20.0, 40.0)
FAST_DUR = dict.fromkeys(FAST_FREQS, 2.0)


@pytest.fixture(scope="module")
def reduced() -> list[Record]:
    return campaign(TRUTH, FAST_FREQS, (50.0, 100.0), FAST_DUR, FAST_NOISE, seed=11)


@pytest.fixture(scope="module")
def fitted(reduced: list[Record]) -> tuple[FitResult, list[tuple]]:
    calls: list[tuple] = []
    res = fit_model(reduced, initial=START, heldout=True, progress=lambda *a: calls.append(a))
    return res, calls


def test_global_fit_recovers_the_truth(fitted: tuple[FitResult, list], reduced) -> None:
    res, _ = fitted
    check_recovery(res.params, TRUTH)
    assert res.params.shape == "exponential"
    assert res.method == "global"
    assert res.entries == [r.name for r in reduced]


def test_nrmse_at_the_noise_floor(fitted: tuple[FitResult, list], reduced) -> None:
    res, _ = fitted
    floor = noise_floor_pct(reduced, FAST_NOISE)
    assert res.nrmse_pct <= 1.2 * floor
    assert res.nrmse_pct == pytest.approx(np.mean(list(res.per_entry.values())))
    # per entry, recomputed independently from the model and the metric
    for r in reduced:
        pred = DynamicHysteresisModel(res.params).predict(r.voltage_V, RATE, hold="zoh")
        assert res.per_entry[r.name] == pytest.approx(nrmse_pct(r.strain_ue, pred), rel=1e-9)
    # leave-one-entry-out: every entry scored by a model fitted without it
    assert set(res.heldout_per_entry) == set(res.per_entry)
    assert res.heldout_nrmse_pct == pytest.approx(np.mean(list(res.heldout_per_entry.values())))
    assert res.nrmse_pct <= res.heldout_nrmse_pct <= 1.3 * floor


def test_fit_is_converged(fitted: tuple[FitResult, list], reduced) -> None:
    """At an optimum: no lower than the truth's cost, and no gradient left."""
    res, _ = fitted
    camp = base_problem(
        scored_sequences(reduced, [r.name for r in reduced], 0.0, False), OperatorFamily(), False
    )
    r_truth = camp.residual_at(TRUTH.model_dump())
    assert res.cost <= 0.5 * float(r_truth @ r_truth)
    # the gradient relative to the cost scale: |J^T r| / (|J| |r|) per parameter
    J = res.jacobian
    r = camp.residual_at(res.params.model_dump())
    rel = np.abs(J.T @ r) / (np.linalg.norm(J, axis=0) * np.linalg.norm(r))
    assert np.max(rel) < 1e-5


def test_uncertainty_and_json(fitted: tuple[FitResult, list]) -> None:
    res, calls = fitted
    out = res.to_json()
    assert set(out) == JSON_KEYS
    assert set(out["params"]) == set(ModelParams.model_fields)
    assert ModelParams(**out["params"]) == res.params
    assert set(out["uncertainty"]) == set(PARAM_NAMES)
    for k in PARAM_NAMES:
        sd = out["uncertainty"][k]
        assert sd is not None and 0 < sd < 0.1 * abs(getattr(res.params, k))
        # the truth lies within a few standard deviations
        assert abs(getattr(res.params, k) - getattr(TRUTH, k)) < 5 * sd, k
    corr = out["correlation"]
    for a in PARAM_NAMES:
        assert corr[a][a] == pytest.approx(1.0)
        for b in PARAM_NAMES:
            assert corr[a][b] == pytest.approx(corr[b][a])
            assert -1 - 1e-9 <= corr[a][b] <= 1 + 1e-9
    assert out["method"] == "global" and out["heldout_nrmse_pct"] is not None
    import json

    json.dumps(out)  # plain JSON types only
    stages = {c[0] for c in calls}
    assert stages == {"fit", "heldout"}


def test_sensitivity_jacobian_matches_finite_differences() -> None:
    """The exact Jacobian (forward sensitivities) against central differences of the residual
    (steps 1e-4 in each coordinate; the difference quotient's own error is ~1e-8 relative)."""
    recs = campaign(TRUTH, (1.0, 40.0), (100.0,), {1.0: 1.0, 40.0: 0.5}, 0.5, seed=3)
    camp = base_problem(
        scored_sequences(recs, [r.name for r in recs], 0.0, False), OperatorFamily(), False
    )
    th = START.model_dump()
    z = camp.coords.z(th, strict=True)
    J = camp.jacobian(z, th)
    for j in range(len(PARAM_NAMES)):
        h = 1e-4
        zp, zm = z.copy(), z.copy()
        zp[j] += h
        zm[j] -= h
        col = (camp.residual(zp, th) - camp.residual(zm, th)) / (2 * h)
        assert np.linalg.norm(J[:, j] - col) <= 1e-5 * np.linalg.norm(col), PARAM_NAMES[j]


def test_staged_procedure(reduced: list[Record]) -> None:
    """The paper's section 3.1: sequential, close to the truth but not at the joint optimum."""
    res = fit_model(reduced, method="staged", heldout=False)
    assert res.method == "staged" and res.heldout_nrmse_pct is None
    check_recovery(res.params, TRUTH, static=0.1, order=0.05, tau=0.5)
    assert res.nrmse_pct < 2.0 * noise_floor_pct(reduced, FAST_NOISE)


#: a healthy simulated actuator of the 200-actuator fleet (``labrig sim fleet 200 --seed 1``,
#: A0030) whose fit, started by the staged procedure alone, stayed at lam_d = 1.0 exactly with
#: G_t at its upper bound (tau_t = 1000 s, alpha0 16.4 instead of 9.0; 0.93 % instead of 0.33 %)
NEAR_ONE = ModelParams(
    alpha0_ue_per_V=9.0075,
    gamma_ue_per_V=7.6440,
    vc_V=58.437,
    lam_t=0.15631,
    tau_t_s=1.5902e-4,
    lam_d=1.1593,
    tau_d_s=2.1541e-3,
)


@pytest.mark.parametrize("lam_d", [1.04, 1.1593])
def test_a_lam_d_just_above_one_is_found_from_the_staged_start(lam_d: float) -> None:
    """No ``initial``: the staged procedure is the only start. Its stage 3 must not start
    ``lam_d`` at 1 exactly (a single pole, a realisation the orders beside it do not approach,
    where the fit stayed: with a start at 1 this campaign's alpha0 comes out 11.5, not 9.0);
    the global fit then recovers the truth and reaches the floor."""
    from labrig.analysis.staged import STAGE3_LAM_STARTS

    assert 1.0 not in STAGE3_LAM_STARTS
    truth = NEAR_ONE.model_copy(update={"lam_d": lam_d})
    recs = campaign(truth, FAST_FREQS, (50.0, 100.0), FAST_DUR, FAST_NOISE, seed=3)
    res = fit_model(recs, heldout=False)
    check_recovery(res.params, truth)
    assert res.nrmse_pct <= 1.1 * noise_floor_pct(recs, FAST_NOISE)


def test_warmup_and_offsets() -> None:
    """Corrupted starts are simulated but not scored; per-entry offsets are fitted."""
    recs = campaign(TRUTH, (1.0, 20.0, 40.0), (50.0, 100.0), dict.fromkeys((1.0, 20.0, 40.0), 1.5),
                    FAST_NOISE, seed=5)  # fmt: skip
    offsets = {}
    for k, r in enumerate(recs):
        offsets[r.name] = 25.0 * (k - 2)
        bad = np.where(r.time_s < 0.3, 300.0 * np.exp(-r.time_s / 0.05), 0.0)  # settling junk
        r.strain_ue = r.strain_ue + bad + offsets[r.name]
    res = fit_model(recs, initial=START, heldout=False, warmup_s=0.4, offset=True)
    check_recovery(res.params, TRUTH, static=0.03, order=0.03, tau=0.25)
    for r in recs:
        assert res.offsets_ue[r.name] == pytest.approx(offsets[r.name], abs=1.0)
        i0 = 400
        pred = res.predict(r)
        assert res.per_entry[r.name] == pytest.approx(nrmse_pct(r.strain_ue[i0:], pred[i0:]))
    floor = float(np.mean([100 * FAST_NOISE / np.ptp(r.strain_ue[400:]) for r in recs]))
    assert res.nrmse_pct <= 1.2 * floor


def test_predict_record_is_the_model(reduced: list[Record]) -> None:
    r = reduced[0]
    lin = Record(r.name, RATE, r.time_s, r.voltage_V, r.strain_ue, {}, "linear", {})
    for rec in (r, lin):
        want = DynamicHysteresisModel(START).predict(rec.voltage_V, RATE, hold=rec.hold)
        np.testing.assert_array_equal(predict_record(START, rec), want)


def test_bad_input_is_refused(reduced: list[Record]) -> None:
    with pytest.raises(ValueError, match="method"):
        fit_model(reduced, method="magic")
    with pytest.raises(ValueError, match="unique"):
        fit_model([reduced[0], reduced[0]])
    flat = reduced[0].with_strain(np.zeros(reduced[0].n))
    with pytest.raises(ValueError, match="constant"):
        fit_model([flat], heldout=False)
    with pytest.raises(ValueError):
        fit_model([])


# -- the paper's full campaign (slow) -----------------------------------------------------------


@pytest.mark.slow
def test_full_campaign_recovery_and_time() -> None:
    """11 independent entries at 1 kHz (50 and 100 V at 1-40 Hz, plus a vanishing envelope)."""
    freqs = (1.0, 5.0, 10.0, 20.0, 40.0)
    dur = {1.0: 10.0, 5.0: 2.0, 10.0: 2.0, 20.0: 2.0, 40.0: 2.0}
    recs = campaign(TRUTH, freqs, (50.0, 100.0), dur, 2.0, seed=2024, envelope=True)
    assert len(recs) == 11
    res = fit_model(recs, initial=START, heldout=True)
    check_recovery(res.params, TRUTH)
    floor = noise_floor_pct(recs, 2.0)
    assert res.nrmse_pct <= 1.2 * floor
    assert res.heldout_nrmse_pct <= 1.3 * floor


def paper_run(noise_ue: float, seed: int) -> list[Record]:
    """experiments/paper.yaml as one continuous run: sines of >= 5 cycles and >= 4 s at 50 then
    100 V, 1-40 Hz, each followed by 3 s at 0 V, then the 1 Hz carrier at 100 V decaying
    exponentially to 0 V from 0.5 s to 5.5 s and 10 s at 0 V (57.5 s recorded)."""
    stream = DynamicHysteresisModel(TRUTH).stream(RATE)
    rng = np.random.default_rng(seed)
    out = []

    def add(name: str, t: np.ndarray, v: np.ndarray, meta: dict) -> None:
        s = stream.process(v) + rng.normal(0, noise_ue, v.size)
        stream.process(np.zeros(int(3 * RATE)))
        out.append(Record(name, RATE, t, v, s, {}, "zoh", {**meta, "rest_after_s": 3.0}))

    for a in (50.0, 100.0):
        for f in (1.0, 5.0, 10.0, 20.0, 40.0):
            t, v = sine(a, f, max(5.0 / f, 4.0))
            add(f"sine_{a:g}V_{f:g}Hz", t, v, {"frequency_hz": f})
    t, v = sine(100.0, 1.0, 15.5)
    x = np.clip(t - 0.5, 0.0, 5.0)  # exponential envelope, tau = decay / 2, exactly 0 at the end
    add("envelope", t, v * np.expm1((5.0 - x) / 2.5) / np.expm1(2.0), {})
    return out


@pytest.mark.slow
def test_paper_campaign_as_one_run() -> None:
    """The simulated rig's campaign: one run, so the entries carry each other's memory."""
    recs = paper_run(2.0, seed=7)
    res = fit_model(recs, initial=START, heldout=True, chain=True)
    check_recovery(res.params, TRUTH)
    floor = noise_floor_pct(recs, 2.0)
    assert res.nrmse_pct <= 1.2 * floor
    assert res.heldout_nrmse_pct <= 1.3 * floor


# -- entries of one run (chain) ----------------------------------------------------------------


@pytest.fixture(scope="module")
def run_records() -> list[Record]:
    """One continuous run (the truth's streaming evaluator never reset), 1 s rests at 0 V."""
    steps = [(100.0, 1.0, 2.0), (50.0, 20.0, 1.0), (100.0, 40.0, 1.0), (50.0, 1.0, 2.0),
             (100.0, 5.0, 1.0)]  # fmt: skip
    stream = DynamicHysteresisModel(TRUTH).stream(RATE)
    rng = np.random.default_rng(8)
    out = []
    for a, f, d in steps:
        t, v = sine(a, f, d)
        s = stream.process(v) + rng.normal(0, FAST_NOISE, v.size)
        stream.process(np.zeros(int(RATE)))  # the rest, not recorded
        meta = {"frequency_hz": f, "rest_after_s": 1.0}
        out.append(Record(f"run_{a:g}V_{f:g}Hz", RATE, t, v, s, {}, "zoh", meta))
    return out


def test_entries_of_a_run_are_not_at_rest(run_records: list[Record]) -> None:
    """Why chain exists: the from-rest prediction of a later entry misses the run's history."""
    floor = noise_floor_pct(run_records, FAST_NOISE)
    later = [nrmse_pct(r.strain_ue, predict_record(TRUTH, r)) for r in run_records[1:]]
    assert np.mean(later) > 3 * floor


def test_chained_fit_of_a_run(run_records: list[Record]) -> None:
    scored = [r.name for r in run_records[1:]]  # the first entry only as history
    res = fit_model(run_records, initial=START, chain=True, scored=scored, heldout=True)
    assert res.entries == scored and res.chain
    check_recovery(res.params, TRUTH)
    floor = noise_floor_pct(run_records[1:], FAST_NOISE)
    assert res.nrmse_pct <= 1.2 * floor
    assert res.heldout_nrmse_pct <= 1.3 * floor
    # predictions cover each record and include the history (independent: the streaming model)
    stream = DynamicHysteresisModel(res.params).stream(RATE)
    for r in run_records:
        want = stream.process(r.voltage_V)
        stream.process(np.zeros(int(RATE)))
        if r.name in scored:
            np.testing.assert_allclose(res.predictions[r.name], want, atol=1e-9 * np.ptp(want))
    with pytest.raises(ValueError, match="scored"):
        fit_model(run_records, scored=["nope"])
