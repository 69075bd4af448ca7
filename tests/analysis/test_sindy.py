"""The SINDy baseline: its free-run integrator against scipy's solve_ivp, its fit against a known
sparse ODE, and ``labrig fit --model sindy`` on the repository's real data.

Tolerances: the integrator is exact for the linear part with a voltage linear between samples
(checked to 1e-9 of the span against solve_ivp at rtol 1e-12) and second order otherwise (the
error falls about fourfold when the step halves); the fit of a known ODE with 0.5 ue of noise
recovers its coefficients within 3 % (measured: within 1 %).
"""

from __future__ import annotations

import itertools
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, optimize
from typer.testing import CliRunner

from labrig.analysis.baselines import fit_baseline
from labrig.analysis.records import Record
from labrig.analysis.sindy import (
    LIBRARY,
    THRESHOLDS,
    SindyBaseline,
    equilibrium,
    free_run,
    free_run_numpy,
    library_matrix,
    same_run_up_to,
    smoothed_derivative,
    smoothing_window,
    stlsq,
)
from labrig.cli import app

NAMES = [t.name for t in LIBRARY]
REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "yan9a-micromanipulator"


def xi_of(**coef: float) -> np.ndarray:
    """Coefficients by term name (``S_absS`` for ``S|S|``, ``absVp_S`` for ``|V'| S`` ...)."""
    alias = {"one": "1", "Vp": "V'", "absVp": "|V'|", "Vp_S": "V' S", "Vp_V": "V' V",
             "absVp_S": "|V'| S", "absVp_V": "|V'| V", "S_absS": "S|S|"}  # fmt: skip
    xi = np.zeros(len(LIBRARY))
    for k, v in coef.items():
        xi[NAMES.index(alias.get(k, k))] = v
    return xi


def rhs_of(xi: np.ndarray, V, dV):
    """``dS/dt`` written out term by term (the reference's right-hand side)."""
    c = dict(zip(NAMES, xi, strict=True))

    def f(t: float, y: np.ndarray) -> np.ndarray:
        s, v, d = y[0], V(t), dV(t)
        return np.array(
            [
                c["1"] + c["S"] * s + c["V"] * v + c["V'"] * d + c["|V'|"] * abs(d)
                + c["V' S"] * d * s + c["V' V"] * d * v + c["|V'| S"] * abs(d) * s
                + c["|V'| V"] * abs(d) * v + c["S|S|"] * s * abs(s)
            ]
        )  # fmt: skip

    return f


NONLINEAR = xi_of(one=5.0, S=-30.0, V=240.0, Vp=1.5, absVp=-0.4, Vp_S=0.002, Vp_V=-0.01,
                  absVp_S=-0.03, absVp_V=0.2, S_absS=-2e-4)  # fmt: skip


def test_library_matrix_columns() -> None:
    s, v, d = np.array([2.0, -3.0]), np.array([10.0, 20.0]), np.array([-5.0, 4.0])
    th = library_matrix(s, v, d)
    want = np.column_stack([np.ones(2), s, v, d, np.abs(d), d * s, d * v, np.abs(d) * s,
                            np.abs(d) * v, s * np.abs(s)])  # fmt: skip
    np.testing.assert_array_equal(th, want)


def test_equilibrium_is_a_stable_root() -> None:
    f = rhs_of(NONLINEAR, lambda t: 70.0, lambda t: 0.0)
    s0 = equilibrium(NONLINEAR, 70.0)
    ref = optimize.brentq(lambda s: f(0.0, np.array([s]))[0], 0.0, 2000.0)
    assert s0 == pytest.approx(ref, rel=1e-10)
    h = 1e-3 * abs(s0)
    assert f(0, np.array([s0 + h]))[0] < 0 < f(0, np.array([s0 - h]))[0]  # stable
    # held at that voltage, the free run stays there
    np.testing.assert_allclose(free_run(NONLINEAR, np.full(500, 70.0), 1000.0, 70.0), s0)


def test_equilibrium_agrees_with_numpy_roots_on_random_equations() -> None:
    """The closed-form roots against ``numpy.roots`` (the companion matrix's eigenvalues) of
    each sign's quadratic, on 3 000 random sparse equations and held voltages (coefficients
    over five decades, a third of them zero): the same stable root chosen (nearest the linear
    one), within 1e-12 relative; the same 0 where there is none."""
    rng = np.random.default_rng(5)
    names = NAMES
    for _ in range(3000):
        xi = rng.normal(size=len(names)) * (rng.random(len(names)) < 0.67)
        xi *= 10.0 ** rng.uniform(-4, 1, len(names))
        v = float(rng.uniform(-150.0, 150.0))
        a = xi[names.index("1")] + xi[names.index("V")] * v
        b, c = xi[names.index("S")], xi[names.index("S|S|")]
        linear = -a / b if b < 0 else 0.0
        cands = [linear] if c == 0 and b < 0 else []
        if c != 0:
            for sgn in (1.0, -1.0):
                for r in np.roots([sgn * c, b, a]):
                    ok = abs(r.imag) < 1e-12 and sgn * r.real >= 0 and b + 2 * c * abs(r.real) < 0
                    if ok:
                        cands.append(float(r.real))
        want = min(cands, key=lambda r: abs(r - linear)) if cands else 0.0
        assert equilibrium(xi, v) == pytest.approx(want, rel=1e-12, abs=1e-300), (xi, v)


@pytest.mark.parametrize("scale", [1e-165, 1e-120, 1e120, 1e160])
def test_equilibrium_of_an_equation_scaled_to_extreme_magnitudes(scale: float) -> None:
    """The root does not change when the whole equation is multiplied by a constant: at
    magnitudes where ``b^2`` would under- or overflow the result is the unscaled one."""
    xi = np.zeros(len(NAMES))
    for name, x in (("1", 0.5), ("S", -0.4), ("V", 0.01), ("S|S|", -0.3)):
        xi[NAMES.index(name)] = x
    assert equilibrium(xi * scale, 70.0) == pytest.approx(equilibrium(xi, 70.0), rel=1e-12)


@pytest.mark.parametrize("lag_per_s", [-30.0, -0.5])  # steps beyond and within the series
def test_linear_part_is_exact_for_a_voltage_linear_between_samples(lag_per_s: float) -> None:
    """Without S|S| each step is exact: a triangle with corners on samples, solve_ivp per leg."""
    rate = 1000.0
    xi = NONLINEAR.copy()
    xi[NAMES.index("S|S|")] = 0.0
    xi[NAMES.index("S")] = lag_per_s
    xi[NAMES.index("|V'| S")] = 0.0  # S's factor is then the lag alone
    corners = [(0, 0.0), (100, 80.0), (160, 20.0), (300, 100.0), (400, 0.0)]
    v = np.concatenate([np.linspace(a[1], b[1], b[0] - a[0] + 1)[1:]
                        for a, b in itertools.pairwise(corners)])  # fmt: skip
    got = free_run(xi, v, rate)
    s = equilibrium(xi, 0.0)
    ref = []
    for a, b in itertools.pairwise(corners):
        slope = (b[1] - a[1]) * rate / (b[0] - a[0])
        t0 = a[0] / rate
        f = rhs_of(xi, lambda t, a=a, t0=t0, slope=slope: a[1] + slope * (t - t0),
                   lambda t, slope=slope: slope)  # fmt: skip
        t_eval = np.arange(a[0] + 1, b[0] + 1) / rate
        sol = integrate.solve_ivp(f, (t0, b[0] / rate), [s], t_eval=t_eval, method="DOP853",
                                  rtol=1e-12, atol=1e-10)  # fmt: skip
        ref.append(sol.y[0])
        s = sol.y[0][-1]
    ref = np.concatenate(ref)
    assert np.max(np.abs(got - ref)) < 1e-9 * np.ptp(ref)
    # the nonlinear step (taken whenever S|S| is on) is exact for the same linear equation
    xi[NAMES.index("S|S|")] = 1e-300
    assert np.max(np.abs(free_run(xi, v, rate) - ref)) < 1e-9 * np.ptp(ref)


def test_free_run_against_solve_ivp_on_a_smooth_drive() -> None:
    """Every term on, a smooth 5 Hz drive: second-order convergence to the reference."""
    w = 2 * np.pi * 5.0

    def V(t):
        return 50.0 * (1 - np.cos(w * t))

    def dV(t):
        return 50.0 * w * np.sin(w * t)

    f = rhs_of(NONLINEAR, V, dV)
    duration = 0.6
    errors = []
    for rate in (1000.0, 2000.0, 4000.0):
        t = np.arange(1, round(duration * rate) + 1) / rate
        sol = integrate.solve_ivp(f, (0.0, t[-1]), [equilibrium(NONLINEAR, 0.0)], t_eval=t,
                                  method="DOP853", rtol=1e-11, atol=1e-9)  # fmt: skip
        got = free_run(NONLINEAR, V(t), rate, 0.0)
        errors.append(np.max(np.abs(got - sol.y[0])) / np.ptp(sol.y[0]))
    assert errors[0] < 1e-4  # measured 2.9e-5 of the span at 1 kHz
    for coarse, fine in itertools.pairwise(errors):
        assert 3.0 < coarse / fine < 5.0


def test_free_run_is_stable_for_a_stiff_lag_and_fast() -> None:
    rate, n = 1000.0, 50_000
    t = np.arange(n) / rate
    v = 50 * (1 - np.cos(2 * np.pi * 1.0 * t))
    stiff = xi_of(S=-1e5, V=8e5)  # tau = 10 us at 1 ms steps: quasi-static S = 8 V
    t0 = time.perf_counter()
    got = free_run(stiff, v, rate)
    linear_s = time.perf_counter() - t0
    # exact for a linear V between samples: the lag of 10 us behind 8 V is 8 tau dV/dt
    lag = 8.0 * 1e-5 * np.diff(np.concatenate(([0.0], v))) * rate
    np.testing.assert_allclose(got, 8.0 * v - lag, atol=1e-6 * 800)
    t0 = time.perf_counter()
    nonlinear = free_run(NONLINEAR, v, rate)
    nonlinear_s = time.perf_counter() - t0
    assert np.all(np.isfinite(nonlinear))
    assert linear_s < 1.0 and nonlinear_s < 1.0  # measured 0.02 s and 0.05 s


def test_a_diverging_model_is_held_at_its_limit() -> None:
    grows = xi_of(S=5.0, V=10.0, S_absS=1e-3)
    got = free_run(grows, np.full(2000, 10.0), 1000.0, 0.0, limit_ue=1e4)
    assert np.all(np.isfinite(got)) and got[-1] == 1e4 and np.max(np.abs(got)) <= 1e4


def test_smoothing_window() -> None:
    assert smoothing_window(1000.0, 40.0) == 5  # 1/8 of 25 samples, at least 5
    assert smoothing_window(200.0, 1.0) == 25
    assert smoothing_window(1000.0, 1.0) == 101  # at most 101
    assert smoothing_window(1000.0, None) == 11  # 10 ms, odd


# -- fitting ----------------------------------------------------------------------------------

KNOWN = xi_of(S=-20.0, V=160.0, Vp=2.0, absVp_S=-0.02, absVp_V=0.12)


def known_records(noise: float, rate: float = 1000.0, rest_s: float | None = None):
    """Sines at 50/100 V and 1/5/20 Hz through the KNOWN ODE (chained with ``rest_s``)."""
    rng = np.random.default_rng(0)
    volts = []
    for a in (50.0, 100.0):
        for f in (1.0, 5.0, 20.0):
            t = np.arange(round(2.0 * rate)) / rate
            volts.append((f"{a:g}V_{f:g}Hz", f, a / 2 * (1 - np.cos(2 * np.pi * f * t))))
    if rest_s is None:
        strains = [free_run(KNOWN, v, rate) for _, _, v in volts]
    else:
        rest = np.zeros(round(rest_s * rate))
        whole = free_run(KNOWN, np.concatenate([np.concatenate([v, rest]) for *_, v in volts]),
                         rate)  # fmt: skip
        step = volts[0][2].size + rest.size
        strains = [whole[k * step : k * step + v.size] for k, (*_, v) in enumerate(volts)]
    out = []
    for (name, f, v), s in zip(volts, strains, strict=True):
        meta = {"frequency_hz": f} | ({} if rest_s is None else {"rest_after_s": rest_s})
        out.append(Record.from_arrays(name, rate, v, s + rng.normal(0, noise, v.size), **meta))
    return out


def test_fit_recovers_a_known_sparse_ode() -> None:
    records = known_records(noise=0.5)
    res = fit_baseline(records, "sindy")
    assert isinstance(res.model, SindyBaseline)
    support = {t.name for t in res.model.support}
    assert support == {"S", "V", "V'", "|V'| S", "|V'| V"}
    np.testing.assert_allclose(res.model.coefficients, KNOWN, rtol=0.03)
    floor = np.mean([100 * 0.5 / np.ptp(r.strain_ue) for r in records])
    assert res.nrmse_pct < 1.3 * floor
    assert res.heldout_nrmse_pct < 1.3 * floor
    j = res.to_json()
    assert j["method"] == "sindy"
    assert j["params"]["terms"] == ["S", "V", "V'", "|V'| S", "|V'| V"]
    assert len(j["params"]["coefficients"]) == len(j["params"]["coefficient_units"]) == 5
    assert j["params"]["equation"].startswith("dS/dt = -20")


def test_chained_run_with_one_offset_per_entry() -> None:
    """A run's entries back to back with their rests, each measured with its own zero."""
    records = known_records(noise=0.5, rest_s=0.5)
    offsets = {r.name: 40.0 * k - 90.0 for k, r in enumerate(records)}
    shifted = [r.with_strain(r.strain_ue + offsets[r.name]) for r in records]
    res = fit_baseline(shifted, "sindy", chain=True, offset=True)
    assert res.chain and res.offsets_ue is not None
    assert {t.name for t in res.model.support} == {"S", "V", "V'", "|V'| S", "|V'| V"}
    for name, o in offsets.items():  # measured: within 2.3 ue (spans of 400 to 900 ue)
        assert res.offsets_ue[name] == pytest.approx(o, abs=3.0)
    floor = np.mean([100 * 0.5 / np.ptp(r.strain_ue) for r in records])
    assert res.nrmse_pct < 2 * floor and res.heldout_nrmse_pct < 2 * floor  # measured 1.5x


def test_records_of_different_rates_are_refused() -> None:
    a = known_records(noise=0.0)[:2]
    b = [Record.from_arrays("slow", 500.0, a[0].voltage_V[::2], a[0].strain_ue[::2])]
    with pytest.raises(ValueError, match="one sample rate"):
        fit_baseline([*a, *b], "sindy")


@pytest.mark.skipif(not (REAL / "Model_Vi_Do.dat").is_file(), reason="real data not in the repo")
def test_cli_fit_sindy_on_real_data(tmp_path: Path) -> None:
    runner = CliRunner()
    run = tmp_path / "real.h5"
    files = [str(REAL / f) for f in ("Model_Vi_Do.dat", "Test_Vi_Do_Di.dat")]
    res = runner.invoke(app, ["import", *files, "--out", str(run), "--voltage", "1",
                              "--strain", "5", "--rate-hz", "200",
                              "--strain-units", "raw"])  # fmt: skip
    assert res.exit_code == 0, res.stderr
    res = runner.invoke(app, ["fit", str(run), "--model", "sindy", "--json"])
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert list(j) == ["params", "uncertainty", "correlation", "nrmse_pct", "per_entry",
                       "heldout_nrmse_pct", "method", "entries"]  # fmt: skip
    assert j["method"] == "sindy" and j["params"]["equation"].startswith("dS/dt =")
    assert set(j["per_entry"]) == {"Model_Vi_Do", "Test_Vi_Do_Di"}
    assert j["nrmse_pct"] < 1.0  # measured 0.78 % (ours 0.65 %)
    assert j["heldout_nrmse_pct"] > j["nrmse_pct"]
    res = runner.invoke(app, ["fit", str(run), "--model", "sindy", "--no-heldout"],
                        env={"COLUMNS": "200"})  # fmt: skip
    assert res.exit_code == 0, res.stderr
    assert "sindy parameters" in res.stdout and "dS/dt = " in res.stdout
    assert "coefficient_units" in res.stdout and "1/s" in res.stdout


# -- compiled and reproduced parts against their references -------------------------------------


def test_compiled_free_run_equals_the_numpy_form() -> None:
    """Each library term alone, all of them, a diverging model held at its limit, flat
    stretches, a held start, one sample and none: the compiled run against
    :func:`free_run_numpy` (the same steps; the transcendental functions' last bits aside)."""
    rate = 1000.0
    t = np.arange(3000) / rate
    v = 40.0 + 50.0 * (1 - np.cos(2 * np.pi * 3.0 * t)) * np.clip(1.5 - t, 0.0, 1.0)
    v[500:700] = v[499]  # a flat stretch
    cases = [(NONLINEAR, v, 40.0, math.inf), (xi_of(S=5.0, V=10.0, S_absS=1e-3), v, 0.0, 1e4)]
    for k, name in enumerate(NAMES):  # each term alone, with a lag so it stays bounded
        xi = np.zeros(len(NAMES))
        xi[k] = NONLINEAR[k]
        if name != "S":
            xi[NAMES.index("S")] = -30.0
        cases.append((xi, v, 40.0, math.inf))
    cases += [(NONLINEAR, v[:1], 40.0, math.inf), (NONLINEAR, v[:0], 0.0, math.inf)]
    for xi, vv, rest, limit in cases:
        got = free_run(xi, vv, rate, rest, limit)
        ref = free_run_numpy(xi, vv, rate, rest, limit)
        assert got.shape == ref.shape == vv.shape
        scale = max(float(np.max(np.abs(ref), initial=0.0)), 1.0)
        assert np.max(np.abs(got - ref), initial=0.0) <= 1e-12 * scale, xi
    held = free_run(xi_of(S=5.0, V=10.0, S_absS=1e-3), v, rate, 0.0, 1e4)
    assert held[-1] == 1e4


@pytest.mark.parametrize("window", [5, 11, 101])
def test_smoothed_derivative_equals_pysindy(window: int) -> None:
    from pysindy import SmoothedFiniteDifference

    rng = np.random.default_rng(2)
    rate = 1000.0
    t = np.arange(1500) / rate
    x = 300.0 * np.sin(2 * np.pi * 2.0 * t) ** 3 + rng.normal(0.0, 2.0, t.size)
    sfd = SmoothedFiniteDifference(smoother_kws={"window_length": window, "polyorder": 3})
    ref = np.asarray(sfd(x, t=1.0 / rate), dtype=float).ravel()
    got = smoothed_derivative(x, rate, window)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def regression_systems() -> list[tuple[np.ndarray, np.ndarray]]:
    """STLSQ's inputs as the fit makes them (the library on a simulated drive, columns and
    target at unit RMS, reduced to the triangular system), a random one, and one with two
    equal columns (rank-deficient: the ridge keeps it solvable, the refit cuts a singular
    value)."""
    rng = np.random.default_rng(4)
    rate = 1000.0
    t = np.arange(4000) / rate
    v = 50.0 * (1 - np.cos(2 * np.pi * 2.0 * t))
    s = free_run(NONLINEAR, v, rate) + rng.normal(0.0, 0.5, t.size)
    d = np.gradient(v) * rate
    X = library_matrix(s, v, d)
    y = smoothed_derivative(s, rate, 63)
    out = []
    for a, b in ((X, y), (rng.normal(size=(200, 10)), rng.normal(size=200))):
        a = a / np.sqrt(np.mean(a * a, axis=0))
        q, r = np.linalg.qr(a, mode="reduced")
        out.append((r, q.T @ (b / np.sqrt(np.mean(b * b)))))
    r, qty = out[-1]
    dup = r.copy()
    dup[:, 3] = dup[:, 2]
    out.append((dup, qty))
    return out


def test_stlsq_equals_pysindy() -> None:
    """Every threshold of the fit's path (and one that drops every term) against pysindy's
    STLSQ with the same settings."""
    from pysindy.optimizers import STLSQ

    for x, y in regression_systems():
        thresholds = (*THRESHOLDS, 1e6)
        got = stlsq(x, y, thresholds)
        assert [lam for lam, _ in got] == list(thresholds)
        supports = set()
        for lam, xi in got:
            opt = STLSQ(threshold=lam, alpha=1e-6, unbias=True, max_iter=20)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                opt.fit(x, y)
            ref = np.asarray(opt.coef_, dtype=float).ravel()
            # the thresholds answered by an earlier fit (not fitted) as well: to the bit
            np.testing.assert_array_equal(xi, ref, err_msg=str(lam))
            supports.add(tuple(np.flatnonzero(xi)))
        assert len(supports) >= 4 and () in supports  # a path, down to nothing


def test_stlsq_fits_only_the_thresholds_an_earlier_fit_does_not_answer(monkeypatch) -> None:
    """Along the fit's path most thresholds repeat an earlier one's run: fewer pysindy fits
    than thresholds (the results are checked against a fit per threshold above), and a path
    asked in decreasing order (nothing answered: each threshold below the last) fits all."""
    from pysindy.optimizers import STLSQ

    calls: list[float] = []
    real_fit = STLSQ.fit

    def counting_fit(self, x, y, *a, **k):
        calls.append(self.threshold)
        return real_fit(self, x, y, *a, **k)

    monkeypatch.setattr(STLSQ, "fit", counting_fit)
    for x, y in regression_systems():
        calls.clear()
        stlsq(x, y, THRESHOLDS)
        assert 1 <= len(calls) <= len(THRESHOLDS) // 2, len(calls)
        calls.clear()
        stlsq(x, y, THRESHOLDS[::-1])
        assert len(calls) == len(THRESHOLDS)


def test_same_run_up_to() -> None:
    """The smallest coefficient any iterate kept (the start, history[0], is not an iterate);
    ``inf`` when every iterate is empty; ``-inf`` for a threshold of 0 (nothing to tell)."""
    start = np.array([[1e-4, 0.3, -2.0]])
    history = [start, np.array([[0.0, 0.3, -2.0]]), np.array([[0.0, 0.0, -1.5]])]
    assert same_run_up_to(history, 0.1) == 0.3
    assert same_run_up_to([start, np.zeros((1, 3))], 0.1) == math.inf
    assert same_run_up_to(history, 0.0) == -math.inf


def reference_sindy(records: list[Record], chain: bool, leave_out: str | None = None):
    """The SINDy fit as it was computed with pysindy (no offsets): pysindy's smoothed
    derivative per segment, one QR of every weighted row, pysindy's STLSQ per threshold, each
    support scored in free run by :func:`free_run_numpy`, the sparsest within the tolerance
    kept. ``leave_out``: fitted without that entry; returns the model and the free-run
    prediction of every record's sequence."""
    from pysindy import SmoothedFiniteDifference
    from pysindy.optimizers import STLSQ

    from labrig.analysis.metrics import drive_frequency_hz, nrmse_pct
    from labrig.analysis.simulate import scored_sequences

    names = [r.name for r in records]
    seqs = scored_sequences(records, names, 0.0, chain)
    items = [(s.seq, [g for g in s.segments if g.name != leave_out]) for s in seqs]
    items = [(q, gs) for q, gs in items if gs]
    rate = items[0][0].rate_hz
    X, Y = [], []
    for seq, segs in items:
        d_all = np.gradient(seq.voltage_V) * seq.rate_hz
        recs = {r.name: r for r in seq.records}
        for g in segs:
            w = smoothing_window(rate, drive_frequency_hz(recs[g.name]))
            sfd = SmoothedFiniteDifference(smoother_kws={"window_length": w, "polyorder": 3})
            sl = slice(w // 2, g.measured_ue.size - w // 2)
            tg = np.asarray(sfd(g.measured_ue, t=1.0 / rate), dtype=float).ravel()[sl]
            wt = 1.0 / (np.sqrt(np.mean(tg * tg)) * np.sqrt(tg.size))
            v, d = seq.voltage_V[g.lo : g.hi][sl], d_all[g.lo : g.hi][sl]
            X.append(library_matrix(g.measured_ue[sl], v, d) * wt)
            Y.append(tg * wt)
    X, y = np.vstack(X), np.concatenate(Y)
    cs, ys = np.sqrt(np.mean(X * X, axis=0)), float(np.sqrt(np.mean(y * y)))
    q, r = np.linalg.qr(X / cs, mode="reduced")
    span = max(float(np.ptp(g.measured_ue)) for _, gs in items for g in gs)
    cands, seen = [], set()
    for lam in THRESHOLDS:
        opt = STLSQ(threshold=lam, alpha=1e-6, unbias=True, max_iter=20)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(r, q.T @ (y / ys))
        xi = np.asarray(opt.coef_, dtype=float).ravel() * ys / cs
        if tuple(np.flatnonzero(xi)) in seen:
            continue
        seen.add(tuple(np.flatnonzero(xi)))
        scores = []
        for seq, segs in items:
            p = free_run_numpy(xi, seq.voltage_V, rate, seq.rest_V, 100.0 * span)
            scores += [nrmse_pct(g.measured_ue, p[g.lo : g.hi]) for g in segs]
        cands.append((float(np.mean(scores)), xi))
    best = min(c[0] for c in cands)
    ok = [c for c in cands if c[0] <= 1.05 * best]
    xi = min(ok, key=lambda c: (np.count_nonzero(c[1]), c[0]))[1]
    preds = {s.seq.records[0].name if not chain else "chain":
             free_run_numpy(xi, s.seq.voltage_V, rate, s.seq.rest_V, 100.0 * span)
             for s in seqs}  # fmt: skip
    return xi, preds, seqs


@pytest.mark.parametrize("chain", [False, True])
def test_fit_and_folds_equal_the_pysindy_fit(chain: bool) -> None:
    """The fit with the reproduced derivative and STLSQ, the shared per-segment factors and the
    compiled free run: the coefficients of the pysindy-based fit (relative 1e-9), in-sample and
    for every leave-one-entry-out fold (held-out NRMSE relative 1e-9)."""
    from labrig.analysis.metrics import nrmse_pct

    records = [r for r in known_records(noise=0.5, rest_s=0.5 if chain else None)
               if r.name.endswith(("_1Hz", "_5Hz"))]  # fmt: skip
    res = fit_baseline(records, "sindy", chain=chain)
    xi, _, _ = reference_sindy(records, chain)
    np.testing.assert_allclose(res.model.coefficients, xi, rtol=1e-9, atol=0)
    for name, held in res.heldout_per_entry.items():
        xi, preds, seqs = reference_sindy(records, chain, leave_out=name)
        k = next(i for i, s in enumerate(seqs) if any(g.name == name for g in s.segments))
        g = next(g for g in seqs[k].segments if g.name == name)
        p = preds["chain" if chain else name][g.lo : g.hi]
        assert held == pytest.approx(nrmse_pct(g.measured_ue, p), rel=1e-9), name
