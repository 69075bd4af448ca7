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
and fast. Between reversals of ``V`` a play operator has the closed form ``max(V - r, y_s)``
(rising) or ``min(V + r, y_s)`` (falling), so the operators are evaluated run by run.

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

SINDy
-----
``kind="sindy"``: a sparse ODE of the strain driven by the voltage, fitted with pysindy and
scored in free run (:mod:`labrig.analysis.sindy`); unlike the two above it depends on the rate.

Objective and scores are those of :mod:`labrig.analysis.fit`: residuals weighted per entry by
``1 / (strain span * sqrt(samples))``, NRMSE per entry and its mean, and the leave-one-entry-out
held-out NRMSE.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

from labrig.analysis.metrics import nrmse_pct, scores_json, second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import (
    CONVERGED,
    Segment,
    SimSequence,
    scored_names,
    scored_sequences,
)
from labrig.analysis.sindy import SindyBaseline, fit_sindy
from labrig.core.blas import single_thread_blas
from labrig.model.bouc_wen import bouc_wen_exact, monotone_runs

__all__ = [
    "KINDS",
    "BaselineResult",
    "BoucWen",
    "PrandtlIshlinskii",
    "bouc_wen_response",
    "fit_baseline",
    "play_operator",
    "play_operators",
]

KINDS = ("prandtl_ishlinskii", "bouc_wen", "sindy")


def _with_rest(v: ArrayLike, rest_V: float = 0.0) -> NDArray:
    """The record preceded by the voltage the actuator rested at (0 V for a run)."""
    return np.concatenate(([float(rest_V)], np.asarray(v, dtype=float)))


# -- Prandtl-Ishlinskii ------------------------------------------------------------------------


def play_operators(v: ArrayLike, thresholds: ArrayLike, rest_V: float = 0.0) -> NDArray[np.float64]:
    """Outputs of play operators with the given thresholds (V) for the record ``v``: shape
    ``(len(v), len(thresholds))``, every operator relaxed at ``rest_V`` (the voltage the
    actuator rested at, 0 V for a run) before the record."""
    r = np.asarray(thresholds, dtype=float)
    if np.any(r < 0):
        raise ValueError("play thresholds must be non-negative")
    vp = _with_rest(v, rest_V)
    out = np.zeros((vp.size, r.size))
    y = np.full(r.size, vp[0])  # relaxed at rest
    for a, b, s in zip(*monotone_runs(vp), strict=True):
        seg = vp[a + 1 : b + 1, None]
        blk = np.maximum(seg - r, y) if s > 0 else np.minimum(seg + r, y)
        out[a + 1 : b + 1] = blk
        y = blk[-1]
    return out[1:]


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
    at 0 V before the record. ``n = 1`` without ``substeps``: exact closed form per monotone run;
    otherwise classical RK4 along the voltage with ``substeps`` steps per sample interval
    (default 8)."""
    vp = _with_rest(v, rest_V)
    h = np.zeros(vp.size)
    if n == 1.0 and substeps is None:
        return bouc_wen_exact(vp, A, beta, gamma)[1:]
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
    monotone runs, cached play bases."""

    seq: SimSequence
    segments: list[Segment]
    vp: NDArray = field(init=False, repr=False)
    runs: tuple = field(init=False, repr=False)
    _basis: dict = field(default_factory=dict, init=False, repr=False)

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


Items = list[tuple[_PlayedSequence, list[Segment]]]


def _centred(x: NDArray, offset: bool) -> NDArray:
    """``x`` about its mean (along the samples) when fitting one offset per entry."""
    return x - x.mean(axis=0) if offset else x


def _fit_pi(items: Items, n_ops: int, offset: bool = False) -> PrandtlIshlinskii:
    r_max = max(float(np.max(np.abs(q.v))) for q, _ in items) or 1.0
    r = tuple(float(x) for x in r_max * np.arange(n_ops) / n_ops)
    rows, rhs = [], []
    for q, segs in items:
        B = q.play_basis(r)
        for g in segs:
            rows.append(_centred(B[g.lo : g.hi], offset) * g.weight)
            rhs.append(_centred(g.measured_ue, offset) * g.weight)
    # same minimiser on the small triangular system: |Mw - b|^2 = |Rw - Q^T b|^2 + const
    qq, rr = np.linalg.qr(np.vstack(rows), mode="reduced")
    w, _ = optimize.nnls(rr, qq.T @ np.concatenate(rhs), maxiter=50 * n_ops)
    return PrandtlIshlinskii(r, tuple(float(x) for x in w))


def _bw_linear(
    items: Items, beta: float, gamma: float, offset: bool = False
) -> tuple[NDArray, NDArray]:
    """Best ``(d, A)`` for ``(beta, gamma)`` and the weighted residual (``offset``: each
    entry's columns and measurement about their means, i.e. one free offset per entry)."""
    c0s, c1s, rhs = [], [], []
    for q, segs in items:
        h1 = bouc_wen_exact(q.vp, 1.0, beta, gamma, q.runs)[1:]
        for g in segs:
            c0s.append(g.weight * _centred(q.v[g.lo : g.hi], offset))
            c1s.append(-g.weight * _centred(h1[g.lo : g.hi], offset))
            rhs.append(_centred(g.measured_ue, offset) * g.weight)
    c0, c1, b = np.concatenate(c0s), np.concatenate(c1s), np.concatenate(rhs)
    # two columns: the normal equations of the column-scaled problem
    n0, n1 = np.linalg.norm(c0) or 1.0, np.linalg.norm(c1) or 1.0
    cc = c0 @ c1 / (n0 * n1)
    M = np.array([[1.0, cc], [cc, 1.0]])
    rhs2 = np.array([c0 @ b / n0, c1 @ b / n1])
    try:
        y = np.linalg.solve(M, rhs2)
    except np.linalg.LinAlgError:
        y = np.linalg.lstsq(M, rhs2, rcond=None)[0]
    x = np.array([y[0] / n0, y[1] / n1])
    return x, x[0] * c0 + x[1] * c1 - b


def _fit_bw(
    items: Items, start: tuple[float, float] | None = None, offset: bool = False
) -> BoucWen:
    vr = max(float(np.ptp(q.vp)) for q, _ in items) or 1.0

    # z = (log((beta + gamma) * vr), (beta - gamma) / (beta + gamma))
    def unpack(z: NDArray) -> tuple[float, float]:
        ks = float(np.exp(z[0])) / vr
        ko = float(z[1]) * ks
        return 0.5 * (ks + ko), 0.5 * (ks - ko)

    def fun(z: NDArray) -> NDArray:
        return _bw_linear(items, *unpack(z), offset)[1]

    lo, hi = np.array([np.log(1e-3), -0.95]), np.array([np.log(1e3), 20.0])
    if start is not None:
        b, g = start
        z0 = np.clip([np.log((b + g) * vr), (b - g) / (b + g)], lo + 1e-9, hi - 1e-9)
    else:  # a small grid, then the best point
        grid = [(np.log(x), y) for x in (0.3, 1.0, 3.0, 10.0) for y in (-0.5, 0.3, 1.0, 3.0)]
        z0 = np.array(min(grid, key=lambda z: float(np.sum(fun(np.array(z)) ** 2))))
    res = optimize.least_squares(fun, z0, bounds=(lo, hi), x_scale="jac", **CONVERGED)
    beta, gamma = unpack(res.x)
    (d, A), _ = _bw_linear(items, beta, gamma, offset)
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

    def to_json(self) -> dict[str, Any]:
        return {
            "params": self.params,
            "uncertainty": {},
            "correlation": {},
            **scores_json(
                self.nrmse_pct, self.per_entry, self.heldout_nrmse_pct, self.kind, self.entries
            ),
        }


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
    p = model.predict(q.v, rest_V=q.seq.rest_V)[q.start(name) : seg.hi][seg.i0 :]
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

    def fit(items: Items, warm: PrandtlIshlinskii | BoucWen | SindyBaseline | None = None):
        if kind == "prandtl_ishlinskii":
            return _fit_pi(items, n_ops, offset)
        if kind == "sindy":
            return fit_sindy([(q.seq, segs) for q, segs in items], offset)
        return _fit_bw(items, None if warm is None else (warm.beta, warm.gamma), offset)

    def predictions(model) -> dict[str, NDArray]:
        out = {}
        for q in seqs:
            s = model.predict(q.v, rest_V=q.seq.rest_V)
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
