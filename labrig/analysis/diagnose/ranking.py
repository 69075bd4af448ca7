"""Ranking candidate effects for ``labrig diagnose``: a score test used as a ranking.

Each candidate's direction is the change of the weighted residual when the effect moves from its
null value to a small physical probe value (several probes for threshold-like effects; the
per-entry regressors for nuisance effects). It is projected off the current model's Jacobian
(what the model can already absorb by moving its own parameters), and the share of the residual
the projected direction explains (with the physical sign, by non-negative least squares where
the effect has one) ranks the candidates. This is a Lagrange-multiplier test used for ordering,
not a p-value: the decision is made on held-out data (:mod:`.acceptance`).

An effect with a ``note_base(base)`` method (``mechanical_resonance``: whether the base's
``G_d`` is itself a resonance) is shown the base parameters it is ranked against, for its
description; its ranking is not changed by it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.diagnose.state import Settings, Setup
from labrig.analysis.extended import ExtendedProblem, FitOutcome
from labrig.core.blas import single_thread_blas
from labrig.model.effects import Effect

__all__ = ["jacobian_basis", "nuisance_directions", "rank"]


def jacobian_basis(J: NDArray) -> NDArray:
    """An orthonormal basis of the (column-scaled) Jacobian ``J``: the directions the model can
    absorb by moving its own parameters."""
    if J.shape[1] == 0:
        return np.zeros((J.shape[0], 0))
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    u, s, _ = np.linalg.svd(J / scale, full_matrices=False)
    return u[:, s > s[0] * 1e-8] if s.size and s[0] > 0 else np.zeros((J.shape[0], 0))


def nuisance_directions(prob: ExtendedProblem, eff: Effect) -> NDArray:
    """The weighted per-entry regressors of a nuisance effect over every scored segment of
    ``prob`` (one block of columns per segment, zero elsewhere), each with the segment's own
    nuisance regressors projected out."""
    blocks, pos, cols = [], 0, []
    for seq, segs in zip(prob.sequences, prob.segments, strict=True):
        for g in segs:
            C = eff.columns(g.time_s, seq.rate_hz)
            Q = prob.nuisance_basis[g.name]
            if Q is not None:
                C = C - Q @ (Q.T @ C)
            blocks.append((pos, g.weight * C))
            pos += g.measured_ue.size
    n = pos
    for start, C in blocks:
        M = np.zeros((n, C.shape[1]))
        M[start : start + C.shape[0]] = C
        cols.append(M)
    return np.hstack(cols) if cols else np.zeros((n, 0))


def rank(
    current: Sequence[Effect],
    cur: FitOutcome,
    cur_prob: ExtendedProblem,
    candidates: Sequence[Effect],
    setup: Setup,
    settings: Settings,
) -> list[tuple[Effect, float, dict[str, float]]]:
    """(effect, explained share, best probe) for each candidate, best first."""
    with single_thread_blas(), np.errstate(over="ignore", invalid="ignore"):
        r = cur_prob.residual(cur.z, cur.base)
        B = jacobian_basis(cur_prob.jacobian(cur.z, cur.base))
        rr = float(r @ r)
        out = []
        for eff in candidates:
            probe_best: dict[str, float] = eff.init
            note_base = getattr(eff, "note_base", None)
            if callable(note_base):  # an effect the base can mimic reads the base it meets
                note_base(cur.base)
            if eff.where == "nuisance":
                D = nuisance_directions(cur_prob, eff)
                D = D - B @ (B.T @ D)
                coef, *_ = np.linalg.lstsq(D, -r, rcond=None)
                expl = float(np.sum((D @ coef) ** 2)) / rr if rr > 0 else 0.0
                out.append((eff, expl, probe_best))
                continue
            prob = setup.problem(settings, [*current, eff])
            r0 = r  # the effect at its null value (or, without parameters, absent)
            cols, costs, probes = [], [], eff.probes([s.context for s in prob.sequences])
            for p in probes:
                rp = prob.residual(prob.z_of(cur.base, {**cur.effects, eff.name: p}), cur.base)
                cols.append(rp - r0)
                costs.append(float(rp @ rp))
            D = np.column_stack(cols)
            D = D - B @ (B.T @ D)
            if not np.any(D):
                out.append((eff, 0.0, probe_best))
                continue
            signed = any(q.sign > 0 for q in eff.params) or not eff.params
            if signed:
                coef, _ = optimize.nnls(D, -r0)
            else:
                coef, *_ = np.linalg.lstsq(D, -r0, rcond=None)
            expl = float(np.sum((D @ coef) ** 2)) / rr if rr > 0 else 0.0
            # start the refit from the probe with the lowest cost
            probe_best = probes[int(np.argmin(costs))]
            out.append((eff, min(expl, 1.0), probe_best))
    return sorted(out, key=lambda x: -x[1])
