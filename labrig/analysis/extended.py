"""Base model + effects: simulation, least-squares fit and leave-one-entry-out scoring.

The numerics behind :mod:`labrig.analysis.diagnose`. :class:`ExtendedProblem` simulates the
dynamic model (the same realisation as :mod:`labrig.analysis.fit`: relaxor banks with the
record's hold, padded to whole blocks, then the quasi-static operator) with a list of effects
from :mod:`labrig.model.effects`: voltage effects transform the driving voltage of each simulated
sequence, operator effects add a strain term computed from the operator's input ``V*``,
output effects transform the strain, and nuisance effects add per-entry regressors that are
eliminated by least squares (variable projection) from every scored entry's residual.

Weighting and chaining follow :func:`labrig.analysis.fit.fit_model`: each entry's residual is
divided by its strain span and the square root of its length (the cost is the sum of squared
per-entry NRMSE), and ``chain=True`` simulates the entries back to back with their rests, so the
model's long memory and the thermal state carry over from one entry to the next.

Held-out scoring (:meth:`ExtendedProblem.heldout`): for each scored entry, the parameters are
refitted without it (it stays in the chain as history) from the full fit, and its error is
taken on the **second half** of its scored samples, in percent of the whole entry's span
(:func:`~labrig.analysis.metrics.second_half_nrmse_pct`); per-entry nuisance parameters (the offset
when ``offset=True``, mains amplitudes, drift slopes) are fitted on the first half only. Every
model, the base included, is scored on the same second halves, so their held-out NRMSE compare
like with like.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.engine import LAM_GAP, LoopScale, Problem, chord_refit, orthonormal, solve
from labrig.analysis.fit_uncertainty import fit_covariance
from labrig.analysis.metrics import second_half_nrmse_pct
from labrig.analysis.parallel import map_tasks
from labrig.analysis.records import Record, warmup_samples
from labrig.analysis.simulate import (
    EXTENDED_CONVERGED,
    LOOSE,
    PARAM_NAMES,
    OperatorFamily,
    SimSequence,
    build_sequences,
    score_segments,
)
from labrig.analysis.spectra import detect_mains_hz
from labrig.core.blas import single_thread_blas
from labrig.model import ModelParams
from labrig.model.effects import Effect

__all__ = ["DEFAULT_MAINS_HZ", "LAM_GAP", "ExtendedProblem", "FitOutcome", "effect_context"]


#: the mains frequency assumed when none is given and the data show no mains line
DEFAULT_MAINS_HZ = 50.0


def effect_context(records: Sequence[Record], mains_hz: float | None = None) -> dict:
    """How the effect library is configured for ``records`` (the keyword arguments of
    :func:`labrig.model.effects.library`): whether every record has a temperature channel and
    the amplifier's measured voltage, the mains frequency (given, else the line the strain shows
    at 50 or 60 Hz, :func:`~labrig.analysis.spectra.detect_mains_hz`, else
    :data:`DEFAULT_MAINS_HZ`), the full-scale voltage (the largest ``|V|``, the reference of
    ``quadratic_term``) and the lowest sample rate (what ``mechanical_resonance`` can resolve)."""
    return {
        "temperature": all("temperature" in r.aux for r in records),
        "amplifier_voltage": all("amplifier_voltage" in r.aux for r in records),
        "mains_hz": float(mains_hz or detect_mains_hz(records) or DEFAULT_MAINS_HZ),
        "v_ref": max(float(np.max(np.abs(r.voltage_V))) for r in records),
        "rate_hz": min(float(r.rate_hz) for r in records),
    }


@dataclass
class FitOutcome:
    """A fitted base + effects model."""

    base: dict[str, float]
    effects: dict[str, dict[str, float]]  # effect name -> its parameters
    sd: dict[str, dict[str, float | None]]  # effect name -> 1-sigma of its parameters
    base_sd: dict[str, float | None]
    per_entry: dict[str, float]  # in-sample NRMSE (whole scored samples)
    cost: float
    at_bound: dict[str, list[str]] = field(default_factory=dict)  # effect -> params at a bound
    z: NDArray | None = field(default=None, repr=False)
    nfev: int = 0

    @property
    def nrmse_pct(self) -> float:
        return float(np.mean(list(self.per_entry.values())))

    def params(self, shape: str, memory: str = "return_point") -> ModelParams:
        return OperatorFamily(shape, memory).params(self.base)


class ExtendedProblem(Problem):
    """The campaign simulated with a list of effects; fitting and held-out scoring (module
    docstring): the engine's :class:`~labrig.analysis.engine.Problem` made from records.

    ``base_free``: the base parameters left free (``FitResult.free``); the others stay at the
    values of ``base0`` given to :meth:`fit`. ``sequences``: the simulated sequences of these
    records (:func:`~labrig.analysis.simulate.build_sequences`), to share them (and their
    effect caches) between problems on the same records. Sequences with no scored entry are
    not simulated.
    """

    def __init__(
        self,
        records: Sequence[Record],
        effects: Sequence[Effect],
        *,
        chain: bool,
        shape: str = "exponential",
        memory: str = "return_point",
        scored: Sequence[str] | None = None,
        warmup_s: float = 0.0,
        offset: bool = False,
        base_free: Sequence[str] = PARAM_NAMES,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        sequences: list[SimSequence] | None = None,
        shared: Any = None,
    ):
        self.records = list(records)
        self.chain = chain
        self.shape = shape
        self.memory = memory
        self.offset = offset
        self.warmup_s = warmup_s
        ordered = [
            e
            for w in ("voltage", "operator", "output", "nuisance")
            for e in effects
            if e.where == w
        ]
        self.nui = [e for e in ordered if e.where == "nuisance"]
        self.all_sequences = (
            sequences if sequences is not None else build_sequences(self.records, chain)
        )
        names = [r.name for r in self.records]
        keep = set(names if scored is None else scored)
        seqs, segs, basis = [], [], {}
        for seq in self.all_sequences:
            chosen = score_segments(seq, keep, warmup_s)
            for g in chosen:
                basis[g.name] = orthonormal(self.nuisance_columns(g.time_s, seq.rate_hz))
            if chosen:
                seqs.append(seq)
                segs.append(chosen)
        span = max((float(np.ptp(s.voltage_V)) for s in self.all_sequences if s.n), default=0.0)
        super().__init__(
            seqs,
            segs,
            ordered,
            OperatorFamily(shape, memory),
            base_free=base_free,
            bounds=bounds,
            nuisance=basis,
            with_gd=True,
            lam_gap=True,
            shared=shared,
            loop=LoopScale(span, shape) if span > 0 else None,
        )

    # -- parameters ---------------------------------------------------------------------------
    @property
    def base_free(self) -> tuple[str, ...]:
        return self.coords.base_free

    @property
    def nuisance_basis(self) -> dict[str, NDArray | None]:
        """Orthonormal basis of each scored segment's nuisance regressors (``None``: none)."""
        return self.nuisance

    @property
    def names(self) -> list[tuple[str, str]]:
        return self.coords.names

    @property
    def lo(self) -> NDArray:
        return self.coords.lo

    @property
    def hi(self) -> NDArray:
        return self.coords.hi

    def nuisance_columns(self, t: NDArray, rate_hz: float) -> NDArray:
        """The per-entry regressors of an entry at times ``t`` (s): its offset (``offset``)
        and the nuisance effects' columns."""
        cols = [np.ones((t.size, 1))] if self.offset else []
        cols += [e.columns(t, rate_hz) for e in self.nui]
        return np.hstack(cols) if cols else np.zeros((t.size, 0))

    def z_of(self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]) -> NDArray:
        """Coordinates of base parameters and effect parameters (clipped to the bounds)."""
        return self.coords.z(base, eff)

    def unpack(self, z: NDArray, base0: Mapping[str, float]) -> tuple[dict, dict]:
        """Base parameters (the fixed ones from ``base0``) and effect parameters at ``z``."""
        return self.coords.unpack(z, base0)

    # -- fitting ------------------------------------------------------------------------------
    def fit(
        self,
        base0: Mapping[str, float],
        eff0: Mapping[str, Mapping[str, float]] | None = None,
        tight: bool = True,
        max_nfev: int | None = None,
        sd: bool = True,
    ) -> FitOutcome:
        """Least squares from ``base0`` and ``eff0`` (effects absent from it start at their
        ``init``); ``tight``: converged (with uncertainties unless ``sd`` is false), else
        loose."""
        eff0 = eff0 or {}
        z0 = self.z_of(base0, eff0)
        n0 = self.nfev
        with single_thread_blas(), np.errstate(over="ignore"):
            if z0.size:
                res = solve(self, z0, base0, max_nfev, EXTENDED_CONVERGED if tight else LOOSE)
                z = res.x
            else:
                z = z0
            r = self.residual(z, base0)
            base, eff = self.unpack(z, base0)
            sd_z = self._sd(z, base0, r) if tight and sd and z.size else np.full(z.size, np.nan)
            per = self.per_entry(base, eff)
        return self._outcome(z, base, eff, sd_z, per, 0.5 * float(r @ r), self.nfev - n0)

    def _outcome(self, z, base, eff, sd_native, per, cost, nfev) -> FitOutcome:
        """A :class:`FitOutcome`: uncertainties in native units (``sd_native`` in the order of
        :meth:`~labrig.analysis.engine.Coordinates.native_jacobian`), effect parameters on
        bounds."""
        sd: dict[str, dict[str, float | None]] = {e.name: {} for e in self.glob}
        base_sd: dict[str, float | None] = dict.fromkeys(PARAM_NAMES)
        at_bound: dict[str, list[str]] = {}
        span = self.hi - self.lo
        nb = len(self.base_free)
        for i, n in enumerate(self.base_free):
            s = float(sd_native[i])
            base_sd[n] = s if np.isfinite(s) else None
        for j, (who, n) in enumerate(self.names):
            if who == "base":
                continue
            s = float(sd_native[j]) if j >= nb else float("nan")
            sd[who][n] = s if np.isfinite(s) else None
            if min(z[j] - self.lo[j], self.hi[j] - z[j]) <= 1e-3 * span[j]:
                at_bound.setdefault(who, []).append(n)
        return FitOutcome(base, eff, sd, base_sd, per, cost, at_bound, z, nfev)

    def _sd(self, z: NDArray, base0: Mapping[str, float], r: NDArray) -> NDArray:
        """1-sigma of the free parameters in native units (base first, then the effects'),
        ``NaN`` for one the data do not determine: the pooled ``s^2 (J^T J)^+``
        (:func:`~labrig.analysis.fit_uncertainty.fit_covariance`; ``labrig fit --effect``
        takes the per-entry estimate of a plain fit instead)."""
        return fit_covariance(self, z, base0, residual=r, pooled=True).sd

    # -- held-out -----------------------------------------------------------------------------
    def fold(self, scored: Sequence[str]) -> ExtendedProblem:
        """This problem scored on ``scored`` only, sharing its simulations."""
        return ExtendedProblem(
            self.records,
            self.effects,
            chain=self.chain,
            shape=self.shape,
            memory=self.memory,
            scored=scored,
            warmup_s=self.warmup_s,
            offset=self.offset,
            base_free=self.base_free,
            bounds=self.bounds,
            sequences=self.all_sequences,
            shared=self._shared,
        )

    def heldout(
        self,
        full: FitOutcome,
        max_nfev: int = 60,
        workers: int = 1,
        progress: Callable[[int, int], Any] | None = None,
    ) -> dict[str, float]:
        """Leave-one-entry-out NRMSE (module docstring) of each scored entry: each fold refitted
        to convergence from the full fit (by the chord method on the full fit's Jacobian,
        :func:`~labrig.analysis.engine.chord_refit`, else by trust-region least squares to
        :data:`~labrig.analysis.simulate.EXTENDED_CONVERGED`, at most ``max_nfev``
        evaluations), on ``workers`` processes
        (:func:`~labrig.analysis.parallel.map_tasks`); ``progress(done, total)`` after each
        fold (in this process, one worker)."""
        names = list(self.scored)

        def fold(k: int) -> tuple[float, int]:
            name = names[k]
            sub = self.fold([n for n in names if n != name])
            with single_thread_blas(), np.errstate(over="ignore"):
                got = chord_refit(sub, sub.z_of(full.base, full.effects), full.base)
            if got is not None:
                base, eff = sub.unpack(got[0], full.base)
            else:
                fo = sub.fit(full.base, full.effects, tight=True, max_nfev=max_nfev, sd=False)
                base, eff = fo.base, fo.effects
            score = self.score_second_half(name, base, eff)
            if progress is not None and workers <= 1:
                progress(k + 1, len(names))
            return score, sub.nfev

        results = map_tasks(fold, len(names), workers)
        self.nfev += sum(n for _, n in results)
        return {name: score for name, (score, _) in zip(names, results, strict=True)}

    def score_second_half(self, name: str, base, eff) -> float:
        """NRMSE of entry ``name`` on the second half of its scored samples, nuisance terms
        fitted on the first half."""
        for seq in self.all_sequences:
            if name not in seq.entries:
                continue
            rec = next(r for r in seq.records if r.name == name)
            one = Problem([seq], [[]], self.effects, self.family, shared=self._shared)
            with single_thread_blas(), np.errstate(over="ignore"):
                y = one.strains(base, eff)[0]
            i0 = warmup_samples(rec, self.warmup_s)
            a = seq.entries[name].start
            p = y[a + i0 : a + rec.n]
            m = rec.strain_ue[i0:]
            t = rec.time_s[i0:]
            half = m.size // 2
            C = self.nuisance_columns(t, rec.rate_hz)
            if C.shape[1]:
                coef, *_ = np.linalg.lstsq(C[:half], m[:half] - p[:half], rcond=None)
                p = p + C @ coef
            return second_half_nrmse_pct(m, p)
        raise KeyError(name)
