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
    play_operators_numpy,
)
from labrig.analysis.metrics import nrmse_pct
from labrig.analysis.records import Record
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel

from helpers import BASELINE_JSON_KEYS

RATE = 1000.0
JSON_KEYS = set(BASELINE_JSON_KEYS)


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


# -- compiled kernels against their NumPy references -------------------------------------------


def edge_records() -> dict[str, tuple[np.ndarray, float]]:
    """Voltages (V) with the rest each starts from: minor loops with flat stretches, a held
    start (rest_V != 0), a ramp down through zero, one sample, no sample, all flat."""
    rng = np.random.default_rng(3)
    walk = np.cumsum(rng.normal(0, 2.0, 3000))
    walk[100:180] = walk[99]  # flat stretch inside a run
    walk[1000:1001] = walk[999]  # a single repeated sample
    loops = unipolar(100.0, 2.0, 1.5) * (1 + 0.3 * np.sin(np.arange(1500) / 100))
    return {
        "walk": (walk, 0.0),
        "loops_held": (30.0 + loops, 30.0),
        "ramp_through_zero": (np.linspace(40.0, -60.0, 500), 40.0),
        "one_sample": (np.array([12.0]), 0.0),
        "empty": (np.zeros(0), 0.0),
        "all_flat": (np.full(50, 7.0), 7.0),
        "flat_then_step": (np.concatenate([np.zeros(20), np.full(20, 5.0)]), 0.0),
    }


def test_compiled_play_operators_equal_the_run_by_run_form() -> None:
    """Each output is one of ``V - r``, ``V + r`` or the previous one: the sample recursion and
    the run-by-run closed form agree exactly."""
    r = np.array([0.0, 0.5, 3.0, 17.0, 400.0])
    for name, (v, rest) in edge_records().items():
        got = play_operators(v, r, rest)
        ref = play_operators_numpy(v, r, rest)
        assert got.shape == ref.shape == (v.size, r.size), name
        np.testing.assert_array_equal(got, ref, err_msg=name)
        if v.size:  # relaxed at the rest: the widest operator never leaves it
            assert np.all(got[:, -1] == rest), name
    with pytest.raises(ValueError, match="non-negative"):
        play_operators([1.0, 2.0], [-1.0])


@pytest.mark.parametrize(
    ("A", "beta", "gamma"),
    [(4.0, 0.03, 0.01), (4.0, 0.03, -0.02), (-2.0, 0.04, 0.03), (1.0, 1e-6, 5e-7)],
)
def test_compiled_bouc_wen_equals_the_closed_form(A: float, beta: float, gamma: float) -> None:
    """The compiled response against :func:`bouc_wen_exact` (the NumPy closed form), within
    rounding (the same formulas; ``A h_1`` for the compiled form)."""
    from labrig.model.bouc_wen import bouc_wen_exact

    for name, (v, rest) in edge_records().items():
        got = bouc_wen_response(v, A, beta, gamma, rest_V=rest)
        ref = bouc_wen_exact(np.concatenate(([rest], v)), A, beta, gamma)[1:]
        scale = max(float(np.max(np.abs(ref), initial=0.0)), 1e-300)
        assert got.shape == ref.shape, name
        assert np.max(np.abs(got - ref), initial=0.0) <= 1e-13 * scale, name


def test_bouc_wen_derivatives_against_central_differences() -> None:
    """``dh/dks`` and ``dh/dko`` of the compiled kernel against central differences of the
    NumPy closed form (step 1e-5 relative: truncation and rounding both below 1e-8 of the
    scale), on runs that cross zero, runs that do not, and tiny ``k u`` (the series)."""
    from labrig.analysis import baseline_kernels as kern
    from labrig.model.bouc_wen import bouc_wen_exact, monotone_runs

    for (ks, ko), name in [((0.04, 0.02), "walk"), ((0.04, -0.03), "walk"),
                           ((0.05, 0.9), "loops_held"), ((2e-6, 1e-6), "loops_held"),
                           ((0.03, 0.01), "ramp_through_zero")]:  # fmt: skip
        v, rest = edge_records()[name]
        vp = np.concatenate(([rest], v))
        runs = monotone_runs(vp)
        h, hks, hko = kern.bouc_wen_h1(vp, runs, ks, ko, sens=True)

        def h_of(ks_: float, ko_: float, vp=vp, runs=runs) -> np.ndarray:
            return bouc_wen_exact(vp, 1.0, 0.5 * (ks_ + ko_), 0.5 * (ks_ - ko_), runs)

        np.testing.assert_allclose(h, h_of(ks, ko), rtol=0, atol=1e-13 * np.max(np.abs(h)))
        for got, (dks, dko) in ((hks, (1e-5 * ks, 0.0)), (hko, (0.0, 1e-5 * max(ks, abs(ko))))):
            step = dks + dko
            fd = (h_of(ks + dks, ko + dko) - h_of(ks - dks, ko - dko)) / (2 * step)
            assert np.max(np.abs(got - fd)) <= 1e-7 * np.max(np.abs(fd)), (ks, ko, name)
        # without derivatives they are zero and h is the same
        h2, z1, z2 = kern.bouc_wen_h1(vp, runs, ks, ko, sens=False)
        np.testing.assert_array_equal(h2, h)
        assert not z1.any() and not z2.any()


def test_bouc_wen_derivative_on_one_run_against_mpmath() -> None:
    """From ``h = 0`` along one rising run ``h = phi(ks, u)`` and ``dh/dks = psi(ks, u)``: both
    against 40-digit mpmath on both sides of ``|ks u| = 0.01`` (the series' switch), relative
    error below 1e-12."""
    import mpmath

    from labrig.analysis import baseline_kernels as kern
    from labrig.model.bouc_wen import monotone_runs

    mpmath.mp.dps = 40
    u = np.concatenate(([0.0], np.geomspace(1e-4, 200.0, 400)))
    for ks in (1e-5, 4.9e-5, 5.1e-5, 0.05, 2.0):
        h, hks, _ = kern.bouc_wen_h1(u, monotone_runs(u), ks, 0.3 * ks, sens=True)
        k = mpmath.mpf(ks)
        for i in range(1, u.size):
            x = mpmath.mpf(u[i])
            phi = -mpmath.expm1(-k * x) / k
            psi = (x * mpmath.exp(-k * x) - phi) / k
            assert abs(h[i] - phi) <= 1e-12 * abs(phi), (ks, u[i])
            assert abs(hks[i] - psi) <= 1e-12 * abs(psi), (ks, u[i])


def test_segment_sums_against_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled sums of the Bouc-Wen fit against their NumPy forms and a direct
    centred product."""
    from labrig.analysis import baseline_kernels as kern

    rng = np.random.default_rng(5)
    cols = rng.normal(3.0, 2.0, (4, 400))
    meas = rng.normal(-50.0, 10.0, 300)
    lo, n = np.array([10, 150, 399]), np.array([100, 199, 1])
    m0 = np.array([0, 100, 299])
    coef = rng.normal(size=(3, 3, 5))
    got = {}
    for compiled in (True, False):
        if not compiled:
            monkeypatch.setattr(kern, "kernel", lambda name: None)
        for centre in (True, False):
            mom = kern.segment_moments(cols, meas, lo, m0, n, centre)
            gram = kern.residual_gram(cols, meas, lo, m0, n, np.ascontiguousarray(mom[:, 0]), coef)
            got[compiled, centre] = (mom, gram)
    for centre in (True, False):
        for a, b in zip(got[True, centre], got[False, centre], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
        mom, gram = got[True, centre]
        for g in range(3):  # direct: the centred columns' products
            y = np.vstack((cols[:, lo[g] : lo[g] + n[g]], meas[m0[g] : m0[g] + n[g]]))
            yc = y - (y.mean(axis=1, keepdims=True) if centre else 0.0)
            np.testing.assert_allclose(mom[g, 1:], yc @ yc.T, rtol=1e-12, atol=1e-9)
        q = np.hstack([coef[g] @ (np.vstack((cols[:, lo[g] : lo[g] + n[g]],
                                             meas[m0[g] : m0[g] + n[g]])) - mom[g, 0][:, None])
                       for g in range(3)])  # fmt: skip
        np.testing.assert_allclose(gram, q @ q.T, rtol=1e-12, atol=1e-9)


# -- the fits against the previous algorithm ---------------------------------------------------


def reference_bouc_wen(records: list[Record], **kw) -> tuple[BoucWen, float]:
    """The Bouc-Wen fit as it was computed before the compiled kernels (an independent path to
    the same optimum): the full weighted residual vector from :func:`bouc_wen_exact`, ``(d, A)``
    by least squares, Jacobian by scipy's differences; the same start grid, bounds and
    tolerances. Returns the model and its cost, ``sum_e (NRMSE_e / 100)^2``."""
    from scipy import optimize

    from labrig.analysis.simulate import CONVERGED, scored_names, scored_sequences
    from labrig.model.bouc_wen import bouc_wen_exact

    offset, warmup, chain = kw.get("offset", False), kw.get("warmup_s", 0.0), kw.get("chain", False)
    seqs = scored_sequences(records, scored_names(records, None), warmup, chain)
    vps = [np.concatenate(([s.seq.rest_V], s.seq.voltage_V)) for s in seqs]
    vr = max(float(np.ptp(vp)) for vp in vps)

    def cen(x: np.ndarray) -> np.ndarray:
        return x - x.mean() if offset else x

    def columns(beta: float, gamma: float):
        c0, c1, b = [], [], []
        for s, vp in zip(seqs, vps, strict=True):
            h1 = bouc_wen_exact(vp, 1.0, beta, gamma)[1:]
            for g in s.segments:
                c0.append(g.weight * cen(s.seq.voltage_V[g.lo : g.hi]))
                c1.append(-g.weight * cen(h1[g.lo : g.hi]))
                b.append(g.weight * cen(g.measured_ue))
        C = np.column_stack([np.concatenate(c0), np.concatenate(c1)])
        return C, np.concatenate(b)

    def unpack(z):
        ks = float(np.exp(z[0])) / vr
        return 0.5 * (ks + z[1] * ks), 0.5 * (ks - z[1] * ks)

    def fun(z):
        C, b = columns(*unpack(z))
        return C @ np.linalg.lstsq(C, b, rcond=None)[0] - b

    lo, hi = np.array([np.log(1e-3), -0.95]), np.array([np.log(1e3), 20.0])
    grid = [(np.log(x), y) for x in (0.3, 1.0, 3.0, 10.0) for y in (-0.5, 0.3, 1.0, 3.0)]
    z0 = np.array(min(grid, key=lambda z: float(np.sum(fun(np.array(z)) ** 2))))
    res = optimize.least_squares(fun, z0, bounds=(lo, hi), x_scale="jac", **CONVERGED)
    beta, gamma = unpack(res.x)
    C, b = columns(beta, gamma)
    d, A = np.linalg.lstsq(C, b, rcond=None)[0]
    return BoucWen(float(d), float(A), beta, gamma), float(res.fun @ res.fun)


def bw_cases() -> dict[str, tuple[list[Record], dict]]:
    """A chained run (history in the rests) and imported-style records with offsets, a warm-up
    and a held start."""
    truth = BoucWen(d=13.0, A=4.0, beta=0.03, gamma=0.012)
    rng = np.random.default_rng(8)
    volts = [unipolar(a, f, 1.0) for a, f in ((100.0, 1.0), (40.0, 5.0), (70.0, 2.0))]
    rest = np.zeros(300)
    whole = truth.predict(np.concatenate([np.concatenate([v, rest]) for v in volts]))
    chained, pos = [], 0
    for k, v in enumerate(volts):
        s = whole[pos : pos + v.size] + rng.normal(0, 1.0, v.size)
        chained.append(Record.from_arrays(f"e{k}", RATE, v, s, rest_after_s=0.3))
        pos += v.size + rest.size
    held = []
    for k, (a, f) in enumerate(((60.0, 1.0), (90.0, 3.0))):
        v = 20.0 + unipolar(a, f, 2.0)
        s = truth.predict(v, rest_V=20.0) + 30.0 * k + rng.normal(0, 1.0, v.size)
        held.append(Record.from_arrays(f"h{k}", RATE, v, s, hold="linear", rest_V=20.0))
    return {
        "chain": (chained, {"chain": True}),
        "offsets": (held, {"offset": True, "warmup_s": 0.3}),
    }


@pytest.mark.parametrize("case", ["chain", "offsets"])
def test_bouc_wen_fit_equals_the_previous_algorithm(case: str) -> None:
    """Exact derivatives and the 3-row least-squares form reach the optimum the difference-based
    fit on the full residual reaches: parameters within 1e-5 (the optimiser's own tolerance
    leaves them about 1e-5 from the exact optimum), the objective (the sum of squared
    per-entry NRMSE, with offsets each entry about its mean) within 1e-8 relative."""
    records, kw = bw_cases()[case]
    res = fit_baseline(records, "bouc_wen", heldout=False, **kw)
    ref, cost = reference_bouc_wen(records, **kw)
    for k in ("d", "A", "beta", "gamma"):
        assert getattr(res.model, k) == pytest.approx(getattr(ref, k), rel=1e-5), k
    assert sum((p / 100) ** 2 for p in res.per_entry.values()) == pytest.approx(cost, rel=1e-8)


def test_pi_fit_equals_one_qr_of_every_row() -> None:
    """The segments' factors stacked (shared by the folds) give the weights of the NNLS on all
    rows at once, in-sample and for every fold."""
    from scipy import optimize

    recs = [
        *bw_cases()["offsets"][0],
        *bw_cases()["chain"][0],
    ]  # four records on their own, with offsets
    res = fit_baseline(recs, "prandtl_ishlinskii", offset=True, warmup_s=0.3)
    r = np.asarray(res.model.thresholds)
    rows, rhs = [], []
    for rec in recs:
        i0 = round(0.3 * RATE)
        B = play_operators(rec.voltage_V, r, rec.rest_V)[i0:]
        m = rec.strain_ue[i0:]
        w = 1.0 / (np.ptp(m) * np.sqrt(m.size))
        rows.append((B - B.mean(axis=0)) * w)
        rhs.append((m - m.mean()) * w)
    w_ref, _ = optimize.nnls(np.vstack(rows), np.concatenate(rhs), maxiter=50 * r.size)
    np.testing.assert_allclose(res.model.weights, w_ref, rtol=1e-9, atol=1e-9 * np.max(w_ref))
    assert res.heldout_nrmse_pct is not None and res.heldout_nrmse_pct > res.nrmse_pct


def test_numpy_fallback_without_numba(monkeypatch: pytest.MonkeyPatch) -> None:
    """numba missing: one warning, and the NumPy forms give the same fits."""
    import sys

    from labrig.analysis import baseline_kernels as kern

    records, kw = bw_cases()["chain"]
    compiled = {k: fit_baseline(records, k, **kw) for k in ("prandtl_ishlinskii", "bouc_wen")}
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba -> ImportError
    monkeypatch.setattr(kern, "COMPILED", {})
    with pytest.warns(RuntimeWarning, match="numba cannot be imported") as rec:
        plain = {k: fit_baseline(records, k, **kw) for k in ("prandtl_ishlinskii", "bouc_wen")}
    assert len(rec) == 1
    assert all(v is None for v in kern.COMPILED.values())
    for k, a in compiled.items():
        b = plain[k]
        assert b.nrmse_pct == pytest.approx(a.nrmse_pct, rel=1e-8), k
        assert b.heldout_nrmse_pct == pytest.approx(a.heldout_nrmse_pct, rel=1e-7), k
        for name, x in a.params.items():
            assert b.params[name] == pytest.approx(x, rel=1e-5), (k, name)
