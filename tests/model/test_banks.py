"""The relaxor banks: the compiled recursion, several inputs and outputs in one pass, and the
accuracy of the pole-corrected trapezoidal quadrature (labrig.model.diffusive).

References: the numpy block realisation (``engine="numpy"``) and :class:`BankStepper` (a plain
per-sample loop) for the recursion; the ``exact`` method (closed-form kernel by FFT, checked
against mpmath in ``test_relaxor.py``) for the quadrature. Full scale is 1 (unit steps) or
100 V (the sweeps).
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.model import Relaxor
from labrig.model.accel import kernels
from labrig.model.diffusive import lattice
from labrig.model.modal import BankStepper, DiscreteBank, run_bank, run_bank_multi

from reference.signals import unipolar_sweep

PAPER = [(15.5e-5, 0.15, "zoh"), (2e-3, 1.35, "linear")]
needs_numba = pytest.mark.skipif(kernels() is None, reason="numba is not installed")


@needs_numba
@pytest.mark.parametrize("hold", ["zoh", "linear"])
@pytest.mark.parametrize(("tau", "lam"), [(15.5e-5, 0.15), (2e-3, 1.35), (1e-3, 0.97), (1e3, 0.02)])
def test_compiled_bank_equals_numpy_blocks(tau: float, lam: float, hold: str) -> None:
    bank = Relaxor(tau, lam).bank(1e3, hold)
    v = unipolar_sweep(30_001, 1e3, 0.1, 200.0)
    y1, s1 = run_bank(bank, v, engine="compiled")
    y0, s0 = run_bank(bank, v, engine="numpy")
    # the same recursion in another order: rounding only (1e-12 of the 100 V full scale)
    np.testing.assert_allclose(y1, y0, rtol=0, atol=1e-12 * 100)
    # streamed in uneven blocks, carrying state and the last input
    state, up, parts = None, 0.0, []
    for b in np.split(v, [1, 2, 7, 1000, 1003, 17_000]):
        yb, state = run_bank(bank, b, state, up, engine="compiled")
        up = float(b[-1]) if b.size else up
        parts.append(yb)
    np.testing.assert_allclose(np.concatenate(parts), y0, rtol=0, atol=1e-12 * 100)
    # the final states agree too (states of the slowest modes grow like the input's integral)
    for a, b in zip(s1, s0, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.max(np.abs(b)))


def _tiny_parts(state) -> int:
    """How many parts (real, imaginary) of the arrays in ``state`` are nonzero and under
    1e-200 in magnitude."""
    x = np.concatenate([np.ravel(np.asarray(g)).astype(complex) for g in state])
    parts = np.abs(np.concatenate([x.real, x.imag]))
    return int(np.sum((parts > 0) & (parts < 1e-200)))


@needs_numba
@pytest.mark.parametrize("hold", ["zoh", "linear"])
@pytest.mark.parametrize(("tau", "lam"), [(15.5e-5, 0.15), (2e-3, 1.35), (1e3, 0.02)])
def test_a_rest_leaves_no_subnormal_state(tau: float, lam: float, hold: str) -> None:
    # a drive, then 30 s at exactly 0 V: the modes decay through the rest, and a mode whose
    # state reaches the subnormal range stays there for thousands of samples (slow arithmetic).
    # The compiled banks set a state under TINY_STATE to 0 every 64 samples; the numpy path,
    # which does not, shows that this input gets there
    from labrig.model.compiled import TINY_STATE  # imports numba

    bank = Relaxor(tau, lam).bank(1e3, hold)
    v = np.concatenate([unipolar_sweep(3000, 1e3, 10.0, 100.0), np.zeros(30_000)])
    y1, s1 = run_bank(bank, v, engine="compiled")
    y0, s0 = run_bank(bank, v, engine="numpy")
    np.testing.assert_allclose(y1, y0, rtol=0, atol=1e-12 * 100)

    assert TINY_STATE == 1e-200  # the bound _tiny_parts counts under
    assert _tiny_parts(s0) > 0
    assert _tiny_parts(s1) == 0


@needs_numba
def test_short_calls_flush_too() -> None:
    # the flush counts the samples of each call; a stream of calls shorter than 64 samples
    # (a live view's frames) is flushed at the end of each call: the banks through run_bank,
    # and the fused model through ModelStream. The numpy path, which never flushes, shows that
    # this input takes the paper's G_t bank into the subnormal range
    from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, ModelStream

    v = np.concatenate([unipolar_sweep(3000, 1e3, 10.0, 100.0), np.zeros(30_000)])
    chunks = np.split(v, np.arange(50, v.size, 50))
    model = DynamicHysteresisModel(PAPER_TABLE1)
    bank = model.g_t.bank(1e3, "zoh")
    _, reference = run_bank(bank, v, engine="numpy")
    assert _tiny_parts(reference) > 0
    state, up = None, 0.0
    for c in chunks:
        _, state = run_bank(bank, c, state, up, engine="compiled")
        up = float(c[-1])
    assert _tiny_parts(state) == 0
    fused = ModelStream(model, 1e3)
    for c in chunks:
        fused.process(c)
    assert _tiny_parts([fused._bt[5], fused._bt[6], fused._bd[5], fused._bd[6]]) == 0


@needs_numba
def test_a_nan_input_is_not_flushed_away() -> None:
    # a NaN in the input makes every later output NaN (the states carry it; the numpy path's
    # blocks make all of them NaN): the compiled banks' flush of tiny states, every 64 samples,
    # must not set a NaN state to 0 and hand finite outputs back after it
    bank = Relaxor(2e-3, 1.35).bank(1e3, "linear")
    v = np.full(300, 50.0)
    v[10] = np.nan
    y1, _ = run_bank(bank, v, engine="compiled")
    y0, _ = run_bank(bank, v, engine="numpy")
    assert np.all(np.isnan(y0[10:]))
    assert np.all(np.isfinite(y1[:10])) and np.all(np.isnan(y1[10:]))


def test_run_bank_multi_against_a_plain_loop() -> None:
    # columns and output rows against BankStepper, an independent per-sample loop: the rows'
    # weights are put into banks of their own
    r = Relaxor(2e-3, 1.35)
    modes = r.modes(1e3)
    a = np.exp(modes.q * 1e-3)
    bank = modes.discretise(1e-3, "linear")
    rng = np.random.default_rng(3)
    extra = rng.standard_normal((2, bank.size)) + 1j * rng.standard_normal((2, bank.size))
    u = rng.standard_normal((500, 3)).cumsum(axis=0)
    for engine in ["numpy", "compiled"] if kernels() is not None else ["numpy"]:
        y, _ = run_bank_multi(bank, u, extra, engine=engine)
        assert y.shape == (500, 3, 3)
        groups = bank.groups
        for q in range(3):
            if q == 0:
                b = bank
            else:
                cs = [extra[q - 1][idx] for idx in bank.order]
                cs = [
                    c if np.iscomplexobj(g.a) else c.real for g, c in zip(groups, cs, strict=True)
                ]
                b = DiscreteBank.from_arrays(
                    *(np.concatenate([getattr(g, f) for g in groups]) for f in ("a", "b0", "b1")),
                    np.concatenate(cs),
                )
            for j in range(3):
                st = BankStepper(b)
                want = np.array([st.step(float(x)) for x in u[:, j]])
                np.testing.assert_allclose(y[:, j, q], want, rtol=1e-10, atol=1e-10)
    assert a.size == modes.q.size  # (the bank has one more mode: the instantaneous gain)


def test_run_bank_multi_rejects_bad_shapes() -> None:
    bank = Relaxor(1e-3, 0.5).bank(1e3)
    with pytest.raises(ValueError, match=r"shape \(N, k\)"):
        run_bank_multi(bank, np.ones(5))
    with pytest.raises(ValueError, match="columns"):
        run_bank_multi(bank, np.ones((5, 1)), np.ones((1, bank.size + 1)))


# -- the quadrature ----------------------------------------------------------------------------

LAMS = (0.1, 0.15, 0.3, 0.5, 0.8, 0.95, 0.999, 1.001, 1.05, 1.2, 1.5, 1.8)
STEP_TOL = {"zoh": 1e-12, "linear": 1e-11}  # the exact linear-hold kernel itself is ~3e-12


@pytest.mark.parametrize("hold", ["zoh", "linear"])
@pytest.mark.parametrize("lam", LAMS)
def test_bank_matches_exact_on_a_step(lam: float, hold: str) -> None:
    # stated accuracy (relaxor.py, docs/model.md): ~1e-13 of full scale for every order,
    # through lam = 1, with ~80 modes at 1 kHz; checked here on a unit step (full scale 1)
    r = Relaxor(1e-3, lam)
    n = 20_000
    fast = r.filter(np.ones(n), 1e3, method="fast", hold=hold)
    exact = r.filter(np.ones(n), 1e3, method="exact", hold=hold)
    assert np.max(np.abs(fast - exact)) <= STEP_TOL[hold]
    assert r.bank(1e3, hold).size <= 83


@pytest.mark.parametrize("hold", ["zoh", "linear"])
@pytest.mark.parametrize(("tau", "lam"), [(15.5e-5, 0.15), (2e-3, 1.35)])
def test_paper_relaxors_on_the_sweep(tau: float, lam: float, hold: str) -> None:
    # zoh: 1e-13 of the 100 V full scale (measured 3e-14, 6e-14; the previous bank of 285
    # modes was 6e-11 off for G_d). The exact linear-hold kernel (differences of interval
    # means) carries ~1e-11 of its own on this drive, the same against the previous bank.
    r = Relaxor(tau, lam)
    v = unipolar_sweep(100_000, 1e3, 0.1, 200.0)
    err = np.max(np.abs(r.filter(v, 1e3, "fast", hold) - r.filter(v, 1e3, "exact", hold)))
    assert err <= (1e-13 if hold == "zoh" else 2e-11) * 100


@pytest.mark.slow
@pytest.mark.parametrize("rate", [1e3, 1e4])
@pytest.mark.parametrize("lam", LAMS)
def test_bank_accuracy_long_records(lam: float, rate: float) -> None:
    # 1e6 samples (the slow modes' horizon matters) at 1 and 10 kHz, both holds
    r = Relaxor(1e-3, lam)
    v = unipolar_sweep(1_000_000, rate, 0.01, 0.2 * rate)
    for hold in ("zoh", "linear"):
        err = np.max(np.abs(r.filter(v, rate, "fast", hold) - r.filter(v, rate, "exact", hold)))
        assert err <= 10 * STEP_TOL[hold] * 100


@pytest.mark.parametrize(("tau", "lam"), [(1e3, 0.02), (1e-15, 0.3), (10.0, 0.8), (1e-7, 0.99)])
def test_bank_at_the_fits_bounds(tau: float, lam: float) -> None:
    # the fit's parameter box (analysis/simulate.py): tau_t up to 1e3 s with lam_t down to
    # 0.02, tau down to 1e-15 s (the relaxor is then instantaneous), slow and fast G_d
    r = Relaxor(tau, lam)
    n = 20_000
    err = np.max(np.abs(r.filter(np.ones(n), 1e3, "fast") - r.filter(np.ones(n), 1e3, "exact")))
    assert err <= 1e-12


def test_node_positions_do_not_depend_on_tau_or_lam() -> None:
    # the lattice is fixed for a sample rate: only the weights move with the parameters (the
    # derivatives of filter_sensitivities rely on it); special modes come after it
    lat = lattice(1e-3)
    n = int(np.sum(~lat.fast))
    ref = None
    for tau, lam in [(1e-3, 0.15), (1.0, 0.6), (1e-6, 0.97), (2e-3, 1.35), (1e2, 1.9)]:
        q = Relaxor(tau, lam).modes(1e3).q[:n]
        if ref is None:
            ref = q
        np.testing.assert_array_equal(q, ref)
    np.testing.assert_allclose(-ref.real, np.exp(lat.x[~lat.fast]), rtol=1e-15)


@pytest.mark.parametrize("hold", ["zoh", "linear"])
def test_continuous_through_lam_one(hold: str) -> None:
    # lam = 1 is the single pole 1/(1 + tau s); the bank approaches it from both sides at the
    # rate the relaxor itself does (O(|lam - 1|)), with no jump
    n = 5000
    one = Relaxor(1e-3, 1.0).filter(np.ones(n), 1e3, "fast", hold)
    for d in (1e-3, 1e-5, 1e-7):
        for lam in (1 - d, 1 + d):
            r = Relaxor(1e-3, lam)
            fast = r.filter(np.ones(n), 1e3, "fast", hold)
            exact = r.filter(np.ones(n), 1e3, "exact", hold)
            assert np.max(np.abs(fast - exact)) <= 1e-9  # rounding grows like eps / |lam - 1|
            assert np.max(np.abs(fast - one)) <= 5 * d


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize(
    ("b", "a"),
    [
        ([0.0, 1.0 - 0.999], [1.0, -0.999]),  # thermal_drift's lag of the loss power
        ([1.0 - 0.2 * 0.97, -(1.0 - 0.2) * 0.97], [1.0, -0.97]),  # a Kelvin-Voigt element
        ([3.0], [2.0, -1.0]),  # a[0] != 1, a numerator of one term
    ],
)
def test_first_order_filter_is_lfilter(
    b: list[float], a: list[float], engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """:func:`labrig.model.modal.first_order_filter` against ``scipy.signal.lfilter`` (the
    reference) on 20 000 samples of a 100 V sweep with noise: 1e-12 of full scale, on either
    engine (the compiled one when the kernels are loaded)."""
    from scipy.signal import lfilter

    import labrig.model.modal as modal

    if engine == "compiled" and kernels() is None:
        pytest.skip("numba is not installed")
    monkeypatch.setattr(modal, "stream_engine", lambda: engine)
    x = unipolar_sweep(20_000, 1e3, 5.0, 100.0)
    x = x + np.random.default_rng(3).normal(0.0, 0.5, x.size)
    want = lfilter(b, a, x)
    got = modal.first_order_filter(b, a, x)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(want)))


def test_first_order_filter_refuses_what_is_not_first_order() -> None:
    from labrig.model.modal import first_order_filter

    for b, a in (([1.0, 0.0, 0.0], [1.0, -0.5]), ([1.0], [1.0, -0.5, 0.1]), ([1.0], [0.0, 1.0])):
        with pytest.raises(ValueError, match="first-order"):
            first_order_filter(b, a, np.ones(4))
