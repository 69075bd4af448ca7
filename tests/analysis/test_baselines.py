"""Baselines: play operator against its analytic response, PI by NNLS, Bouc-Wen integration and
parameter recovery."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from labrig.analysis.baselines import (
    KINDS,
    BaselineResult,
    BoucWen,
    PrandtlIshlinskii,
    bouc_wen_response,
    fit_baseline,
    play_operator,
    play_operators,
)
from labrig.analysis.metrics import nrmse_pct
from labrig.analysis.records import Record
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel

from helpers import FIT_JSON_KEYS

RATE = 1000.0
JSON_KEYS = set(FIT_JSON_KEYS)


def unipolar(amp: float, f: float, duration_s: float) -> np.ndarray:
    t = np.arange(round(duration_s * RATE)) / RATE
    return amp / 2 * (1 - np.cos(2 * np.pi * f * t))


def records_from(fn, amps=(50.0, 100.0), freqs=(1.0, 5.0), noise=0.0, seed=0) -> list[Record]:
    rng = np.random.default_rng(seed)
    out = []
    for a in amps:
        for f in freqs:
            v = unipolar(a, f, 2.0)
            s = fn(v) + (rng.normal(0, noise, v.size) if noise else 0.0)
            out.append(Record.from_arrays(f"{a:g}V_{f:g}Hz", RATE, v, s, frequency_hz=f))
    return out


# -- play operator / Prandtl-Ishlinskii --------------------------------------------------------


def test_play_operator_on_a_triangle_wave() -> None:
    """Triangle 0 -> a -> -a -> a through a play of threshold r, closed form per leg."""
    a, r, m = 10.0, 3.0, 200
    up1 = np.linspace(0, a, m + 1)[1:]
    down = np.linspace(a, -a, 2 * m + 1)[1:]
    up2 = np.linspace(-a, a, 2 * m + 1)[1:]
    v = np.concatenate([up1, down, up2])
    y = play_operator(v, r)
    # initial loading from rest: y = max(v - r, 0)
    np.testing.assert_allclose(y[:m], np.maximum(up1 - r, 0.0), atol=1e-12)
    # falling from a: held at a - r until v = a - 2r, then v + r
    np.testing.assert_allclose(y[m : 3 * m], np.minimum(down + r, a - r), atol=1e-12)
    # rising from -a: held at -a + r until v = -a + 2r, then v - r
    np.testing.assert_allclose(y[3 * m :], np.maximum(up2 - r, -a + r), atol=1e-12)
    # threshold 0 is the identity; the operator never leaves the band |v - y| <= r
    np.testing.assert_allclose(play_operator(v, 0.0), v)
    Y = play_operators(v, [0.0, 1.0, 3.0, 7.0])
    assert np.all(np.abs(v[:, None] - Y) <= np.array([0.0, 1.0, 3.0, 7.0]) + 1e-12)
    np.testing.assert_allclose(Y[:, 2], y)


def test_play_operator_matches_the_sample_recursion() -> None:
    rng = np.random.default_rng(1)
    v = np.cumsum(rng.normal(0, 1, 500))
    v[50:60] = v[49]  # flat stretch
    for r in (0.5, 2.0, 10.0):
        y, prev = np.empty(v.size), 0.0
        for i, x in enumerate(v):
            prev = max(x - r, min(x + r, prev))
            y[i] = prev
        np.testing.assert_allclose(play_operator(v, r), y, atol=1e-12)


def test_pi_fits_pi_generated_data_exactly() -> None:
    r = tuple(100.0 * np.arange(16) / 16)
    w = np.zeros(16)
    w[[0, 2, 5, 9]] = [6.0, 2.5, 1.5, 0.8]
    truth = PrandtlIshlinskii(r, tuple(w))
    recs = records_from(truth.predict)
    res = fit_baseline(recs, "prandtl_ishlinskii")
    assert res.model.thresholds == pytest.approx(r)
    np.testing.assert_allclose(res.model.weights, w, atol=1e-9)
    assert res.nrmse_pct < 1e-9
    assert res.heldout_nrmse_pct < 1e-9


def test_pi_weights_non_negative_on_model_data() -> None:
    model = DynamicHysteresisModel(PAPER_TABLE1)
    recs = records_from(lambda v: model.predict(v, RATE), noise=2.0)
    res = fit_baseline(recs, "prandtl_ishlinskii")
    assert np.all(np.asarray(res.model.weights) >= 0)
    assert np.sum(res.model.weights) > 0
    # the rate-independent PI cannot follow the model's dynamics perfectly, but it is close
    assert 0.3 < res.nrmse_pct < 10.0
    assert res.heldout_nrmse_pct >= res.nrmse_pct
    for r in recs:
        assert res.per_entry[r.name] == pytest.approx(nrmse_pct(r.strain_ue, res.predict(r)))
    out = res.to_json()
    assert set(out) == JSON_KEYS and out["method"] == "prandtl_ishlinskii"
    assert isinstance(res, BaselineResult)


# -- Bouc-Wen ----------------------------------------------------------------------------------

BW = BoucWen(d=13.0, A=4.0, beta=0.03, gamma=0.01)


def test_bouc_wen_integration_converges() -> None:
    v = unipolar(100.0, 2.0, 1.5) * (1 + 0.3 * np.sin(np.arange(1500) / 100))  # minor loops
    exact = bouc_wen_response(v, BW.A, BW.beta, BW.gamma)
    errs = []
    for m in (1, 2, 4, 8):
        h = bouc_wen_response(v, BW.A, BW.beta, BW.gamma, substeps=m)
        errs.append(np.max(np.abs(h - exact)))
    scale = np.ptp(exact)
    assert errs[-1] < 1e-6 * scale  # RK4 converges to the closed form
    assert all(b < a for a, b in itertools.pairwise(errs))  # monotonically
    # halving the step changes little, for n = 1 and for n = 1.5 (no closed form)
    for n in (1.0, 1.5):
        h4 = bouc_wen_response(v, BW.A, BW.beta, BW.gamma, n=n, substeps=4)
        h8 = bouc_wen_response(v, BW.A, BW.beta, BW.gamma, n=n, substeps=8)
        assert np.max(np.abs(h8 - h4)) < 1e-5 * np.ptp(h8)
    # saturation: a long monotone run approaches A / (beta + gamma)
    h = bouc_wen_response(np.linspace(0, 400, 4001), BW.A, BW.beta, BW.gamma)
    assert h[-1] == pytest.approx(BW.A / (BW.beta + BW.gamma), rel=1e-6)


def test_bouc_wen_fit_recovers_its_parameters() -> None:
    recs = records_from(BW.predict, noise=1.0, seed=4)
    res = fit_baseline(recs, "bouc_wen")
    m = res.model
    amp = m.A
    assert m.d == pytest.approx(BW.d, rel=0.01)
    assert amp == pytest.approx(BW.A, rel=0.03)
    assert m.beta == pytest.approx(BW.beta, rel=0.05)
    assert m.gamma == pytest.approx(BW.gamma, rel=0.1)
    floor = np.mean([100 * 1.0 / np.ptp(r.strain_ue) for r in recs])
    assert res.nrmse_pct <= 1.05 * floor
    assert res.heldout_nrmse_pct <= 1.1 * floor
    out = res.to_json()
    assert set(out) == JSON_KEYS and set(out["params"]) >= {"d_ue_per_V", "beta_per_V"}


def test_unknown_kind_is_refused() -> None:
    assert KINDS == ("prandtl_ishlinskii", "bouc_wen", "sindy")
    with pytest.raises(ValueError, match="kind"):
        fit_baseline(records_from(BW.predict), "preisach")


def test_chained_run_for_both_baselines() -> None:
    """Entries of one run: the operators keep their state through the 0 V rests."""
    truth_pi = PrandtlIshlinskii(tuple(100.0 * np.arange(8) / 8), (5.0, 0, 2.0, 0, 1.0, 0, 0, 3.0))
    amps_freqs = [(100.0, 1.0), (40.0, 5.0), (70.0, 2.0)]
    for kind, truth in (("prandtl_ishlinskii", truth_pi), ("bouc_wen", BW)):
        volts = [unipolar(a, f, 1.0) for a, f in amps_freqs]
        rest = np.zeros(500)
        whole = truth.predict(np.concatenate([np.concatenate([v, rest]) for v in volts]))
        recs, pos = [], 0
        for (a, _f), v in zip(amps_freqs, volts, strict=True):
            s = whole[pos : pos + v.size]
            recs.append(Record.from_arrays(f"{a:g}V", RATE, v, s, rest_after_s=0.5))
            pos += v.size + rest.size
        chained = fit_baseline(recs, kind, chain=True)
        assert chained.chain and chained.nrmse_pct < 1e-6, kind
        np.testing.assert_allclose(chained.predictions["40V"], recs[1].strain_ue, atol=1e-6)
        # simulated from rest, the later entries miss their history
        alone = fit_baseline(recs, kind, heldout=False)
        assert alone.nrmse_pct > 100 * chained.nrmse_pct + 0.05, kind
