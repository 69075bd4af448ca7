"""The one least-squares problem under every fit: base model + effects over simulated sequences.

A :class:`Problem` holds simulated sequences (:mod:`labrig.analysis.simulate`), the scored
segments of each, a list of effects (:mod:`labrig.model.effects`) and the free parameters with
their coordinates (:class:`Coordinates`). It evaluates the weighted residual and its Jacobian in
one forward pass (:func:`labrig.analysis.forward.simulate_sequence`): the relaxors' and the
operator's derivatives come out of the same pass as the strain (forward sensitivities), the
effects' parameters by differences of the effect alone. Evaluations are cached by their parameter
values and shared by every problem made with :meth:`Problem.subset` (the folds of a
leave-one-entry-out share the full fit's simulations).

Residual: for each scored segment ``g`` of each sequence, ``w_g P_g (y - measured)`` with
``w_g = 1 / (span * sqrt(samples))`` (the cost is ``sum_e (NRMSE_e / 100)^2``) and ``P_g`` the
projection off the segment's nuisance regressors (its offset with ``offset=True``, the nuisance
effects' columns), i.e. those per-entry parameters eliminated by least squares (variable
projection).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.forward import Forward, moves_input, relaxed_input, simulate_sequence
from labrig.analysis.metrics import nrmse_pct
from labrig.analysis.simulate import (
    CONVERGED,
    DEFAULT_BOUNDS,
    LOG_PARAMS,
    LOOSE,
    PARAM_NAMES,
    LRUCache,
    OperatorFamily,
    Scored,
    Segment,
    SimSequence,
    bounded_least_squares,
)
from labrig.model.effects import Effect
from labrig.model.hysteresis import BUILTIN_SHAPES

__all__ = [
    "LAM_GAP",
    "Coordinate",
    "Coordinates",
    "Problem",
    "SharedSimulations",
    "base_problem",
    "best_of",
    "chord_refit",
    "offset_basis",
    "orthonormal",
    "solve",
]

#: the relaxor realisation is discontinuous at lam = 1 (a single pole at 1, a modal bank with
#: twice the impulse response at 1 + 1e-7, 1 % off at 1.001): with ``lam_gap`` the coordinate of
#: lam_d skips (1 - gap, 1 + gap)
LAM_GAP = 0.01

#: the relaxors' parameters (what V* depends on besides the voltage effects)
RELAXOR_NAMES = ("lam_t", "tau_t_s", "lam_d", "tau_d_s")

#: evaluations kept per problem family (each a full-length strain and Jacobian per sequence)
CACHE_SIZE = 6
#: relaxor passes kept per problem family (:func:`~labrig.analysis.forward.relaxed_input`'s
#: ``memo``: each one to three sequence-length arrays)
PASS_CACHE_SIZE = 32


@dataclass(frozen=True)
class Coordinate:
    """One free parameter: ``who`` is ``"base"`` or an effect's name; ``kind`` its transform
    (``"linear"``, ``"log"``, ``"lam_gap"``); ``lo``, ``hi`` the bounds in the coordinate;
    ``step`` the difference step in the coordinate for an effect's parameter."""

    who: str
    name: str
    kind: str
    lo: float
    hi: float
    step: float | None = None

    def value(self, z: float) -> float:
        if self.kind == "log":
            return float(np.exp(z))
        if self.kind == "lam_gap":
            return float(z) if z <= 1.0 - LAM_GAP else float(z) + 2 * LAM_GAP
        return float(z)

    def coordinate(self, x: float) -> float:
        if self.kind == "log":
            return float(np.log(x))
        if self.kind == "lam_gap":
            if x <= 1.0 - LAM_GAP:
                return float(x)
            if x >= 1.0 + LAM_GAP:
                return float(x) - 2 * LAM_GAP
            return 1.0 - LAM_GAP if x < 1.0 else 1.0 - LAM_GAP + 1e-9
        return float(x)


#: the operator's coordinates when its loop is parametrised by width and curvature
LOOP_WIDTH = "loop_width_ue"
LOOP_CURVATURE = "loop_curvature"


@dataclass(frozen=True)
class LoopScale:
    """How the operator's ``gamma`` and ``vc`` are reparametrised for fitting (module
    docstring of :class:`Coordinates`): ``span_V`` is the stroke of the reference loop (the
    records' largest peak-to-peak voltage), ``shape`` the operator's shape."""

    span_V: float
    shape: str

    def _opening(self, vc: float) -> tuple[float, float]:
        """``D = H1(2A) - 2 H1(A)`` per unit ``gamma`` (``A`` half the span) and ``dD/dvc``."""
        shp = BUILTIN_SHAPES[self.shape]
        a = np.array([self.span_V, 0.5 * self.span_V])
        h = shp.integral(a, 1.0, vc)
        dh = shp.integral_derivatives(a, 1.0, vc)[1]
        return float(h[0] - 2.0 * h[1]), float(dh[0] - 2.0 * dh[1])

    def to_loop(self, gamma: float, vc: float) -> tuple[float, float]:
        """``(W, q)``: the loop's opening (ue) at mid-stroke and ``q = span / vc``."""
        return gamma * self._opening(vc)[0], self.span_V / vc

    def to_native(self, width: float, q: float) -> tuple[float, float]:
        """``(gamma, vc)`` of a loop of opening ``width`` (ue) and curvature ``q``."""
        vc = self.span_V / q
        return width / self._opening(vc)[0], vc

    def jacobian(self, width: float, q: float) -> NDArray:
        """``d(gamma, vc) / d(W, ln q)`` (2 x 2)."""
        vc = self.span_V / q
        d, dd = self._opening(vc)
        return np.array([[1.0 / d, width * vc * dd / (d * d)], [0.0, -vc]])


class Coordinates:
    """The free parameters of a problem in the order of the parameter vector ``z``: the base
    parameters ``base_free`` (``vc`` and the time constants on a log scale; ``lam_d`` skipping
    the gap around 1 when ``lam_gap``), then each global effect's parameters.

    With ``loop`` (a :class:`LoopScale`) and both ``gamma`` and ``vc`` free, those two are
    fitted as the loop's opening ``W`` (ue, at the middle of a loop spanning the records'
    stroke) and its curvature ``q = span / vc`` (log scale): a narrow loop (``vc`` far above the
    stroke, where ``F(x) ~ alpha0 x + (gamma / 2 vc) x^2`` and only ``gamma / vc`` is seen) is
    then the well-conditioned limit ``q -> 0`` of a loop whose width is determined, instead of
    ``gamma`` and ``vc`` running away together."""

    def __init__(
        self,
        base_free: Sequence[str],
        effects: Sequence[Effect],
        bounds: Mapping[str, tuple[float, float]],
        lam_gap: bool,
        loop: LoopScale | None = None,
    ):
        self.base_free = tuple(base_free)
        self.loop = (
            loop
            if loop is not None
            and loop.shape in BUILTIN_SHAPES
            and loop.shape != "linear"
            and loop.span_V > 0
            and {"gamma_ue_per_V", "vc_V"} <= set(base_free)
            else None
        )
        out: list[Coordinate] = []
        for n in base_free:
            a, b = bounds[n]
            if self.loop is not None and n == "gamma_ue_per_V":
                out.append(Coordinate("base", LOOP_WIDTH, "linear", 0.0, 1e12))
            elif self.loop is not None and n == "vc_V":
                s = self.loop.span_V
                out.append(
                    Coordinate(
                        "base", LOOP_CURVATURE, "log", float(np.log(s / b)), float(np.log(s / a))
                    )
                )
            elif n in LOG_PARAMS:
                out.append(Coordinate("base", n, "log", float(np.log(a)), float(np.log(b))))
            elif n == "lam_d" and lam_gap:
                hi = b - 2 * LAM_GAP if b > 1.0 + LAM_GAP else b
                out.append(Coordinate("base", n, "lam_gap", float(a), float(hi)))
            else:
                out.append(Coordinate("base", n, "linear", float(a), float(b)))
        for e in effects:
            for q in e.params:
                a, b = (np.log(q.lo), np.log(q.hi)) if q.log else (q.lo, q.hi)
                kind = "log" if q.log else "linear"
                out.append(Coordinate(e.name, q.name, kind, float(a), float(b), 1e-5 * (b - a)))
        self.items: tuple[Coordinate, ...] = tuple(out)
        self.lo = np.array([c.lo for c in out], dtype=float)
        self.hi = np.array([c.hi for c in out], dtype=float)
        self._effects = {e.name: e for e in effects}

    def operator_map(self, base: Mapping[str, float]) -> tuple[list[int], NDArray]:
        """The operator's coordinates (their indices) and ``d(alpha0, gamma, vc) / dz`` for
        them (3 x k): what turns the operator's native sensitivities into Jacobian columns."""
        idx = [
            j
            for j, c in enumerate(self.items)
            if c.who == "base"
            and c.name in ("alpha0_ue_per_V", "gamma_ue_per_V", "vc_V", LOOP_WIDTH, LOOP_CURVATURE)
        ]
        M = np.zeros((3, len(idx)))
        col = {self.items[j].name: i for i, j in enumerate(idx)}
        if "alpha0_ue_per_V" in col:
            M[0, col["alpha0_ue_per_V"]] = 1.0
        if "gamma_ue_per_V" in col:
            M[1, col["gamma_ue_per_V"]] = 1.0
        if "vc_V" in col:
            M[2, col["vc_V"]] = base["vc_V"]  # log scale
        if self.loop is not None:
            w, q = self.loop.to_loop(base["gamma_ue_per_V"], base["vc_V"])
            T = self.loop.jacobian(w, q)
            M[1:, [col[LOOP_WIDTH], col[LOOP_CURVATURE]]] = T
        return idx, M

    def native_jacobian(self, z: NDArray, base0: Mapping[str, float]) -> NDArray:
        """``d(native free parameters) / dz`` (square): the base's free parameters in the
        order of :attr:`base_free`, then the effects' parameters (native units)."""
        base, _ = self.unpack(z, base0)
        k = len(self.items)
        T = np.zeros((k, k))
        pos = {n: i for i, n in enumerate(self.base_free)}
        for j, c in enumerate(self.items):
            i = pos.get(c.name, j) if c.who == "base" else j
            if c.who == "base" and c.name in (LOOP_WIDTH, LOOP_CURVATURE):
                continue
            T[i, j] = c.value(z[j]) if c.kind == "log" else 1.0
        if self.loop is not None:
            jw = next(j for j, c in enumerate(self.items) if c.name == LOOP_WIDTH)
            jq = next(j for j, c in enumerate(self.items) if c.name == LOOP_CURVATURE)
            w, q = self.loop.to_loop(base["gamma_ue_per_V"], base["vc_V"])
            G = self.loop.jacobian(w, q)
            ig, iv = pos["gamma_ue_per_V"], pos["vc_V"]
            T[np.ix_([ig, iv], [jw, jq])] = G
        return T

    def __len__(self) -> int:
        return len(self.items)

    @property
    def names(self) -> list[tuple[str, str]]:
        return [(c.who, c.name) for c in self.items]

    def z(
        self,
        base: Mapping[str, float],
        eff: Mapping[str, Mapping[str, float]] | None = None,
        strict: bool = False,
    ) -> NDArray[np.float64]:
        """Coordinates of ``base`` and ``eff`` (an effect's missing parameters at their
        ``init``), clipped to the bounds (``strict``: strictly inside, as a start must be)."""
        eff = eff or {}
        z = []
        loop = (
            self.loop.to_loop(float(base["gamma_ue_per_V"]), float(base["vc_V"]))
            if self.loop is not None
            else None
        )
        for c in self.items:
            if c.who == "base" and loop is not None and c.name == LOOP_WIDTH:
                x = loop[0]
            elif c.who == "base" and loop is not None and c.name == LOOP_CURVATURE:
                x = loop[1]
            elif c.who == "base":
                x = float(base[c.name])
            else:
                q = next(p for p in self._effects[c.who].params if p.name == c.name)
                x = float(eff.get(c.who, {}).get(c.name, q.init))
            z.append(c.coordinate(x))
        out = np.array(z, dtype=float)
        if strict:
            pad_lo = 1e-10 * np.maximum(1.0, np.abs(self.lo))
            pad_hi = 1e-10 * np.maximum(1.0, np.abs(self.hi))
            return np.clip(out, self.lo + pad_lo, self.hi - pad_hi)
        return np.clip(out, self.lo, self.hi)

    def unpack(
        self, z: NDArray, base0: Mapping[str, float]
    ) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
        """Base parameters (the fixed ones from ``base0``) and effect parameters at ``z``."""
        base = {n: float(base0[n]) for n in PARAM_NAMES}
        eff: dict[str, dict[str, float]] = {n: {} for n in self._effects if self._params(n)}
        for c, x in zip(self.items, z, strict=True):
            if c.who == "base":
                base[c.name] = c.value(x)
            else:
                eff[c.who][c.name] = c.value(x)
        if self.loop is not None:
            width, q = base.pop(LOOP_WIDTH), base.pop(LOOP_CURVATURE)
            base["gamma_ue_per_V"], base["vc_V"] = self.loop.to_native(width, q)
        return base, eff

    def _params(self, name: str) -> bool:
        return bool(self._effects[name].params)

    def at_bound(self, z: NDArray, rel: float = 1e-6) -> NDArray[np.bool_]:
        """Which coordinates sit on their bound (to ``rel``, relative to the bound)."""
        lo = rel * np.maximum(1.0, np.abs(self.lo))
        hi = rel * np.maximum(1.0, np.abs(self.hi))
        return (z - self.lo <= lo) | (self.hi - z <= hi)


def orthonormal(C: NDArray) -> NDArray | None:
    """An orthonormal basis of the columns of ``C`` (``None`` without columns)."""
    if C.shape[1] == 0:
        return None
    u, s, _ = np.linalg.svd(C, full_matrices=False)
    keep = s > s[0] * 1e-9
    return u[:, keep]


@dataclass
class SharedSimulations:
    """What the problems of one family (a problem and its subsets) share: the simulations."""

    cache: OrderedDict = field(default_factory=OrderedDict)  # whole simulations
    relaxed: OrderedDict = field(default_factory=OrderedDict)  # V* and its derivatives
    evaluations: int = 0  # forward passes computed (cache misses)
    #: the relaxor passes behind ``relaxed`` (each relaxor's output or sensitivities, each
    #: column's tangent), reused across evaluations that share them
    passes: LRUCache = field(default_factory=lambda: LRUCache(PASS_CACHE_SIZE))


class Problem:
    """Base model + ``effects`` over ``sequences`` (module docstring).

    - ``segments``: the scored segments of each sequence (same order as ``sequences``);
    - ``nuisance``: each scored segment's orthonormal nuisance basis (``None``: none);
    - ``base_free``: the base parameters left free; the others stay at the values of ``base0``
      given to :meth:`residual`, :meth:`jacobian` and the fits;
    - ``with_gd``: ``False`` leaves ``G_d`` out (the staged fit's transient stage);
    - ``lam_gap``: ``lam_d``'s coordinate skips the gap around 1 (:data:`LAM_GAP`).
    """

    def __init__(
        self,
        sequences: Sequence[SimSequence],
        segments: Sequence[Sequence[Segment]],
        effects: Sequence[Effect],
        family: OperatorFamily,
        *,
        base_free: Sequence[str] = PARAM_NAMES,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        nuisance: Mapping[str, NDArray | None] | None = None,
        with_gd: bool = True,
        lam_gap: bool = True,
        shared: SharedSimulations | None = None,
        loop: LoopScale | None = None,
    ):
        self.sequences = list(sequences)
        self.segments = [list(s) for s in segments]
        self.effects = list(effects)
        self.family = family
        self.bounds = {**DEFAULT_BOUNDS, **(bounds or {})}
        self.nuisance = dict(nuisance or {})
        self.with_gd = with_gd
        self.lam_gap = lam_gap
        if loop is None and self.sequences:
            span = max(float(np.ptp(s.voltage_V)) if s.n else 0.0 for s in self.sequences)
            loop = LoopScale(span, family.shape) if span > 0 else None
        self.loop = loop
        self.coords = Coordinates(base_free, self.glob, self.bounds, lam_gap, loop)
        self._shared = shared or SharedSimulations()
        self.nfev = 0  # residual evaluations asked of this problem
        self.n_scored = sum(g.measured_ue.size for segs in self.segments for g in segs)

    # -- the effects by where they act ---------------------------------------------------------
    @property
    def glob(self) -> list[Effect]:
        """The effects fitted as global parameters (all but the nuisance effects)."""
        return [e for e in self.effects if e.where != "nuisance"]

    @property
    def scored(self) -> list[str]:
        return [g.name for segs in self.segments for g in segs]

    @property
    def evaluations(self) -> int:
        """Forward passes computed for this problem and its subsets (cache misses)."""
        return self._shared.evaluations

    def subset(self, scored: Sequence[str], base_free: Sequence[str] | None = None) -> Problem:
        """The same problem scored on ``scored`` only (sequences without a scored segment are
        not simulated), with other free base parameters if given, sharing this problem's
        simulations."""
        keep = set(scored)
        seqs, segs = [], []
        for s, gs in zip(self.sequences, self.segments, strict=True):
            chosen = [g for g in gs if g.name in keep]
            if chosen:
                seqs.append(s)
                segs.append(chosen)
        return Problem(
            seqs,
            segs,
            self.effects,
            self.family,
            base_free=self.coords.base_free if base_free is None else base_free,
            bounds=self.bounds,
            nuisance=self.nuisance,
            with_gd=self.with_gd,
            lam_gap=self.lam_gap,
            shared=self._shared,
            loop=self.loop,
        )

    # -- evaluation ----------------------------------------------------------------------------
    def forward(
        self,
        base: Mapping[str, float],
        eff: Mapping[str, Mapping[str, float]],
        jacobian: bool,
    ) -> list[Forward]:
        """Each sequence's modelled strain (before nuisance terms) and, with ``jacobian``, its
        derivative with respect to the free coordinates (cached by the parameter values)."""
        names = (*self.coords.names, ("loop", repr(self.coords.loop))) if jacobian else ()
        key_params = (
            tuple(float(base[n]) for n in PARAM_NAMES),
            tuple(
                (e.name, tuple(sorted((k, float(v)) for k, v in eff.get(e.name, {}).items())))
                for e in self.glob
            ),
        )
        out = []
        cache = self._shared.cache
        fam = (self.family.shape, self.family.memory, self.with_gd)
        coords = self.coords.items if jacobian else ()
        vol = [e for e in self.effects if e.where == "voltage"]
        moving = tuple((c.who, c.name) for c in coords if moves_input(c, vol))
        vkey = (
            tuple(float(base[n]) for n in RELAXOR_NAMES),
            tuple(
                (e.name, tuple(sorted((k, float(v)) for k, v in eff.get(e.name, {}).items())))
                for e in vol
            ),
        )
        for seq in self.sequences:
            key = (id(seq), fam, key_params)
            hit = cache.get(key)
            if hit is None or (jacobian and hit.names != names):
                rkey = (id(seq), fam, vkey, moving)
                relaxed = self._shared.relaxed.get(rkey)
                if relaxed is None:
                    relaxed = relaxed_input(
                        seq, base, eff, vol, coords, self.with_gd, self._shared.passes
                    )
                    self._shared.relaxed[rkey] = relaxed
                    while len(self._shared.relaxed) > CACHE_SIZE * max(1, len(self.sequences)):
                        self._shared.relaxed.popitem(last=False)
                self._shared.relaxed.move_to_end(rkey)
                hit = simulate_sequence(
                    seq,
                    self.family,
                    base,
                    eff,
                    self.effects,
                    coords,
                    with_gd=self.with_gd,
                    relaxed=relaxed,
                    operator_map=self.coords.operator_map(base) if jacobian else None,
                )
                hit.names = names
                self._shared.evaluations += 1
                cache[key] = hit
                while len(cache) > CACHE_SIZE * max(1, len(self.sequences)):
                    cache.popitem(last=False)
            cache.move_to_end(key)
            out.append(hit)
        return out

    def strains(
        self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]] | None = None
    ) -> list[NDArray]:
        """Modelled strain over each simulated sequence (before nuisance terms)."""
        return [f.y for f in self.forward(base, eff or {}, jacobian=False)]

    def _project(self, g: Segment, d: NDArray) -> NDArray:
        Q = self.nuisance.get(g.name)
        if Q is None:
            return d
        return d - Q @ (Q.T @ d)

    def weighted(self, per_seq: Sequence[NDArray], subtract: bool) -> NDArray:
        """The scored rows of per-sequence arrays (vectors or column blocks), weighted and
        projected off the nuisance regressors; ``subtract``: the arrays are predictions,
        subtract the measurements (residuals)."""
        parts = []
        for segs, x in zip(self.segments, per_seq, strict=True):
            for g in segs:
                d = x[g.lo : g.hi]
                if subtract:
                    d = d - g.measured_ue
                parts.append(g.weight * self._project(g, d))
        if not parts:
            return np.zeros(0)
        return np.concatenate(parts)

    def residual_at(
        self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]] | None = None
    ) -> NDArray:
        """The weighted residual of the model ``(base, eff)``."""
        self.nfev += 1
        return self.weighted(self.strains(base, eff), subtract=True)

    def residual(self, z: NDArray, base0: Mapping[str, float]) -> NDArray:
        """The weighted residual at coordinates ``z`` (fixed parameters from ``base0``)."""
        base, eff = self.coords.unpack(z, base0)
        return self.residual_at(base, eff)

    def jacobian(self, z: NDArray, base0: Mapping[str, float]) -> NDArray:
        """d(weighted residual)/dz: the forward sensitivities of the free coordinates."""
        base, eff = self.coords.unpack(z, base0)
        fwd = self.forward(base, eff, jacobian=True)
        return self.weighted([f.J for f in fwd], subtract=False)

    def _with_nuisance(self, g: Segment, p: NDArray) -> NDArray:
        """Prediction ``p`` of segment ``g`` plus its nuisance terms fitted on the segment."""
        Q = self.nuisance.get(g.name)
        return p if Q is None else p + Q @ (Q.T @ (g.measured_ue - p))

    def predictions(
        self,
        base: Mapping[str, float],
        eff: Mapping[str, Mapping[str, float]] | None = None,
        nuisance: bool = True,
    ) -> dict[str, NDArray]:
        """Each scored entry's modelled strain over its whole record (warm-up included), with
        its nuisance terms fitted on the scored samples (``nuisance``)."""
        out = {}
        for seq, segs, y in zip(
            self.sequences, self.segments, self.strains(base, eff), strict=True
        ):
            for g in segs:
                p = y[seq.entries[g.name].start : g.hi].copy()
                if nuisance:
                    p[g.i0 :] = self._with_nuisance(g, p[g.i0 :])
                out[g.name] = p
        return out

    def per_entry(
        self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]] | None = None
    ) -> dict[str, float]:
        """In-sample NRMSE (%) of each scored entry, nuisance terms fitted on the whole entry."""
        out = {}
        for segs, y in zip(self.segments, self.strains(base, eff), strict=True):
            for g in segs:
                out[g.name] = nrmse_pct(g.measured_ue, self._with_nuisance(g, y[g.lo : g.hi]))
        return out

    def cost(self, base: Mapping[str, float], eff=None) -> float:
        r = self.residual_at(base, eff)
        return 0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.inf


def offset_basis(segments: Sequence[Sequence[Segment]]) -> dict[str, NDArray]:
    """One constant strain offset per scored segment, as a nuisance basis (its mean taken out)."""
    out = {}
    for segs in segments:
        for g in segs:
            m = g.measured_ue.size
            out[g.name] = np.full((m, 1), 1.0 / np.sqrt(m))
    return out


def solve(
    problem: Problem,
    z0: NDArray,
    base0: Mapping[str, float],
    max_nfev: int | None,
    tolerances: Mapping[str, float],
) -> optimize.OptimizeResult:
    """Bounded trust-region least squares of ``problem`` from ``z0`` (fixed parameters from
    ``base0``), on its exact Jacobian."""
    return bounded_least_squares(
        lambda z: problem.residual(z, base0),
        lambda z: problem.jacobian(z, base0),
        z0,
        (problem.coords.lo, problem.coords.hi),
        max_nfev,
        dict(tolerances),
    )


def best_of(
    problem: Problem,
    starts: Sequence[Mapping[str, float]],
    short_nfev: int,
    polish_nfev: int | None,
    tight: bool = True,
) -> tuple[dict[str, float], optimize.OptimizeResult]:
    """A base-only ``problem`` from several starts (base parameter values; the parameters that
    are not free stay at the first start's): short runs from each (``short_nfev > 0``) or,
    with ``short_nfev = 0``, just the cost at each; then the best one converged
    (:data:`~labrig.analysis.simulate.CONVERGED` with ``tight``, else
    :data:`~labrig.analysis.simulate.LOOSE`)."""
    base0 = dict(starts[0])
    tol = CONVERGED if tight else LOOSE

    def full(z: NDArray) -> dict[str, float]:
        return problem.coords.unpack(z, base0)[0]

    if len(starts) == 1:
        res = solve(problem, problem.coords.z(starts[0], strict=True), base0, polish_nfev, tol)
        return full(res.x), res
    if short_nfev == 0:
        costs = []
        for s in starts:
            r = problem.residual(problem.coords.z(s, strict=True), base0)
            costs.append(float(r @ r) if np.all(np.isfinite(r)) else np.inf)
        z0 = problem.coords.z(starts[int(np.argmin(costs))], strict=True)
        res = solve(problem, z0, base0, polish_nfev, tol)
        return full(res.x), res
    trials = []
    for s in starts:
        try:
            res = solve(problem, problem.coords.z(s, strict=True), base0, short_nfev, LOOSE)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            continue
        trials.append(res)
    if not trials:
        raise RuntimeError("every start of the fit failed")
    best = min(trials, key=lambda r: r.cost)
    res = solve(problem, best.x, base0, polish_nfev, tol)
    return full(res.x), res


def base_problem(
    scored: Sequence[Scored],
    family: OperatorFamily,
    offset: bool,
    base_free: Sequence[str] = PARAM_NAMES,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    with_gd: bool = True,
) -> Problem:
    """The base model alone over scored sequences (``offset``: one free strain offset per
    entry); ``lam_d``'s coordinate is plain (the base fit's convention)."""
    segs = [s.segments for s in scored]
    return Problem(
        [s.seq for s in scored],
        segs,
        [],
        family,
        base_free=base_free,
        bounds=bounds,
        nuisance=offset_basis(segs) if offset else None,
        with_gd=with_gd,
        lam_gap=False,
    )


#: a chord refit stops when its step is this small (relative to the coordinates' scale)
CHORD_XTOL = 1e-10
#: ... or after this many steps (then the caller falls back to the trust-region fit)
CHORD_STEPS = 15


def chord_refit(
    problem: Problem, z0: NDArray, base0: Mapping[str, float]
) -> tuple[NDArray, NDArray] | None:
    """Refit ``problem`` from ``z0`` with the Jacobian held at ``z0`` (the chord method): each
    step ``-J0^+ r(z)`` needs only a residual, no new Jacobian. For a held-out fold started at
    the full fit's optimum ``z0`` the fold's optimum is close and ``J0`` nearly right, so it
    converges linearly in a few steps to the same point as a trust-region fit. Returns
    ``(z, r)`` at convergence (the step below :data:`CHORD_XTOL`), or ``None`` when a step
    would leave the bounds, raise the cost, or convergence takes more than
    :data:`CHORD_STEPS` steps (the caller then fits with :func:`solve`)."""
    J0 = problem.jacobian(z0, base0)
    if J0.size == 0 or not np.all(np.isfinite(J0)):
        return None
    scale = np.linalg.norm(J0, axis=0)
    if np.any(scale == 0):
        return None
    q, rr = np.linalg.qr(J0 / scale)
    z = np.array(z0, dtype=float)
    r = problem.residual(z, base0)
    cost = float(r @ r)
    span = np.maximum(np.abs(z0), 1.0)
    for _ in range(CHORD_STEPS):
        try:
            step = -np.linalg.solve(rr, q.T @ r) / scale
        except np.linalg.LinAlgError:
            return None
        z_new = z + step
        if np.any(z_new < problem.coords.lo) or np.any(z_new > problem.coords.hi):
            return None
        r_new = problem.residual(z_new, base0)
        cost_new = float(r_new @ r_new)
        if not np.isfinite(cost_new) or cost_new > cost * (1.0 + 1e-12):
            return None
        z, r, cost = z_new, r_new, cost_new
        if np.max(np.abs(step) / span) <= CHORD_XTOL:
            return z, r
    return None
