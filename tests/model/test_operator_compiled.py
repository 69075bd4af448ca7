"""The compiled hysteresis operator and the operator's sensitivities.

References: the numpy operator (``engine="numpy"``: the vectorised branch search, itself checked
against numerical integration in ``test_hysteresis.py``), central differences of ``apply``, and
the numpy ``tangent``. Inputs: random multi-reversal records (hypothesis) and adversarial ones
(tiny wiggles, exactly repeated extrema, flat stretches, deep nested loops, long noisy records,
streaming splits). Tolerance of compiled against numpy: 1e-12 of full scale (the same closed
forms; the compiled exponential branch uses ``exp(-x/vc) - 1`` where numpy uses ``expm1``, which
moves the strain by ~1e-13 ue).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from labrig.model import HysteresisState, QuasiStaticHysteresis, Shape
from labrig.model.accel import kernels

from reference.hysteresis_ref import polyline

SHAPES = {"exponential": 7.8, "linear": 0.12, "gaussian": 7.8}  # gamma (ue/V or ue/V^2)
MEMORIES = ("return_point", "last_reversal", "return_point_open")
REL = 1e-12  # of full scale

pytestmark = pytest.mark.skipif(kernels() is None, reason="numba is not installed")


def op_for(shape: str, memory: str) -> QuasiStaticHysteresis:
    return QuasiStaticHysteresis(8.9, SHAPES[shape], 65.0, shape, memory)


def assert_close(a: np.ndarray, b: np.ndarray, rel: float = REL) -> None:
    scale = max(1.0, float(np.max(np.abs(b), initial=0.0)))
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * scale)


def assert_states_close(s1: HysteresisState, s2: HysteresisState, scale: float) -> None:
    assert len(s1.older) == len(s2.older)
    a = np.array([*s1.older, (s1.u_s, s1.s_s), (s1.u_last, s1.s_last)])
    b = np.array([*s2.older, (s2.u_s, s2.s_s), (s2.u_last, s2.s_last)])
    np.testing.assert_allclose(a, b, rtol=0, atol=REL * max(1.0, scale))
    assert s1.direction == s2.direction


@st.composite
def records(draw) -> np.ndarray:
    """Multi-reversal polylines on a 1 mV grid, with flat stretches, exact repeats of earlier
    extrema and tiny wiggles (1e-9 V, 1e-6 V) spliced in."""
    turns = draw(
        st.lists(st.integers(-30_000, 120_000).map(lambda k: k / 1000.0), min_size=1, max_size=12)
    )
    if len(turns) > 2 and draw(st.booleans()):  # return exactly to an earlier extremum
        i = draw(st.integers(0, len(turns) - 2))
        turns.insert(draw(st.integers(i + 1, len(turns))), turns[i])
    counts = draw(st.lists(st.integers(1, 25), min_size=len(turns), max_size=len(turns)))
    u = polyline(turns, counts)
    for _ in range(draw(st.integers(0, 3))):
        k = draw(st.integers(0, u.size - 1))
        kind = draw(st.sampled_from(["flat", "wiggle9", "wiggle6"]))
        if kind == "flat":
            u = np.r_[u[: k + 1], np.full(draw(st.integers(1, 5)), u[k]), u[k + 1 :]]
        else:
            e = 1e-9 if kind == "wiggle9" else 1e-6
            u = np.r_[u[: k + 1], u[k] + e, u[k] - e, u[k], u[k + 1 :]]
    return u


#: 8 random records per shape and memory rule (72 per property) in the default tier, 40 each
#: (360) in the slow twins
HYP = settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
HYP_LONG = settings(HYP, max_examples=40)


def _check_compiled_equals_numpy(shape: str, memory: str, u: np.ndarray, held: float, data):
    op = op_for(shape, memory)
    ref = op.apply(u, op.held_state(held), engine="numpy")
    assert_close(op.apply(u, op.held_state(held), engine="compiled"), ref)
    # streamed in any split, the strain and the memory carried between blocks agree
    cuts = sorted(data.draw(st.lists(st.integers(0, u.size), max_size=5), label="cuts"))
    s1, s2 = op.held_state(held), op.held_state(held)
    p1 = [op.apply(b, s1, engine="compiled") for b in np.split(u, cuts)]
    p2 = [op.apply(b, s2, engine="numpy") for b in np.split(u, cuts)]
    assert_close(np.concatenate(p1), np.concatenate(p2))
    assert_close(np.concatenate(p1), ref)
    assert_states_close(s1, s2, float(np.max(np.abs(ref))))


@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
@HYP
@given(u=records(), held=st.sampled_from([0.0, 35.0, -12.5]), data=st.data())
def test_compiled_equals_numpy(shape: str, memory: str, u: np.ndarray, held: float, data) -> None:
    _check_compiled_equals_numpy(shape, memory, u, held, data)


@pytest.mark.slow
@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
@HYP_LONG
@given(u=records(), held=st.sampled_from([0.0, 35.0, -12.5]), data=st.data())
def test_compiled_equals_numpy_many(shape: str, memory: str, u: np.ndarray, held: float, data):
    """Compiled against numpy on five times as many random records.

    Fast equivalent in the default tier: tests/model/test_operator_compiled.py::test_compiled_equals_numpy
    """  # noqa: E501
    _check_compiled_equals_numpy(shape, memory, u, held, data)


@pytest.mark.parametrize("memory", MEMORIES)
def test_adversarial_records(memory: str) -> None:
    op = op_for("exponential", memory)
    rng = np.random.default_rng(2)
    t = np.arange(20_000)
    cases = {
        # a clipped drive: every cycle reaches exactly the same extrema
        "repeated extrema": np.clip(60 * np.sin(2 * np.pi * t / 100), 0, 50),
        # a vanishing envelope: thousands of nested minor loops (the stack grows past its
        # first allocation of 64 turning points)
        "nested loops": 50 + 50 * np.cos(np.pi * t / 3) * np.exp(-t / 8000),
        # noise: a turning point every other sample, loops closing at every scale
        "noise": np.cumsum(rng.standard_normal(t.size)),
        # wiggles far below the input's scale, on a slow ramp with holds
        "tiny wiggles": np.repeat(np.linspace(0, 100, 2000), 10)
        + 1e-9 * rng.standard_normal(t.size),
        "constant": np.full(t.size, 42.0),
    }  # fmt: skip
    for name, u in cases.items():
        ref = op.apply(u, engine="numpy")
        got = op.apply(u, engine="compiled")
        assert_close(got, ref), name
        s1, s2 = HysteresisState(), HysteresisState()
        op.apply(u, s1, engine="compiled")
        op.apply(u, s2, engine="numpy")
        assert_states_close(s1, s2, float(np.max(np.abs(ref))))
    if memory == "return_point":  # the nested loops really are nested (the growth is tested)
        s = HysteresisState()
        op.apply(cases["nested loops"][:10_000], s, engine="compiled")
        assert len(s.older) > 1000


def test_huge_record() -> None:
    # 1e6 samples with a turning point every ~2 samples: same strain as numpy
    op = op_for("exponential", "return_point")
    u = 50 + np.cumsum(np.random.default_rng(4).standard_normal(1_000_000)) * 0.05
    assert_close(op.apply(u, engine="compiled"), op.apply(u, engine="numpy"))


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_refused(engine: str, bad: float) -> None:
    op = op_for("exponential", "return_point")
    state = op.held_state(10.0)
    before = (list(state.older), state.u_s, state.s_s, state.u_last, state.direction)
    with pytest.raises(ValueError, match="finite"):
        op.apply(np.array([1.0, bad, 2.0]), state, engine=engine)
    assert (state.older, state.u_s, state.s_s, state.u_last, state.direction) == before
    with pytest.raises(ValueError, match="finite"):
        op.sensitivities(np.array([1.0, bad]), engine=engine)


def test_engine_choice() -> None:
    user = QuasiStaticHysteresis(
        8.9, 7.8, 30.0, Shape("rational", lambda x, g, v: g * x * x / (x * x + v * v))
    )
    u = polyline([80, 20, 60], [30, 30, 30])
    with pytest.raises(ValueError, match="user shape"):
        user.apply(u, engine="compiled")
    with pytest.raises(ValueError, match="engine"):
        op_for("linear", "return_point").apply(u, engine="fast")
    # "auto" runs numpy for a user shape, the kernel for a builtin one
    np.testing.assert_array_equal(user.apply(u), user.apply(u, engine="numpy"))
    op = op_for("gaussian", "return_point")
    np.testing.assert_array_equal(op.apply(u), op.apply(u, engine="compiled"))  # fmt: skip


# -- sensitivities ---------------------------------------------------------------------------


def _smooth(n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / 1000.0
    x = 5 + 50 * (1 - np.cos(2 * np.pi * t)) * (1 + 0.3 * np.sin(7 * t)) + 2 * np.sin(1.3 * t)
    return x, np.column_stack([np.sin(3 * t) + 0.5, np.cos(11 * t), np.ones(n)])


def _param_fd(op: QuasiStaticHysteresis, u: np.ndarray, held: float) -> np.ndarray:
    """Central differences of ``apply`` in alpha0, gamma, vc (4th order, relative step 1e-3).
    The turning points are samples of ``u``, so the structure never moves with the parameters.
    """
    cols = []
    for name in ("alpha0", "gamma", "vc"):
        p = {"alpha0": op.alpha0, "gamma": op.gamma, "vc": op.vc}
        e = 1e-3 * max(abs(p[name]), 1e-3)

        def s(k: float, name: str = name, p: dict = p, e: float = e) -> np.ndarray:
            q = QuasiStaticHysteresis(
                **{**p, name: p[name] + k * e}, shape=op.shape, memory=op.memory
            )
            return q.apply(u, q.held_state(held), engine="numpy")

        cols.append((8 * (s(1) - s(-1)) - (s(2) - s(-2))) / (12 * e))
    return np.column_stack(cols)


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
def test_parameter_derivatives_match_differences(shape: str, memory: str, engine: str) -> None:
    op = op_for(shape, memory)
    u = polyline(
        [80, 20, 100, 0, 60, 40, 90, -20, 95, 55, 70, 10],
        [40, 33, 55, 60, 37, 11, 31, 49, 57, 23, 9, 41],
    )
    for held in (0.0, 30.0):
        S, dP, _ = op.sensitivities(u, held, engine=engine)
        np.testing.assert_array_equal(S, op.apply(u, op.held_state(held), engine=engine))
        fd = _param_fd(op, u, held)
        # 4th-order differences: truncation ~1e-12, rounding ~1e-13 relative to the column
        for j in range(3):
            scale = max(1e-12, float(np.max(np.abs(fd[:, j]))))
            np.testing.assert_allclose(dP[:, j], fd[:, j], rtol=0, atol=1e-8 * scale)
    if shape == "linear":
        assert np.all(dP[:, 2] == 0.0)
    else:  # vc matters: the column is not trivially zero
        assert np.max(np.abs(dP[:, 2])) > 1.0


def _check_sensitivities(shape: str, memory: str, u: np.ndarray, held: float, seed: int):
    op = op_for(shape, memory)
    du = np.random.default_rng(seed).standard_normal((u.size, 3))
    S1, P1, U1 = op.sensitivities(u, held, du, engine="compiled")
    S2, P2, U2 = op.sensitivities(u, held, du, engine="numpy")
    assert_close(S1, S2)
    for j in range(3):
        assert_close(P1[:, j], P2[:, j])
        assert_close(U1[:, j], U2[:, j])
        # each column is what tangent computes for it (numpy reference)
        assert_close(U1[:, j], op.tangent(u, du[:, j], held, engine="numpy"))


@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
@HYP
@given(u=records(), held=st.sampled_from([0.0, 35.0]), seed=st.integers(0, 2**16))
def test_sensitivities_compiled_equal_numpy_and_tangent(shape, memory, u, held, seed) -> None:
    _check_sensitivities(shape, memory, u, held, seed)


@pytest.mark.slow
@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
@HYP_LONG
@given(u=records(), held=st.sampled_from([0.0, 35.0]), seed=st.integers(0, 2**16))
def test_sensitivities_compiled_equal_numpy_and_tangent_many(shape, memory, u, held, seed):
    """The sensitivities on five times as many random records.

    Fast equivalent in the default tier: tests/model/test_operator_compiled.py::test_sensitivities_compiled_equal_numpy_and_tangent
    """  # noqa: E501
    _check_sensitivities(shape, memory, u, held, seed)


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
@pytest.mark.parametrize("memory", MEMORIES)
def test_input_derivatives_match_differences(memory: str, engine: str) -> None:
    # a perturbation that keeps the structure (smooth, extrema unequal from cycle to cycle):
    # the tangent is the derivative of apply itself
    op = op_for("exponential", memory)
    x, du = _smooth()
    _, _, dU = op.sensitivities(x, 7.0, du, params=False, engine=engine)
    h = 1e-5
    for j in range(du.shape[1]):
        sp = op.apply(x + h * du[:, j], op.held_state(7.0), engine="numpy")
        sm = op.apply(x - h * du[:, j], op.held_state(7.0), engine="numpy")
        np.testing.assert_allclose(dU[:, j], (sp - sm) / (2 * h), rtol=0, atol=1e-5)
    # the held voltage does not move: x starts below it, so 7 V is a turning point whose
    # derivative is 0, and the first sample's derivative is the slope from there times du
    assert x[0] < 7.0
    np.testing.assert_allclose(dU[0], op.slope(7.0 - x[0]) * du[0], rtol=1e-14)
    one = op.sensitivities(x, 7.0, du[:, 0], engine=engine)[2]
    assert one.shape == x.shape
    np.testing.assert_array_equal(one, dU[:, 0])


def test_user_shape_sensitivities() -> None:
    # a user shape without derivatives: central differences of its integral; with them stated:
    # the closed forms. Both against differences of apply.
    def h(x, g, v):
        return g * x * x / (x * x + v * v)

    def dh_dg(x, g, v):  # H/g: int_0^x y^2/(y^2+v^2) = x - v atan(x/v)
        return x - v * np.arctan(x / v)

    def dh_dv(x, g, v):
        return g * (x / v / (1 + (x / v) ** 2) - np.arctan(x / v))

    u = polyline([80, 20, 100, 0, 60, 40, 90], [40, 33, 55, 60, 37, 11, 31])
    for shape in (Shape("r", h), Shape("r", h, None, dh_dg, dh_dv)):
        op = QuasiStaticHysteresis(8.9, 7.8, 30.0, shape)
        _, dP, _ = op.sensitivities(u, 0.0)
        fd = _param_fd(op, u, 0.0)
        for j in range(3):
            np.testing.assert_allclose(
                dP[:, j], fd[:, j], rtol=0, atol=1e-7 * np.max(np.abs(fd[:, j]))
            )


def test_sensitivities_reject_bad_du() -> None:
    op = op_for("exponential", "return_point")
    with pytest.raises(ValueError, match="du must have shape"):
        op.sensitivities(np.ones(5), 0.0, np.ones((4, 2)))


# -- without numba ---------------------------------------------------------------------------

HIDDEN = """
import sys, warnings
sys.modules["numba"] = None  # import numba -> ImportError
import numpy as np
from labrig.model import DynamicHysteresisModel, PAPER_TABLE1, QuasiStaticHysteresis
op = QuasiStaticHysteresis(8.9, 7.8, 65.0)
u = 50 * (1 - np.cos(np.arange(3000) / 50.0)) * np.exp(-np.arange(3000) / 2000.0)
with warnings.catch_warnings(record=True) as w:
    warnings.simplefilter("always")
    a = op.apply(u)
    b = op.apply(u)
    s, dp, du = op.sensitivities(u, 0.0, np.ones((u.size, 1)))
    y = DynamicHysteresisModel(PAPER_TABLE1).predict(u, 1000.0)
print(len([x for x in w if "numba is not available" in str(x.message)]))
np.save(sys.argv[1], np.concatenate([a, s, dp.ravel(), du.ravel(), y]))
"""


def test_numba_hidden_in_process(monkeypatch: pytest.MonkeyPatch) -> None:
    # the fast equivalent of the subprocess test below: numba's import fails, the loader warns
    # once and every "auto" call runs the numpy code
    from labrig.model import Relaxor, accel
    from labrig.model.modal import run_bank

    op = QuasiStaticHysteresis(8.9, 7.8, 65.0)
    u = 50 * (1 - np.cos(np.arange(3000) / 50.0))
    bank = Relaxor(2e-3, 1.35).bank(1e3, "linear")
    monkeypatch.setitem(sys.modules, "numba", None)
    accel.reset()
    try:
        with pytest.warns(RuntimeWarning, match="numba is not available"):
            assert accel.kernels() is None
        np.testing.assert_array_equal(op.apply(u), op.apply(u, engine="numpy"))
        np.testing.assert_array_equal(run_bank(bank, u)[0], run_bank(bank, u, engine="numpy")[0])
        with pytest.raises(RuntimeError, match="needs numba"):
            op.apply(u, engine="compiled")
        with pytest.raises(RuntimeError, match="needs numba"):
            run_bank(bank, u, engine="compiled")
    finally:
        monkeypatch.undo()
        accel.reset()
    assert accel.kernels() is not None


@pytest.mark.slow
def test_numba_hidden_falls_back_to_numpy(tmp_path) -> None:
    out = tmp_path / "hidden.npy"
    env = {**os.environ, "PYTHONWARNINGS": "default"}
    res = subprocess.run(
        [sys.executable, "-c", HIDDEN, str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "1"  # one warning, however many calls
    got = np.load(out)
    from labrig.model import PAPER_TABLE1, DynamicHysteresisModel

    op = QuasiStaticHysteresis(8.9, 7.8, 65.0)
    u = 50 * (1 - np.cos(np.arange(3000) / 50.0)) * np.exp(-np.arange(3000) / 2000.0)
    s, dp, du = op.sensitivities(u, 0.0, np.ones((u.size, 1)), engine="compiled")
    y = DynamicHysteresisModel(PAPER_TABLE1).predict(u, 1000.0)
    want = np.concatenate([op.apply(u, engine="compiled"), s, dp.ravel(), du.ravel(), y])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


# -- the whole fast model in one compiled pass ---------------------------------------------------


def _numpy_predict(model, v: np.ndarray, rate: float, rest: float) -> np.ndarray:
    """The fast model as separate numpy stages (run_bank blocks, the numpy operator)."""
    from labrig.model.modal import run_bank

    bt, bd = model.g_t.bank(rate, "zoh"), model.g_d.bank(rate, "linear")
    vt = run_bank(bt, v - rest, engine="numpy")[0]
    vd = run_bank(bd, vt, engine="numpy")[0] + rest
    op = model.operator
    return op.apply(vd, op.held_state(rest), engine="numpy")


@pytest.mark.parametrize("memory", MEMORIES)
@pytest.mark.parametrize("shape", list(SHAPES))
def test_predict_in_one_pass_equals_the_stages(shape: str, memory: str) -> None:
    from labrig.model import PAPER_TABLE1, DynamicHysteresisModel

    p = PAPER_TABLE1.model_copy(update={"shape": shape, "memory": memory,
                                        "gamma_ue_per_V": SHAPES[shape]})  # fmt: skip
    model = DynamicHysteresisModel(p)
    rng = np.random.default_rng(9)
    t = np.arange(30_001) / 1e3
    v = 50 * (1 - np.cos(2 * np.pi * 7 * t)) * np.exp(-t / 10) + rng.standard_normal(t.size)
    for rest in (0.0, -20.0):
        want = _numpy_predict(model, v + rest, 1e3, rest)
        assert_close(model.predict(v + rest, 1e3, rest_V=rest), want)
    # streamed in uneven blocks (chunk edges of the kernel: 4096 samples) with the memory
    # carried between them
    stream = model.stream(1e3)
    cuts = [1, 5, 4096, 4100, 9000, 20_000]
    parts = [stream.process(b) for b in np.split(v, cuts)]
    assert_close(np.concatenate(parts), _numpy_predict(model, v, 1e3, 0.0))
    with pytest.raises(ValueError, match="finite"):
        model.predict(np.array([1.0, np.nan]), 1e3)
