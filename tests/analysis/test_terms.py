"""The term library and the sparse selection of terms from a residual (labrig.analysis.terms).

References are independent of the code under test: terms against hand-written formulas and
analytic derivatives, coefficients against the planted ones (tolerances from the noise: with
n samples of unit-RMS columns and noise sigma, a coefficient's standard error is about
sigma / sqrt(n)), and the projection against a joint least-squares fit (Frisch-Waugh-Lovell).
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.analysis.terms import (
    TERM_KEYS,
    SelectionRule,
    Term,
    TermScales,
    empirical_effect,
    select_terms,
    term_columns,
    term_library,
)
from labrig.model.effects.base import Context

N = 4000
RNG = np.random.default_rng(12)


def signals(k: int, n: int = N) -> np.ndarray:
    """``k`` smooth, unit-RMS, roughly independent columns."""
    t = np.linspace(0.0, 1.0, n)
    cols = []
    for j in range(k):
        x = np.sin(2 * np.pi * (j + 1.3) * t + 0.7 * j) + 0.5 * np.cos(2 * np.pi * (2 * j + 5) * t)
        cols.append(x / np.sqrt(np.mean(x * x)))
    return np.column_stack(cols)


def plain_terms(k: int) -> list[Term]:
    """Terms named x0..x(k-1) with scale 1 (select_terms only reads names, scales, physics)."""
    return [
        Term(f"x{j}", f"x{j}", "", 1.0, "", "", lambda s, c, j=j: np.zeros(c.n)) for j in range(k)
    ]


# -- selection --------------------------------------------------------------------------------


def test_recovers_a_sparse_combination_with_signs_and_shares() -> None:
    X = signals(6)
    noise = 0.05
    r = 2.0 * X[:, 1] - 0.7 * X[:, 4] + RNG.normal(0, noise, N)
    sel = select_terms(r, X, plain_terms(6))
    assert sel.keys == ["x1", "x4"]
    got = {t.key: t for t in sel.terms}
    # standard error about noise / sqrt(N) = 8e-4 (times the columns' collinearity): 0.01 is
    # more than 10 standard errors
    assert got["x1"].coefficient_ue == pytest.approx(2.0, abs=0.01)
    assert got["x4"].coefficient_ue == pytest.approx(-0.7, abs=0.01)
    assert (got["x1"].sign, got["x4"].sign) == (1, -1)
    # the pair explains all but the noise
    assert sel.share == pytest.approx(1 - noise**2 * N / float(r @ r), abs=0.002)
    assert 0 < got["x4"].share < got["x1"].share < sel.share


def test_noise_alone_selects_nothing() -> None:
    X = signals(6)
    sel = select_terms(RNG.normal(0, 1.0, N), X, plain_terms(6))
    assert sel.terms == [] and sel.threshold is None
    assert sel.best_share < SelectionRule().min_share


@pytest.mark.parametrize(("small", "kept"), [(0.1, False), (0.6, True)])
def test_the_sparsest_support_within_the_tolerance_is_kept(small: float, kept: bool) -> None:
    """A second term that adds less than 5 % of the best share is left out; one that adds more
    is kept (shares measured here by plain least squares)."""
    X = signals(4)
    r = X[:, 0] + small * X[:, 2] + RNG.normal(0, 0.05, N)

    def share(cols: list[int]) -> float:
        c, *_ = np.linalg.lstsq(X[:, cols], r, rcond=None)
        e = r - X[:, cols] @ c
        return 1 - float(e @ e) / float(r @ r)

    assert (share([0]) < 0.95 * share([0, 2])) == kept  # the planted case is what it claims
    sel = select_terms(r, X, plain_terms(4))
    assert sel.keys == (["x0", "x2"] if kept else ["x0"])


def test_weights_act_like_labrigs_fits() -> None:
    """Zero weights remove samples: a term present only there is not selected."""
    X = signals(3)
    half = N // 2
    r = np.where(np.arange(N) < half, 1.5 * X[:, 0], -2.0 * X[:, 2])
    w = np.where(np.arange(N) < half, 1.0, 0.0)
    sel = select_terms(r, X, plain_terms(3), weights=w)
    assert sel.keys == ["x0"]
    assert sel.terms[0].coefficient_ue == pytest.approx(1.5, rel=1e-6)


def test_projection_off_the_model_basis() -> None:
    """A term the model absorbs is reported and never selected; the selected coefficient equals
    the joint least-squares fit of the model's directions and the term."""
    X = signals(5)
    J = np.column_stack([X[:, 0], 0.6 * X[:, 0] + X[:, 3]])  # the model's directions
    B, _ = np.linalg.qr(J)
    cols = np.column_stack([X[:, 0], X[:, 1], 0.8 * X[:, 0] + 0.5 * X[:, 2]])
    r = 3.0 * X[:, 0] + 1.2 * cols[:, 2] + 0.5 * X[:, 3] + RNG.normal(0, 0.02, N)
    sel = select_terms(r, cols, plain_terms(3), basis=B)
    assert sel.absorbed == ["x0"]
    assert sel.keys == ["x2"]
    joint, *_ = np.linalg.lstsq(np.column_stack([J, cols[:, 2]]), r, rcond=None)
    assert sel.terms[0].coefficient_ue == pytest.approx(joint[-1], rel=1e-9)
    assert sel.terms[0].coefficient_ue == pytest.approx(1.2, abs=0.01)


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="columns"):
        select_terms(np.zeros(10), np.zeros((10, 3)), plain_terms(2))


# -- the library --------------------------------------------------------------------------------


def record(name: str, v: np.ndarray, s: np.ndarray, temp: np.ndarray | None = None) -> Record:
    aux = {} if temp is None else {"temperature": temp}
    return Record(name, 1000.0, np.arange(v.size) / 1000.0, v, s, aux)


def test_terms_against_their_formulas() -> None:
    rate = 1000.0
    t = np.arange(2000) / rate
    v = 40.0 + 60.0 * np.sin(2 * np.pi * 3 * t)
    s = 9.0 * v + 20 * np.cos(2 * np.pi * 3 * t)
    temp = 25.0 + 0.5 * t
    scales = TermScales.from_records([record("a", v, s, temp)])
    assert scales.v_ref_V == pytest.approx(100.0, rel=1e-4)
    assert scales.rate_ref_V_per_s == pytest.approx(60 * 2 * np.pi * 3, rel=1e-3)
    assert scales.strain_ref_ue == pytest.approx(np.ptp(s))
    lib = term_library(scales)
    assert tuple(lib) == TERM_KEYS
    ctx = Context(rate, v, {"a": slice(0, v.size)}, None, temp, hold="linear")  # smooth V
    dv = 60 * 2 * np.pi * 3 * np.cos(2 * np.pi * 3 * t)  # analytic dV/dt
    inner = slice(1, -1)  # central differences: O(h^2) = 2e-4 relative inside
    expected = {
        "V": v / scales.v_ref_V,
        "V2": v**2 / scales.v_ref_V**2,
        "V3": v**3 / scales.v_ref_V**3,
        "S": s / scales.strain_ref_ue,
        "S_absS": s * np.abs(s) / scales.strain_ref_ue**2,
        "V_S": v * s / (scales.v_ref_V * scales.strain_ref_ue),
        "dVdt": dv / scales.rate_ref_V_per_s,
        "absdVdt": np.abs(dv) / scales.rate_ref_V_per_s,
        "absdVdt_S": np.abs(dv) * s / (scales.rate_ref_V_per_s * scales.strain_ref_ue),
        "T": (temp - np.mean(temp)) / scales.dt_ref_K,
        "T_S": (temp - np.mean(temp)) * s / (scales.dt_ref_K * scales.strain_ref_ue),
    }
    for key, want in expected.items():
        got = lib[key].values(s, ctx)
        np.testing.assert_allclose(got[inner], want[inner], rtol=1e-3, atol=1e-3, err_msg=key)
    cols = term_columns(list(lib.values()), s, ctx)
    assert cols.shape == (v.size, len(lib))


def test_term_slopes_are_the_derivatives_in_the_strain() -> None:
    rate = 1000.0
    t = np.arange(500) / rate
    v = 50 * (1 - np.cos(2 * np.pi * 5 * t))
    s = 8.0 * v - 30.0
    temp = 30 + 2 * t
    scales = TermScales(100.0, 2000.0, 900.0, 30.0, 1.0)
    ctx = Context(rate, v, {"a": slice(0, v.size)}, None, temp)
    h = 1e-3
    for term in term_library(scales).values():
        fd = (term.values(s + h, ctx) - term.values(s - h, ctx)) / (2 * h)
        np.testing.assert_allclose(
            np.broadcast_to(term.slope(s, ctx), s.shape), fd, rtol=1e-6, atol=1e-12,
            err_msg=term.key,
        )  # fmt: skip
        assert term.uses_strain == bool(np.any(fd != 0))


def test_temperature_is_referenced_across_the_campaign() -> None:
    """One reference for every entry (the campaign's mean), so a hot entry's thermal term is
    not zero at its own start (issue 18: aux channels referenced across the campaign)."""
    v = np.linspace(0, 100, 300)
    cool = record("cool", v, 9 * v, np.full(300, 25.0))
    hot = record("hot", v, 9 * v, np.full(300, 35.0))
    scales = TermScales.from_records([cool, hot])
    assert scales.t_ref_C == pytest.approx(30.0) and scales.dt_ref_K == pytest.approx(5.0)
    term = term_library(scales)["T"]
    ctx = Context(1000.0, v, {"hot": slice(0, 300)}, None, hot.aux["temperature"])
    np.testing.assert_allclose(term.values(hot.strain_ue, ctx), 1.0)
    # no temperature channel on every record: no temperature terms
    plain = TermScales.from_records([cool, record("x", v, 9 * v)])
    assert "T" not in term_library(plain) and "T_S" not in term_library(plain)


def test_empirical_effect_from_keys() -> None:
    scales = TermScales(100.0, 1e4, 1000.0)
    eff = empirical_effect(["V3", "V2"], scales)
    assert [q.name for q in eff.params] == ["c_V3", "c_V2"]
    with pytest.raises(ValueError, match="unknown terms"):
        empirical_effect(["V4"], scales)
    with pytest.raises(ValueError, match="unknown terms"):
        empirical_effect(["T_S"], scales)  # the campaign has no temperature channel


def test_odd_terms_read_by_their_sign():
    """A negative V^3 or S|S| reads as field saturation; a positive one (a gain rising with
    field) corresponds to no library effect."""
    lib = term_library(TermScales(100.0, 1e4, 1000.0))
    for key in ("V3", "S_absS"):
        assert lib[key].reading(-1.0)[1] == "field_saturation"
        physics, effect = lib[key].reading(+1.0)
        assert effect == "" and "rising" in physics
    assert lib["V2"].reading(+1.0)[1] == "quadratic_term"
