"""The sparse ODE's forward sensitivities: the derivative of its free run, of its rest strain and
of the output-error residual with respect to each coefficient, against central differences of
the NumPy reference recursion (:func:`free_run_numpy`, written separately from the compiled
kernels).

Tolerances: central differences with a relative step of 1e-4 have a truncation error of order
1e-8 and a rounding error of order 1e-16 / 1e-4 = 1e-12 of the output's scale over the
coefficient's (measured on the case with every term: 4e-9 to 8e-9 of each column's largest
value; 4e-7 to 6e-7 with a step of 1e-6, where rounding dominates); the check allows 1e-6 of
each column's largest value, so a wrong term (an error of order one in a step's derivative)
cannot pass. The free run the kernel returns beside the
sensitivities is the free run itself, to the bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from labrig.analysis.baseline_kernels import sindy_free_run_sensitivities
from labrig.analysis.diagnose.contraction import (
    least_squares_jacobian,
    output_jacobian,
    output_residual,
    scored_runs,
)
from labrig.analysis.records import Record
from labrig.analysis.simulate import scored_sequences
from labrig.analysis.sindy import (
    LIBRARY,
    equilibrium,
    equilibrium_gradient,
    free_run,
    free_run_numpy,
    free_run_sensitivities,
)
from labrig.analysis.split import split_entries

NAMES = [t.name for t in LIBRARY]
RATE = 1000.0
#: every term, a lag, a saturating S|S| (the equilibrium is a root of the quadratic)
FULL = np.array([5.0, -20.0, 0.3, 0.9, 0.05, -1e-3, 2e-4, -2e-3, 1e-5, -1e-3])


def _drive(n: int = 3000, bias: float = 50.0) -> np.ndarray:
    t = np.arange(n) / RATE
    return bias + 60.0 * np.sin(2 * np.pi * 1.3 * t) + 5.0 * np.sin(2 * np.pi * 17.0 * t)


def _central(f, xi: np.ndarray, k: int, h: float | None = None) -> np.ndarray:
    """Central difference of ``f`` in ``xi[k]``, step ``1e-4 |xi_k|`` (``h`` when given)."""
    h = h or 1e-4 * abs(xi[k])
    up, dn = xi.copy(), xi.copy()
    up[k] += h
    dn[k] -= h
    return (f(up) - f(dn)) / (2 * h)


def _only(**terms: float) -> np.ndarray:
    xi = np.zeros(len(NAMES))
    for name, x in terms.items():
        xi[NAMES.index(name)] = x
    return xi


CASES = {
    "every term": (FULL, 10.0),
    "linear (no S|S|)": (np.where(np.arange(10) == 9, 0.0, FULL), 10.0),
    "growing S|S|": (_only(**{"1": 2.0, "S": -5.0, "V": 0.2, "V'": 0.5, "S|S|": 1e-4}), 0.0),
    "a stiff lag": (_only(**{"S": -3000.0, "V": 300.0, "|V'| S": -0.01}), 20.0),
    "a slow lag, small z (series)": (_only(**{"S": -0.5, "V": 0.05, "V' S": 1e-4}), 20.0),
}


@pytest.mark.parametrize("case", CASES)
def test_the_free_run_beside_its_sensitivities_is_the_free_run(case: str) -> None:
    xi, rest = CASES[case]
    v = _drive()
    y, _ = free_run_sensitivities(xi, v, RATE, rest)
    assert np.array_equal(y, free_run(xi, v, RATE, rest))


@pytest.mark.parametrize("case", CASES)
def test_sensitivities_equal_central_differences_of_the_reference_run(case: str) -> None:
    xi, rest = CASES[case]
    v = _drive()
    y, J = free_run_sensitivities(xi, v, RATE, rest)
    assert J.shape == (v.size, len(NAMES))
    for k in range(len(NAMES)):
        # a term the model lacks: a step that moves the run by about 1e-4 of its size
        h = None if xi[k] else 1e-4 * np.max(np.abs(y)) / max(np.max(np.abs(J[:, k])), 1e-300)
        ref = _central(lambda x: free_run_numpy(x, v, RATE, rest), xi, k, h)
        scale = max(float(np.max(np.abs(ref))), 1e-9)
        assert np.max(np.abs(J[:, k] - ref)) <= 1e-6 * scale, NAMES[k]


def test_a_held_output_has_no_sensitivity() -> None:
    """A run that leaves its limit is held there: the held samples do not move with the
    coefficients (and nothing before the limit is reached changes)."""
    xi = _only(**{"1": 50.0, "S": 3.0})  # grows from rest
    v = np.zeros(2000)
    y, J = free_run_sensitivities(xi, v, RATE, 0.0, limit_ue=1e3)
    held = np.abs(y) == 1e3
    assert held.any() and not held.all()
    assert np.all(J[held] == 0.0)
    free = ~held
    for k in (0, 1):
        ref = _central(lambda x: free_run_numpy(x, v, RATE, 0.0, 1e3), xi, k)
        assert np.max(np.abs(J[free, k] - ref[free])) <= 1e-6 * np.max(np.abs(ref[free]))


@pytest.mark.parametrize(
    ("xi", "rest"),
    [(FULL, 10.0), (FULL, -80.0), (_only(**{"1": 3.0, "S": -2.0, "V": 0.5}), 7.0)],
)
def test_the_rest_strain_moves_as_central_differences_say(xi: np.ndarray, rest: float) -> None:
    g = equilibrium_gradient(xi, rest)
    ref = np.array(
        [
            _central(lambda x: np.array(equilibrium(x, rest)), xi, k, 1e-4 * (abs(xi[k]) or 1.0))
            for k in range(10)
        ]
    )
    assert np.allclose(g, ref.ravel(), rtol=1e-6, atol=1e-12)


def test_no_equilibrium_no_gradient() -> None:
    """``S' = 1 + S`` held anywhere has no stable rest: the start is 0, fixed."""
    xi = _only(**{"1": 1.0, "S": 1.0})
    assert equilibrium(xi, 5.0) == 0.0
    assert np.all(equilibrium_gradient(xi, 5.0) == 0.0)


def _runs() -> list:
    v = _drive(4000, bias=0.0)
    s = free_run(FULL, v, RATE, 0.0) + np.random.default_rng(1).normal(0, 0.05, v.size)
    rec = Record.from_arrays("r", RATE, v, s, hold="linear")
    rec.meta["kind"] = "import"
    recs = split_entries([rec], 4)
    scored = scored_sequences(recs, [r.name for r in recs], 0.0, True)
    return scored_runs([(x.seq, list(x.segments)) for x in scored])


@pytest.mark.parametrize("offset", [False, True])
def test_the_output_residuals_jacobian_equals_central_differences(offset: bool) -> None:
    runs = _runs()
    xi = FULL * 1.01
    J = output_jacobian(runs, xi, offset, math.inf)
    assert J is not None
    for k in range(10):
        ref = _central(lambda x: output_residual(runs, x, offset, math.inf), xi, k)
        assert np.max(np.abs(J[:, k] - ref)) <= 1e-6 * np.max(np.abs(ref)), NAMES[k]


def test_the_least_squares_jacobian_follows_the_parametrisation() -> None:
    """Parameters ``p`` with ``xi = unpack(p)`` affine (ratios to the coefficients, and
    ``xi_S`` moving with a third parameter too, as the bounded refit's growth rate does): the
    Jacobian in ``p`` against central differences in ``p``."""
    runs = _runs()
    sup = np.array([1, 2, 3, 9])

    def unpack(p: np.ndarray) -> np.ndarray:
        xi = FULL.copy()
        xi[sup] = p * FULL[sup]
        xi[1] -= 0.7 * FULL[3] * (p[2] - 1.0)
        return xi

    jac = least_squares_jacobian(runs, True, math.inf, unpack, sup.size)
    assert callable(jac)
    p = np.array([1.02, 0.97, 1.01, 1.05])
    got = jac(p)
    for j in range(p.size):
        ref = _central(lambda q: output_residual(runs, unpack(q), True, math.inf), p, j)
        assert np.max(np.abs(got[:, j] - ref)) <= 1e-6 * np.max(np.abs(ref))


def test_a_run_that_leaves_its_limit_and_comes_back() -> None:
    """Clipped at each step, a run can come back from its limit: from there its sensitivities
    start again from zero (the clipped value does not move with the coefficients); a kernel
    that carried them through the clip would be wrong after the first return."""
    xi = _only(**{"S": -50.0, "V": 50.0})
    v = _drive(bias=0.0)
    y, J = free_run_sensitivities(xi, v, RATE, 0.0, limit_ue=20.0)
    held = np.abs(y) == 20.0
    assert np.sum(np.diff(held.astype(int)) == -1) >= 3  # leaves the limit several times
    for k in (1, 2):
        ref = _central(lambda x: free_run_numpy(x, v, RATE, 0.0, 20.0), xi, k)
        assert np.max(np.abs(J[:, k] - ref)) <= 1e-6 * np.max(np.abs(ref)), NAMES[k]


def test_no_stable_root_with_a_negative_lag_has_no_gradient() -> None:
    """``1 - S + S|S|``: ``b < 0`` yet no stable rest (the start is 0, fixed); only the check
    that the start solves the rest equation tells."""
    xi = _only(**{"1": 1.0, "S": -1.0, "S|S|": 1.0})
    assert equilibrium(xi, 0.0) == 0.0
    assert not equilibrium_gradient(xi, 0.0).any()


def test_the_series_branch_under_a_large_forcing() -> None:
    """``|z| < 1e-3`` everywhere with a forcing large against the lag, so the series
    derivatives ``phi1'``, ``phi2'`` weigh in every column."""
    xi = _only(**{"1": 200.0, "S": -0.5, "V": 20.0, "V'": 3.0, "V' S": 1e-4})
    v = _drive(bias=0.0)
    _, J = free_run_sensitivities(xi, v, RATE, 0.0)
    for k in np.flatnonzero(xi):
        ref = _central(lambda x: free_run_numpy(x, v, RATE, 0.0), xi, int(k))
        assert np.max(np.abs(J[:, k] - ref)) <= 1e-6 * np.max(np.abs(ref)), NAMES[k]


def test_the_kernel_needs_the_ten_coefficients() -> None:
    """The compiled kernel writes one column per coefficient into a ten-column array (numba
    does not check bounds): any other count is refused before it runs."""
    vp = np.concatenate(([0.0], _drive()))
    for n in (9, 11):
        with pytest.raises(ValueError, match="10 coefficients"):
            sindy_free_run_sensitivities(np.zeros(n), vp, RATE, 0.0, np.zeros(n), math.inf)
