"""Baseline hysteresis models fitted on the same data as ours, for comparison.

Both are classical *rate-independent* models driven by the voltage record (they see only the
sequence of voltage values, not the time), written here because no maintained package exists.
Both start from rest at the voltage the record was held at before it
(:attr:`~labrig.analysis.records.Record.rest_V`, 0 V for a run), the convention of our model.

Prandtl-Ishlinskii (PI)
-----------------------
``S(t) = sum_i w_i F_{r_i}[V](t)`` with play (backlash) operators

    y_r[n] = max(V[n] - r, min(V[n] + r, y_r[n-1])),     y_r[-1] = V_rest  (relaxed)

the standard initial-loading convention (every operator relaxed at the start). Thresholds on a
uniform grid ``r_i = R i / n_ops``, ``i = 0..n_ops-1``, with ``R`` the largest ``|V|`` of the
training records (``r_0 = 0`` is the linear term); weights ``w_i >= 0`` (ue/V) by non-negative
least squares (``scipy.optimize.nnls``). The model is linear in the weights, so the fit is exact
and fast. The operators run as the sample recursion above, compiled
(:mod:`labrig.analysis.baseline_kernels`); between reversals of ``V`` it equals the closed form
``max(V - r, y_s)`` (rising) or ``min(V + r, y_s)`` (falling) of :func:`play_operators_numpy`,
the reference. Each segment's weighted rows are reduced once to their QR factor ``(R_g,
Q_g^T b_g)``; a fit (the full one or a held-out fold) stacks the factors of its segments, whose
QR gives the triangular system of all its rows at once.

Bouc-Wen (BW)
-------------
The common piezo form

    S = d V - h,      dh/dt = A V' - beta |V'| |h|^(n-1) h - gamma V' |h|^n      (V' = dV/dt)

(units: ``d, A`` ue/V; ``beta, gamma`` 1/V for ``n = 1``). It is rate independent:
along a run of monotone voltage (direction ``s``, distance ``u = s (V - V_0)``)
``dh/du = s A - beta |h|^(n-1) h - gamma s |h|^n``. For ``n = 1`` (the usual choice for piezo
stacks, and the one fitted) this is linear in ``h`` on each side of ``h = 0``, so each run has a
closed form: ``h = sA/k + (h_0 - sA/k) exp(-k u)`` with ``k = beta - gamma`` while ``h`` is
opposite to the motion and ``k = beta + gamma`` once it has the motion's sign (the crossing of
zero is found in closed form). So ``n = 1`` is integrated exactly, with no step size; other
``n`` use classical RK4 with ``substeps`` per sample interval along ``u`` (checked against the
closed form and by halving the step in the tests). For ``n = 1``, ``h`` is proportional to
``A``, so ``S = d V - A h_1`` with ``h_1`` the response for ``A = 1``: ``d`` and ``A`` are solved
by linear least squares inside a bounded ``least_squares`` over ``beta + gamma > 0`` (log) and
``(beta - gamma) / (beta + gamma) > -1`` (which keeps ``beta > 0``, so ``h`` stays bounded).
The compiled closed form (:func:`labrig.analysis.baseline_kernels.bouc_wen_h1`) also gives the
exact derivatives of ``h_1`` with respect to ``beta + gamma`` and ``beta - gamma``, from which
the Jacobian of the residual (``d`` and ``A`` following the two parameters: variable
projection) is formed; the solver sees the 3-row equivalent of residual and Jacobian
(:class:`_BoucWenFit`). Each held-out fold starts from the full fit's parameters.

SINDy
-----
``kind="sindy"``: a sparse ODE of the strain driven by the voltage, fitted with pysindy and
scored in free run (:mod:`labrig.analysis.sindy`); unlike the two above it depends on the rate.

Objective and scores are those of :mod:`labrig.analysis.fit`: residuals weighted per entry by
``1 / (strain span * sqrt(samples))``, NRMSE per entry and its mean, and the leave-one-entry-out
held-out NRMSE. Without numba the kernels fall back to their NumPy forms, with a warning.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

from labrig.analysis import baseline_kernels as kern
from labrig.analysis.metrics import nrmse_pct, scores_json, second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import (
    CONVERGED,
    Segment,
    SimSequence,
    scored_names,
    scored_sequences,
)
from labrig.analysis.sindy import SindyBaseline, SindyCache, fit_sindy
from labrig.core.blas import single_thread_blas
from labrig.model.bouc_wen import monotone_runs

__all__ = [
    "KINDS",
    "BaselineResult",
    "BoucWen",
    "PrandtlIshlinskii",
    "bouc_wen_response",
    "fit_baseline",
    "play_operator",
    "play_operators",
    "play_operators_numpy",
]

KINDS = ("prandtl_ishlinskii", "bouc_wen", "sindy")


def _with_rest(v: ArrayLike, rest_V: float = 0.0) -> NDArray:
    """The record preceded by the voltage the actuator rested at (0 V for a run)."""
    return np.concatenate(([float(rest_V)], np.asarray(v, dtype=float)))


# -- Prandtl-Ishlinskii ------------------------------------------------------------------------


def play_operators(v: ArrayLike, thresholds: ArrayLike, rest_V: float = 0.0) -> NDArray[np.float64]:
    """Outputs of play operators with the given thresholds (V) for the record ``v``: shape
    ``(len(v), len(thresholds))``, every operator relaxed at ``rest_V`` (the voltage the
    actuator rested at, 0 V for a run) before the record (compiled:
    :func:`labrig.analysis.baseline_kernels.play_operators`)."""
    r = np.asarray(thresholds, dtype=float)
    if np.any(r < 0):
        raise ValueError("play thresholds must be non-negative")
    return kern.play_operators(_with_rest(v, rest_V), r)


def play_operators_numpy(
    v: ArrayLike, thresholds: ArrayLike, rest_V: float = 0.0
) -> NDArray[np.float64]:
    """:func:`play_operators` run by run in NumPy (the reference of the compiled form)."""
    r = np.asarray(thresholds, dtype=float)
    if np.any(r < 0):
        raise ValueError("play thresholds must be non-negative")
    vp = _with_rest(v, rest_V)
    return kern.play_operators_numpy(vp, r, monotone_runs(vp))


def play_operator(v: ArrayLike, r: float) -> NDArray[np.float64]:
    """One play operator of threshold ``r`` (V) (see :func:`play_operators`)."""
    return play_operators(v, [r])[:, 0]


@dataclass(frozen=True)
class PrandtlIshlinskii:
    """``S = sum_i weights[i] * play_{thresholds[i]}[V]`` (weights in ue/V)."""

    thresholds: tuple[float, ...]
    weights: tuple[float, ...]

    def predict(self, v: ArrayLike, rest_V: float = 0.0) -> NDArray[np.float64]:
        return play_operators(v, self.thresholds, rest_V) @ np.asarray(self.weights)

    def params(self) -> dict[str, Any]:
        return {"thresholds_V": list(self.thresholds), "weights_ue_per_V": list(self.weights)}


# -- Bouc-Wen ----------------------------------------------------------------------------------


def _bw_rhs(h: float, s: float, A: float, beta: float, gamma: float, n: float) -> float:
    ah = abs(h)
    return s * A - beta * ah ** (n - 1.0) * h - gamma * s * ah**n if ah > 0 else s * A


def bouc_wen_response(
    v: ArrayLike,
    A: float,
    beta: float,
    gamma: float,
    n: float = 1.0,
    substeps: int | None = None,
    rest_V: float = 0.0,
) -> NDArray[np.float64]:
    """Hysteretic state ``h`` (ue) of the Bouc-Wen model for the record ``v`` (V), from ``h = 0``
    at ``rest_V`` before the record. ``n = 1`` without ``substeps``: exact closed form per
    monotone run (compiled, :func:`labrig.analysis.baseline_kernels.bouc_wen_h1`: ``h`` is ``A``
    times the response for ``A = 1``, with ``gamma -> -gamma`` for ``A < 0``, the mirror image
    of :mod:`labrig.model.bouc_wen`); otherwise classical RK4 along the voltage with
    ``substeps`` steps per sample interval (default 8)."""
    vp = _with_rest(v, rest_V)
    h = np.zeros(vp.size)
    if n == 1.0 and substeps is None:
        if A == 0:
            return h[1:]
        g = gamma if A > 0 else -gamma
        return A * kern.bouc_wen_h1(vp, monotone_runs(vp), beta + g, beta - g)[0, 1:]
    m = 8 if substeps is None else int(substeps)
    if m < 1:
        raise ValueError("substeps must be >= 1")
    hc = 0.0
    for i in range(1, vp.size):
        dv = vp[i] - vp[i - 1]
        if dv != 0.0:
            s = 1.0 if dv > 0 else -1.0
            du = abs(dv) / m
            for _ in range(m):
                k1 = _bw_rhs(hc, s, A, beta, gamma, n)
                k2 = _bw_rhs(hc + 0.5 * du * k1, s, A, beta, gamma, n)
                k3 = _bw_rhs(hc + 0.5 * du * k2, s, A, beta, gamma, n)
                k4 = _bw_rhs(hc + du * k3, s, A, beta, gamma, n)
                hc += du * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
        h[i] = hc
    return h[1:]


@dataclass(frozen=True)
class BoucWen:
    """``S = d V - h`` with the Bouc-Wen ``h`` (module docstring); units ue/V, ue/V, 1/V, 1/V."""

    d: float
    A: float
    beta: float
    gamma: float
    n: float = 1.0

    def predict(
        self, v: ArrayLike, substeps: int | None = None, rest_V: float = 0.0
    ) -> NDArray[np.float64]:
        v = np.asarray(v, dtype=float)
        h = bouc_wen_response(v, self.A, self.beta, self.gamma, self.n, substeps, rest_V)
        return self.d * v - h

    def params(self) -> dict[str, Any]:
        return {
            "d_ue_per_V": self.d,
            "A_ue_per_V": self.A,
            "beta_per_V": self.beta,
            "gamma_per_V": self.gamma,
            "n": self.n,
        }


# -- fitting -----------------------------------------------------------------------------------


@dataclass
class _PlayedSequence:
    """A simulated sequence as the baselines see it: the voltage with its rest before it, its
    monotone runs, cached play bases and per-segment factors (shared by every fold)."""

    seq: SimSequence
    segments: list[Segment]
    vp: NDArray = field(init=False, repr=False)
    runs: tuple = field(init=False, repr=False)
    _basis: dict = field(default_factory=dict, init=False, repr=False)
    _pi: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self.vp = _with_rest(self.v, self.seq.rest_V)
        self.runs = monotone_runs(self.vp)

    @property
    def v(self) -> NDArray:
        return self.seq.voltage_V

    def start(self, name: str) -> int:
        return self.seq.entries[name].start

    def play_basis(self, thresholds: tuple[float, ...]) -> NDArray:
        if thresholds not in self._basis:
            self._basis[thresholds] = play_operators(self.v, thresholds, self.seq.rest_V)
        return self._basis[thresholds]

    def pi_factor(self, thresholds: tuple[float, ...], g: Segment, offset: bool) -> tuple:
        """``(R, Q^T b)`` of the reduced QR of segment ``g``'s weighted rows of the play basis
        (``Q R``) and its weighted measurement ``b`` (each about its mean with ``offset``)."""
        key = (thresholds, g.name, offset)
        if key not in self._pi:
            B = self.play_basis(thresholds)
            q, r = np.linalg.qr(_centred(B[g.lo : g.hi], offset) * g.weight, mode="reduced")
            self._pi[key] = (r, q.T @ (_centred(g.measured_ue, offset) * g.weight))
        return self._pi[key]


Items = list[tuple[_PlayedSequence, list[Segment]]]


def _centred(x: NDArray, offset: bool) -> NDArray:
    """``x`` about its mean (along the samples) when fitting one offset per entry."""
    return x - x.mean(axis=0) if offset else x


def _fit_pi(items: Items, n_ops: int, offset: bool = False) -> PrandtlIshlinskii:
    """NNLS of the weights on the stacked segments. ``|M w - b|^2`` over the stacked rows
    equals ``sum_g |R_g w - c_g|^2`` plus a constant (``Q_g R_g`` each segment's reduced QR,
    ``c_g = Q_g^T b_g``), and that stack's own QR gives the same small triangular system as a QR
    of every row at once; the segments' factors are made once and shared by the folds."""
    r_max = max(float(np.max(np.abs(q.v))) for q, _ in items) or 1.0
    r = tuple(float(x) for x in r_max * np.arange(n_ops) / n_ops)
    rs, cs = zip(*(q.pi_factor(r, g, offset) for q, segs in items for g in segs), strict=True)
    qq, rr = np.linalg.qr(np.vstack(rs), mode="reduced")
    w, _ = optimize.nnls(rr, qq.T @ np.concatenate(cs), maxiter=50 * n_ops)
    return PrandtlIshlinskii(r, tuple(float(x) for x in w))


@dataclass
class _BoucWenPart:
    """One sequence of a Bouc-Wen fit: its voltage, runs and scored segments as the kernels
    take them; ``cols`` holds the rest-prefixed voltage, ``h`` and its two derivatives."""

    q: _PlayedSequence
    segs: list[Segment]
    cols: NDArray = field(init=False, repr=False)
    lo: NDArray = field(init=False, repr=False)
    m0: NDArray = field(init=False, repr=False)
    n: NDArray = field(init=False, repr=False)
    meas: NDArray = field(init=False, repr=False)
    w: NDArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.cols = np.empty((4, self.q.vp.size))
        self.cols[0] = self.q.vp
        self.lo = np.array([g.lo + 1 for g in self.segs], dtype=np.int64)  # in vp
        self.n = np.array([g.measured_ue.size for g in self.segs], dtype=np.int64)
        self.m0 = np.concatenate(([0], np.cumsum(self.n)[:-1])).astype(np.int64)
        self.meas = np.ascontiguousarray(np.concatenate([g.measured_ue for g in self.segs]))
        self.w = np.array([g.weight for g in self.segs])


def _bw_linear_solve(g: NDArray) -> NDArray:
    """Best ``(d, A)`` from the Gram matrix ``g`` of ``(c0, c1, ..., b)`` (``c0`` the weighted
    voltage, ``c1`` minus the weighted ``h`` for ``A = 1``, ``b`` the weighted measurement, last):
    the normal equations of the column-scaled two-column problem."""
    n0, n1 = np.sqrt(g[0, 0]) or 1.0, np.sqrt(g[1, 1]) or 1.0
    cc = g[0, 1] / (n0 * n1)
    M = np.array([[1.0, cc], [cc, 1.0]])
    rhs2 = np.array([g[0, -1] / n0, g[1, -1] / n1])
    try:
        y = np.linalg.solve(M, rhs2)
    except np.linalg.LinAlgError:
        y = np.linalg.lstsq(M, rhs2, rcond=None)[0]
    return np.array([y[0] / n0, y[1] / n1])


def _solve_2x2(a: NDArray, b: NDArray) -> NDArray:
    try:
        return np.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(a, b, rcond=None)[0]


class _BoucWenFit:
    """The Bouc-Wen fit's residual on ``items`` as a function of
    ``z = (log((beta + gamma) * vr), (beta - gamma) / (beta + gamma))``, ``vr`` the largest
    voltage span, with ``(d, A)`` solved linearly (variable projection).

    For each ``z`` the kernels give ``h`` for ``A = 1`` and its exact derivatives, then the
    sums over the scored samples: the weighted residual ``r = d c0 + A c1 - b`` and the total
    derivative ``J`` of ``r`` (``(d, A)`` following ``z``: ``J_i = A D_i + C delta_i``,
    ``delta_i = -(C^T C)^-1 (C^T D_i A + e_A D_i^T r)``, ``D_i = dc1/dz_i``). The least-squares
    solver sees the 3-row equivalent of ``(J, r)``: rows whose Gram matrix is ``[J r]^T [J r]``,
    so the same cost, gradient and Gauss-Newton matrix at every step as the full residual."""

    def __init__(self, items: Items, offset: bool) -> None:
        self.parts = [_BoucWenPart(q, segs) for q, segs in items if segs]
        self.offset = offset
        self.vr = max(float(np.ptp(p.q.vp)) for p in self.parts) or 1.0
        self._last: tuple[bytes, bool, tuple] | None = None

    def ks_ko(self, z: NDArray) -> tuple[float, float]:
        ks = float(np.exp(z[0])) / self.vr
        return ks, float(z[1]) * ks

    def unpack(self, z: NDArray) -> tuple[float, float]:
        """``(beta, gamma)`` (1/V)."""
        ks, ko = self.ks_ko(z)
        return 0.5 * (ks + ko), 0.5 * (ks - ko)

    def _moments(self, z: NDArray, sens: bool) -> tuple[list[NDArray], NDArray]:
        ks, ko = self.ks_ko(z)
        moms, total = [], np.zeros((kern.N_COLS, kern.N_COLS))
        for p in self.parts:
            kern.bouc_wen_h1(p.q.vp, p.q.runs, ks, ko, sens, out=p.cols[1:])
            m = kern.segment_moments(p.cols, p.meas, p.lo, p.m0, p.n, self.offset)
            moms.append(m)
            total += np.einsum("g,gij->ij", p.w * p.w, m[:, 1:])
        return moms, total

    def evaluate(self, z: NDArray, sens: bool) -> tuple:
        """``(x, rows, J')``: ``x = (d, A)``, the 3 residual rows and (with ``sens``) their
        3 x 2 Jacobian."""
        key = (np.asarray(z, dtype=float).tobytes(), sens)
        if self._last is not None and self._last[0] == key[0] and (self._last[1] or not sens):
            return self._last[2]
        ks, ko = self.ks_ko(z)
        moms, G = self._moments(z, sens)
        # (c0, c1, D0, D1, b) on the centred columns (V, h, dh/dks, dh/dko, S) per unit weight
        T = np.zeros((5, kern.N_COLS))
        T[0, 0], T[1, 1], T[4, 4] = 1.0, -1.0, 1.0
        T[2, 2], T[2, 3] = -ks, -ko  # dc1/dz0: dks/dz0 = ks, dko/dz0 = ko
        T[3, 3] = -ks  # dc1/dz1: dko/dz1 = ks
        Gp = T @ G @ T.T
        x = _bw_linear_solve(Gp[[0, 1, 4]][:, [0, 1, 4]])
        coef_r = x[0] * T[0] + x[1] * T[1] - T[4]
        if sens:
            CtC = Gp[:2, :2]
            coefs = []
            for i in (2, 3):
                dtr = x[0] * Gp[i, 0] + x[1] * Gp[i, 1] - Gp[i, 4]
                delta = -_solve_2x2(CtC, Gp[:2, i] * x[1] + np.array([0.0, dtr]))
                coefs.append(x[1] * T[i] + delta[0] * T[0] + delta[1] * T[1])
            coef = np.vstack([*coefs, coef_r])
        else:
            coef = np.vstack([np.zeros((2, kern.N_COLS)), coef_r])
        M = np.zeros((3, 3))
        for p, m in zip(self.parts, moms, strict=True):
            M += kern.residual_gram(
                p.cols,
                p.meas,
                p.lo,
                p.m0,
                p.n,
                np.ascontiguousarray(m[:, 0]),
                p.w[:, None, None] * coef[None],
            )
        rtr = float(M[-1, -1])
        out: tuple[NDArray, NDArray, NDArray | None]
        if not sens:
            out = (x, np.array([np.sqrt(rtr), 0.0, 0.0]), None)
        else:
            lam, V = np.linalg.eigh(M[:2, :2])  # J^T J = V diag(lam) V^T
            keep = lam > 1e-14 * max(float(lam[-1]), 1e-300)
            sq = np.sqrt(np.where(keep, lam, 0.0))
            top = np.where(keep, (V.T @ M[:2, 2]) / np.where(keep, sq, 1.0), 0.0)
            rows = np.array([top[0], top[1], np.sqrt(max(rtr - float(top @ top), 0.0))])
            jac = np.vstack([sq[:, None] * V.T, np.zeros((1, 2))])
            out = (x, rows, jac)
        self._last = (key[0], sens, out)
        return out

    def cost2(self, z: NDArray) -> float:
        """The sum of squared weighted residuals at ``z``."""
        rows = self.evaluate(z, False)[1]
        return float(rows @ rows)


def _fit_bw(
    items: Items, start: tuple[float, float] | None = None, offset: bool = False
) -> BoucWen:
    prob = _BoucWenFit(items, offset)
    vr = prob.vr
    lo, hi = np.array([np.log(1e-3), -0.95]), np.array([np.log(1e3), 20.0])
    if start is not None:
        b, g = start
        z0 = np.clip([np.log((b + g) * vr), (b - g) / (b + g)], lo + 1e-9, hi - 1e-9)
    else:  # a small grid, then the best point
        grid = [(np.log(x), y) for x in (0.3, 1.0, 3.0, 10.0) for y in (-0.5, 0.3, 1.0, 3.0)]
        z0 = np.array(min(grid, key=lambda z: prob.cost2(np.array(z))))
    res = optimize.least_squares(
        lambda z: prob.evaluate(z, True)[1],
        z0,
        jac=lambda z: prob.evaluate(z, True)[2],
        bounds=(lo, hi),
        x_scale="jac",
        **CONVERGED,
    )
    beta, gamma = prob.unpack(res.x)
    d, A = prob.evaluate(res.x, False)[0]
    return BoucWen(float(d), float(A), beta, gamma)


@dataclass
class BaselineResult:
    """A fitted baseline and its scores (same metrics as :class:`~labrig.analysis.fit.FitResult`).

    :meth:`to_json` has the keys of ``labrig fit --json`` (``uncertainty`` and ``correlation``
    empty, ``method`` the baseline's kind).
    """

    kind: str
    model: PrandtlIshlinskii | BoucWen | SindyBaseline
    nrmse_pct: float
    per_entry: dict[str, float]
    heldout_nrmse_pct: float | None
    entries: list[str]
    heldout_per_entry: dict[str, float] | None = None
    warmup_s: float = 0.0
    chain: bool = False
    #: the fitted constant strain offset of each entry (``offset=True``), else ``None``
    offsets_ue: dict[str, float] | None = None
    #: the fitted baseline's strain for each scored entry (whole record, offset included; with
    #: ``chain`` the run's history included)
    predictions: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)

    @property
    def params(self) -> dict[str, Any]:
        return self.model.params()

    def predict(self, target: Any) -> Any:
        """Strain (ue) for a :class:`Record` or a run file's entry, from rest, plus its fitted
        offset if any; for a run (``labrig.Run``) ``{entry: strain}``, chained as the fit did
        (as :meth:`labrig.analysis.fit.FitResult.predict`)."""
        from labrig.analysis.load import as_records
        from labrig.analysis.simulate import predict_sequences

        records, single = as_records(target)
        out = predict_sequences(
            records,
            self.chain and not single,
            lambda seq: self.model.predict(seq.voltage_V, rest_V=seq.rest_V),
            self.offsets_ue,
        )
        return out[records[0].name] if single else out

    def simulate(self, records: Sequence[Record], chain: bool) -> dict[str, NDArray[np.float64]]:
        """The fitted baseline's strain (ue) for each of ``records`` (records it was not fitted
        on: ``labrig validate``), chained as a run when ``chain``, without any offset; SINDy
        is integrated at the records' own sample rate."""
        from labrig.analysis.simulate import predict_sequences

        def run(seq: SimSequence) -> NDArray[np.float64]:
            if isinstance(self.model, SindyBaseline):
                return self.model.predict(seq.voltage_V, rest_V=seq.rest_V, rate_hz=seq.rate_hz)
            return self.model.predict(seq.voltage_V, rest_V=seq.rest_V)

        return predict_sequences(records, chain, run)

    def to_json(self) -> dict[str, Any]:
        return {
            "params": self.params,
            "uncertainty": {},
            "correlation": {},
            **scores_json(
                self.nrmse_pct, self.per_entry, self.heldout_nrmse_pct, self.kind, self.entries
            ),
        }


def _predict(model: Any, q: _PlayedSequence, stop: int | None = None) -> NDArray[np.float64]:
    """The fitted baseline's strain (ue) over the sequence ``q`` (its first ``stop`` samples;
    every baseline is causal), the PI model from the sequence's cached play basis."""
    if isinstance(model, PrandtlIshlinskii):
        return (q.play_basis(model.thresholds) @ np.asarray(model.weights))[:stop]
    return model.predict(q.v[:stop], rest_V=q.seq.rest_V)


def _heldout_nrmse_pct(
    name: str,
    seqs: list[_PlayedSequence],
    fit: Callable[..., Any],
    warm: Any,
    offset: bool,
) -> float:
    """NRMSE (%) of entry ``name`` predicted by ``fit`` on every other entry (started from
    ``warm``); with ``offset``, the offset from the first half, scored on the second."""
    items = [(q, [g for g in q.segments if g.name != name]) for q in seqs]
    model = fit([(q, gs) for q, gs in items if gs], warm=warm)
    q = next(q for q in seqs if any(g.name == name for g in q.segments))
    seg = next(g for g in q.segments if g.name == name)
    p = _predict(model, q, seg.hi)[q.start(name) : seg.hi][seg.i0 :]
    m = seg.measured_ue
    return second_half_nrmse_pct(m, p, fit_offset=True) if offset else nrmse_pct(m, p)


def fit_baseline(
    records: list[Record],
    kind: str = "prandtl_ishlinskii",
    heldout: bool = True,
    warmup_s: float = 0.0,
    n_ops: int = 16,
    *,
    chain: bool = False,
    scored: Sequence[str] | None = None,
    offset: bool = False,
) -> BaselineResult:
    """Fit a baseline (``"prandtl_ishlinskii"``, ``"bouc_wen"`` or ``"sindy"``) on ``records``.

    ``n_ops``: number of play operators of the PI model. ``warmup_s``, ``chain`` and ``scored``
    as in :func:`~labrig.analysis.fit.fit_model` (a run's entries back to back, each followed by
    ``meta["rest_after_s"]`` at 0 V; both baselines have memory too). ``offset`` fits one
    constant strain offset per entry, as in :func:`~labrig.analysis.fit.fit_model` (held out:
    fitted on the first half of the entry's scored samples, scored on the second half).
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    scored = scored_names(records, scored)
    seqs = [
        _PlayedSequence(s.seq, s.segments)
        for s in scored_sequences(records, scored, warmup_s, chain)
    ]
    everything: Items = [(q, list(q.segments)) for q in seqs]
    sindy_cache = SindyCache()  # the SINDy regression's rows, shared by the folds

    def fit(items: Items, warm: PrandtlIshlinskii | BoucWen | SindyBaseline | None = None):
        if kind == "prandtl_ishlinskii":
            return _fit_pi(items, n_ops, offset)
        if kind == "sindy":
            return fit_sindy([(q.seq, segs) for q, segs in items], offset, cache=sindy_cache)
        start = (warm.beta, warm.gamma) if isinstance(warm, BoucWen) else None  # warm: a BoucWen
        return _fit_bw(items, start, offset)

    def predictions(model) -> dict[str, NDArray]:
        out = {}
        for q in seqs:
            s = _predict(model, q)
            for g in q.segments:
                out[g.name] = s[q.start(g.name) : g.hi]
        return out

    segs = {g.name: g for q in seqs for g in q.segments}
    with single_thread_blas():
        model = fit(everything)
        preds = predictions(model)
        offsets = None
        if offset:
            offsets = {
                n: float(np.mean(segs[n].measured_ue - preds[n][segs[n].i0 :])) for n in scored
            }
            preds = {n: p + offsets.get(n, 0.0) for n, p in preds.items()}
        per_entry = {n: nrmse_pct(segs[n].measured_ue, preds[n][segs[n].i0 :]) for n in scored}
        held, held_per = None, None
        if heldout and len(scored) >= 2:
            held_per = {n: _heldout_nrmse_pct(n, seqs, fit, model, offset) for n in scored}
            held = float(np.mean(list(held_per.values())))
    return BaselineResult(
        kind=kind,
        model=model,
        nrmse_pct=float(np.mean(list(per_entry.values()))),
        per_entry=per_entry,
        heldout_nrmse_pct=held,
        entries=list(scored),
        heldout_per_entry=held_per,
        warmup_s=warmup_s,
        chain=chain,
        offsets_ue=offsets,
        predictions=preds,
    )
