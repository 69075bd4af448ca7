"""The base model's least-squares problem: cached simulation, structured Jacobian, solvers.

The residual is the weighted free-run simulation error of the dynamic model over the scored
segments of simulated sequences (:mod:`labrig.analysis.simulate`); with ``offset=True`` each
segment's residual is taken about its mean (one constant strain offset per entry, eliminated in
closed form).

Coordinates: ``alpha0, gamma`` as they are, ``log vc``, ``lam_t``, ``log tau_t``, ``lam_d``,
``log tau_d`` (:class:`ParameterSpace`). The Jacobian is structured instead of generic finite
differences: ``S = alpha0 V* + gamma G_vc(V*)`` exactly (the operator is linear in ``alpha0`` and
``gamma`` for a fixed input, and its reversals depend on the input only), so those two columns
are exact, ``vc`` needs the operator alone, and the four relaxor parameters need one new relaxor
bank each; ``G_t``'s output is cached for the ``G_d`` columns.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.simulate import (
    CONVERGED,
    LOG_PARAMS,
    LOOSE,
    LRUCache,
    OperatorFamily,
    Scored,
    bounded_least_squares,
    relaxor_output,
)
from labrig.model import QuasiStaticHysteresis

__all__ = ["BaseProblem", "ParameterSpace", "best_of", "solve"]

FD_FORWARD = 1e-6  # forward-difference step in transformed coordinates (iterations)
FD_CENTRAL = 1e-4  # central-difference step (final Jacobian)
FD_VC = 1e-5  # central step in log vc (operator only)


class ParameterSpace:
    """Free parameters, their transform (log for ``vc`` and the time constants) and bounds; the
    rest fixed at ``values``."""

    def __init__(
        self,
        free: Sequence[str],
        values: dict[str, float],
        bounds: dict[str, tuple[float, float]],
    ):
        self.free = tuple(free)
        self.values = dict(values)
        lo, hi = [], []
        for name in self.free:
            a, b = bounds[name]
            if name in LOG_PARAMS:
                a, b = np.log(a), np.log(b)
            lo.append(a)
            hi.append(b)
        self.lo, self.hi = np.array(lo), np.array(hi)

    def z(self, values: dict[str, float]) -> NDArray:
        """Coordinates of ``values``, strictly inside the bounds (least_squares needs a feasible
        start)."""
        out = np.array(
            [np.log(values[n]) if n in LOG_PARAMS else float(values[n]) for n in self.free],
            dtype=float,
        )
        return np.clip(out, self.lo + self._pad(self.lo), self.hi - self._pad(self.hi))

    @staticmethod
    def _pad(bound: NDArray) -> NDArray:
        return 1e-10 * np.maximum(1.0, np.abs(bound))

    def at_bound(self, z: NDArray) -> NDArray:
        """Which coordinates sit on their bound (to 1e-6, relative to the bound)."""
        lo, hi = 1e-6 * np.maximum(1.0, np.abs(self.lo)), 1e-6 * np.maximum(1.0, np.abs(self.hi))
        return (z - self.lo <= lo) | (self.hi - z <= hi)

    def full(self, z: NDArray) -> dict[str, float]:
        """All parameters, the free ones at ``z``."""
        th = dict(self.values)
        for n, x in zip(self.free, z, strict=True):
            th[n] = float(np.exp(x)) if n in LOG_PARAMS else float(x)
        return th


class BaseProblem:
    """Simulation of scored sequences with caches for the relaxor outputs.

    ``with_gd=False`` leaves ``G_d`` out (the transient stage of the staged fit).
    """

    def __init__(
        self,
        scored: Sequence[Scored],
        family: OperatorFamily,
        offset: bool = False,
        with_gd: bool = True,
    ):
        self.scored = list(scored)
        self.family = family
        self.offset = offset
        self.with_gd = with_gd
        self._vt = LRUCache(6)
        self._vd = LRUCache(8)
        self.segments = [g for s in self.scored for g in s.segments]
        self.n_scored = sum(g.measured_ue.size for g in self.segments)
        self.nfev = 0

    def vt(self, lam_t: float, tau_t: float) -> list[NDArray]:
        """``G_t V`` of each sequence (padded length)."""
        return self._vt.get(
            (lam_t, tau_t),
            lambda: [
                relaxor_output(tau_t, lam_t, s.seq.rate_hz, s.seq.hold, s.seq.padded, s.seq.rest_V)
                for s in self.scored
            ],
        )

    def vd(self, th: dict[str, float]) -> list[NDArray]:
        """``V* = G_d G_t V`` of each sequence (padded length)."""
        vt = self.vt(th["lam_t"], th["tau_t_s"])
        if not self.with_gd:
            return vt
        key = (th["lam_t"], th["tau_t_s"], th["lam_d"], th["tau_d_s"])
        return self._vd.get(
            key,
            lambda: [
                relaxor_output(th["tau_d_s"], th["lam_d"], s.seq.rate_hz, "linear", x, s.seq.rest_V)
                for s, x in zip(self.scored, vt, strict=True)
            ],
        )

    def _op(self, th: dict[str, float]) -> QuasiStaticHysteresis:
        return self.family.operator(th["alpha0_ue_per_V"], th["gamma_ue_per_V"], th["vc_V"])

    def strains(self, th: dict[str, float]) -> list[NDArray]:
        """Predicted strain of each simulated sequence (full length)."""
        op = self._op(th)
        return [
            op.apply(x[: s.seq.n], op.held_state(s.seq.rest_V))
            for s, x in zip(self.scored, self.vd(th), strict=True)
        ]

    def _weighted(self, per_seq: Sequence[NDArray], subtract: bool = False) -> NDArray:
        """The scored parts of per-sequence arrays, weighted (about their mean with ``offset``).

        ``subtract``: the arrays are predictions, subtract the measurements (residuals)."""
        out = []
        for s, x in zip(self.scored, per_seq, strict=True):
            for g in s.segments:
                d = x[g.lo : g.hi] - g.measured_ue if subtract else x[g.lo : g.hi]
                if self.offset:
                    d = d - d.mean()
                out.append(g.weight * d)
        return np.concatenate(out)

    def residuals(self, th: dict[str, float]) -> NDArray:
        self.nfev += 1
        return self._weighted(self.strains(th), subtract=True)

    def predictions(self, th: dict[str, float]) -> dict[str, NDArray]:
        """Prediction over each scored record's whole length (warm-up included)."""
        out = {}
        for s, y in zip(self.scored, self.strains(th), strict=True):
            for g in s.segments:
                out[g.name] = y[s.seq.entries[g.name].start : g.hi].copy()
        return out

    def _hyst_part(self, vd: NDArray, vc: float, held_V: float) -> NDArray:
        """``G_vc(V*)``: the operator's output per unit gamma (alpha0 part removed), held at
        ``held_V`` before."""
        op = self.family.operator(1.0, 1.0, vc)
        return op.apply(vd, op.held_state(held_V)) - vd

    def _difference_columns(
        self, space: ParameterSpace, z: NDArray, j: int, central: bool, base: list | None
    ) -> tuple[list[NDArray], list | None]:
        """d strain / d z_j by finite differences (forward, or central for the final Jacobian)."""
        zp = z.copy()
        if central:
            h = FD_CENTRAL
            zp[j] = z[j] + h
            zm = z.copy()
            zm[j] = z[j] - h
            sp, sm = self.strains(space.full(zp)), self.strains(space.full(zm))
            return [(a - b) / (2 * h) for a, b in zip(sp, sm, strict=True)], base
        h = FD_FORWARD
        step = h if z[j] + h <= space.hi[j] or z[j] - h < space.lo[j] else -h
        zp[j] = z[j] + step
        if base is None:
            base = self.strains(space.full(z))
        sp = self.strains(space.full(zp))
        return [(a - b) / step for a, b in zip(sp, base, strict=True)], base

    def jacobian(self, space: ParameterSpace, z: NDArray, central: bool = False) -> NDArray:
        """d(weighted residual)/dz, structured (module docstring)."""
        th = space.full(z)
        cols: list[list[NDArray]] = [[] for _ in space.free]
        vd = [x[: s.seq.n] for s, x in zip(self.scored, self.vd(th), strict=True)]
        rests = [s.seq.rest_V for s in self.scored]
        base = None
        for j, name in enumerate(space.free):
            if name == "alpha0_ue_per_V":
                cols[j] = vd
            elif name == "gamma_ue_per_V":
                cols[j] = [
                    self._hyst_part(x, th["vc_V"], r) for x, r in zip(vd, rests, strict=True)
                ]
            elif name == "vc_V":
                g, vc, h = th["gamma_ue_per_V"], th["vc_V"], FD_VC
                cols[j] = [
                    g
                    * (
                        self._hyst_part(x, vc * np.exp(h), r)
                        - self._hyst_part(x, vc * np.exp(-h), r)
                    )
                    / (2 * h)
                    for x, r in zip(vd, rests, strict=True)
                ]
            else:
                cols[j], base = self._difference_columns(space, z, j, central, base)
        J = np.empty((self.n_scored, len(space.free)))
        for j in range(len(space.free)):  # all columns are d/dz (vc: d/dlog vc)
            J[:, j] = self._weighted(cols[j])
        return J


def solve(
    problem: BaseProblem,
    space: ParameterSpace,
    z0: NDArray,
    max_nfev: int | None,
    tight: bool = True,
) -> optimize.OptimizeResult:
    """Bounded trust-region least squares from ``z0`` (``tight``: :data:`CONVERGED`)."""
    return bounded_least_squares(
        lambda z: problem.residuals(space.full(z)),
        lambda z: problem.jacobian(space, z),
        z0,
        (space.lo, space.hi),
        max_nfev,
        CONVERGED if tight else LOOSE,
    )


def best_of(
    problem: BaseProblem,
    space: ParameterSpace,
    starts: Sequence[dict[str, float]],
    short_nfev: int,
    polish_nfev: int | None,
    tight: bool = True,
) -> tuple[dict[str, float], optimize.OptimizeResult]:
    """Short runs from each start (``short_nfev > 0``) or, with ``short_nfev = 0``, just the
    cost at each start; then the best one converged."""
    if len(starts) == 1:
        res = solve(problem, space, space.z(starts[0]), polish_nfev, tight)
        return space.full(res.x), res
    if short_nfev == 0:
        costs = []
        for s in starts:
            r = problem.residuals(space.full(space.z(s)))
            costs.append(float(r @ r) if np.all(np.isfinite(r)) else np.inf)
        z0 = space.z(starts[int(np.argmin(costs))])
        res = solve(problem, space, z0, polish_nfev, tight)
        return space.full(res.x), res
    trials = []
    for s in starts:
        try:
            res = solve(problem, space, space.z(s), short_nfev, tight=False)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            continue
        trials.append(res)
    if not trials:
        raise RuntimeError("every start of the fit failed")
    best = min(trials, key=lambda r: r.cost)
    res = solve(problem, space, best.x, polish_nfev, tight)
    return space.full(res.x), res
