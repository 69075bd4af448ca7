"""The compiled fast model (``compiled.model_run``: both relaxor banks and the operator fused in
one loop over blocks of eight samples) and the compact banks it runs (``modal.compact_form``).

References, independent of the fused loop: the numpy stages, each bank run by the numpy block
realisation (BLAS products, the full bank as :meth:`Relaxor.bank` builds it) and then the numpy
operator (the vectorised branch search); and the ``exact`` method (closed-form kernels by FFT).
Full scale is the largest strain of the reference record.
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, ModelParams
from labrig.model.accel import kernels
from labrig.model.modal import (
    COMPACT_TOL,
    MODE_PAD,
    DiscreteBank,
    compact_form,
    run_bank,
    scaled_form,
)

from reference.signals import unipolar_sweep

RATE = 1e3
needs_numba = pytest.mark.skipif(kernels() is None, reason="numba is not installed")


def _numpy_stages(model: DynamicHysteresisModel, v: np.ndarray, rest: float) -> np.ndarray:
    """``predict``'s maths by the numpy code: full banks by blocks, then the numpy operator."""
    bt, bd = model.g_t.bank(RATE, "zoh"), model.g_d.bank(RATE, "linear")
    vt = run_bank(bt, v - rest, engine="numpy")[0]
    vd = rest + run_bank(bd, vt, engine="numpy")[0]
    op = model.operator
    return op.apply(vd, op.held_state(rest), engine="numpy")


def _shrinking_oscillation(n: int) -> np.ndarray:
    """50 V +- a decaying 30 Hz oscillation: every reversal is a turning point inside the last
    loop, so return-point memory keeps them all (the stack passes 64 and must grow)."""
    t = np.arange(n) / RATE
    return 50.0 + 40.0 * np.exp(-t / 2.0) * np.sin(2 * np.pi * 30.0 * t)


@needs_numba
@pytest.mark.parametrize("memory", ["return_point", "return_point_open", "last_reversal"])
@pytest.mark.parametrize("shape", ["exponential", "linear", "gaussian"])
@pytest.mark.parametrize(("n", "rest"), [(20_003, 0.0), (4_101, 30.0), (7, 10.0)])
def test_fused_predict_equals_the_numpy_stages(
    shape: str, memory: str, n: int, rest: float
) -> None:
    # lengths not a multiple of 8 (the per-sample tail), a held start, every shape and memory
    params = ModelParams(**{**PAPER_TABLE1.model_dump(), "shape": shape, "memory": memory})
    model = DynamicHysteresisModel(params)
    v = unipolar_sweep(n, RATE, 0.2, 60.0, seed=n) if n > 8 else np.linspace(0, 80, n)
    got = model.predict(v, RATE, rest_V=rest)
    want = _numpy_stages(model, v, rest)
    # compact banks (dropped modes <= 1e-15 of full scale) and regrouped sums: 1e-12 of it
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(want)))


@needs_numba
def test_fused_predict_grows_the_turning_point_stack() -> None:
    model = DynamicHysteresisModel(PAPER_TABLE1)
    v = _shrinking_oscillation(12_000)
    vd = model.equivalent_static_voltage(v, RATE)
    reversals = np.count_nonzero(np.diff(np.sign(np.diff(vd))))
    assert reversals > 200  # far more turning points than the initial stack's 64 rows
    want = _numpy_stages(model, v, 0.0)
    got = model.predict(v, RATE)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(want)))
    # and streamed in blocks that end mid-block of eight, carrying the memory across calls
    stream = model.stream(RATE)
    parts = [stream.process(b) for b in np.split(v, [5, 13, 4_000, 4_003, 9_999])]
    np.testing.assert_allclose(np.concatenate(parts), got, rtol=0, atol=1e-9)


@needs_numba
def test_fast_agrees_with_exact_to_1e12_of_full_scale() -> None:
    # the stated accuracy of the banks (~1e-13 of full scale against the exact kernels) carries
    # through the operator, whose slope is at most alpha0 + gamma: 1e-12 of the strain's scale
    model = DynamicHysteresisModel(PAPER_TABLE1)
    v = unipolar_sweep(30_000, RATE, 0.2, 40.0, seed=3)
    fast = model.predict(v, RATE, method="fast")
    exact = model.predict(v, RATE, method="exact")
    np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-12 * np.max(np.abs(exact)))


# -- compact_form ----------------------------------------------------------------------------------


def _bank_output(form: tuple, u: np.ndarray) -> np.ndarray:
    """A plain per-sample loop over the compiled kernels' form ``(a, cw, feed, ca, ccw)``:
    ``w[n] = a w[n-1] + u[n-1]``, ``y[n] = sum cw w[n] + Re sum ccw wc[n] + feed u[n]``."""
    a, cw, feed, ca, ccw = form
    w = np.zeros(a.size)
    wc = np.zeros(ca.size, dtype=complex)
    up = 0.0
    y = np.empty(u.size)
    for k, x in enumerate(u):
        w = a * w + up
        wc = ca * wc + up
        y[k] = np.sum(cw * w) + np.sum(ccw * wc).real + feed * x
        up = x
    return y


def test_compact_form_merges_equal_poles_and_conjugate_pairs_exactly() -> None:
    a = [0.5, 0.9, 0.5, 1.0, 1.0, 0.6 + 0.3j, 0.6 - 0.3j]
    c = [1.0, -2.0, 0.25, 1e-3, 2e-3, 0.2 - 0.1j, 0.2 + 0.1j]
    bank = DiscreteBank.from_arrays(a, np.ones(7), np.zeros(7), c)
    full = scaled_form(bank)
    small = compact_form(bank)
    assert np.count_nonzero(small[1]) == 3  # 0.5 (twice), 0.9, 1.0 (twice) -> three poles
    assert small[0].size % MODE_PAD == 0
    assert small[3].size == 1  # one mode of the conjugate pair
    u = np.random.default_rng(0).standard_normal(300)
    np.testing.assert_allclose(_bank_output(small, u), _bank_output(full, u), rtol=0, atol=1e-13)


@pytest.mark.parametrize(("scale", "dropped"), [(0.99, True), (1.01, False)])
def test_compact_form_drops_modes_within_the_tolerance_only(scale: float, dropped: bool) -> None:
    # a mode whose worst-case contribution |cw| / (1 - |a|) is just inside (outside) the
    # tolerance is dropped (kept); the output then moves by at most that bound
    a_small = 0.5
    cw_small = scale * COMPACT_TOL * (1.0 - a_small)
    bank = DiscreteBank.from_arrays([0.9, a_small], [1.0, 1.0], [0.0, 0.0], [1.0, cw_small])
    small = compact_form(bank)
    assert bool(np.count_nonzero(small[1]) == 1) is dropped
    u = np.random.default_rng(1).uniform(-1.0, 1.0, 400)
    diff = np.max(np.abs(_bank_output(small, u) - _bank_output(scaled_form(bank), u)))
    assert diff <= scale * COMPACT_TOL * (1 + 1e-9) + 1e-16


@pytest.mark.parametrize(("tau", "lam", "hold"), [(15.5e-5, 0.15, "zoh"), (2e-3, 1.35, "linear")])
def test_compact_paper_banks_are_smaller_and_agree(tau: float, lam: float, hold: str) -> None:
    from labrig.model import Relaxor

    bank = Relaxor(tau, lam).bank(RATE, hold)
    full, small = scaled_form(bank), compact_form(bank)
    assert np.count_nonzero(small[1]) + 2 * small[3].size < full[0].size + 2 * full[3].size
    u = unipolar_sweep(3_000, RATE, 0.5, 40.0)
    np.testing.assert_allclose(
        _bank_output(small, u), _bank_output(full, u), rtol=0, atol=1e-13 * 100
    )


# -- the exact method's compiled interpolant --------------------------------------------------


@needs_numba
@pytest.mark.parametrize("order", ["sorted", "shuffled"])
def test_compiled_chebyshev_sums_equal_numpy_chebval(order: str, monkeypatch) -> None:
    # blocks of eight in one panel run as eight chains, mixed blocks one at a time: both against
    # numpy's chebval per panel (the same recurrence), on times crossing many panels
    import labrig.model.relaxor as relaxor

    interp = relaxor._LogChebyshevStep(2e-3, 1.35, 2.048, 3e3)
    rng = np.random.default_rng(7)
    t = np.sort(10 ** rng.uniform(np.log10(2.048), np.log10(3e3), 5_003))
    if order == "shuffled":
        t = rng.permutation(t)
    got = interp.branch(t)
    monkeypatch.setattr(relaxor, "kernels", lambda: None)
    want = interp.branch(t)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15 * np.max(np.abs(want)))
