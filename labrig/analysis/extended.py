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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.metrics import nrmse_pct, second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import (
    DEFAULT_BOUNDS,
    EXTENDED_CONVERGED,
    LOG_PARAMS,
    LOOSE,
    PARAM_NAMES,
    LRUCache,
    OperatorFamily,
    Segment,
    SimSequence,
    bounded_least_squares,
    build_sequences,
    pad_to_block,
    relaxor_output,
    score_segments,
)
from labrig.analysis.spectra import detect_mains_hz
from labrig.core.blas import single_thread_blas
from labrig.model import ModelParams, QuasiStaticHysteresis
from labrig.model.effects import Context, Effect

__all__ = ["DEFAULT_MAINS_HZ", "LAM_GAP", "ExtendedProblem", "FitOutcome", "effect_context"]


#: the relaxor realisation is discontinuous at lam = 1 (a single pole at 1, a modal bank with
#: twice the impulse response at 1 + 1e-7, 1 % off at 1.001): lam_d skips (1 - gap, 1 + gap)
LAM_GAP = 0.01


def _lam_to_z(lam: float) -> float:
    if lam <= 1.0 - LAM_GAP:
        return lam
    if lam >= 1.0 + LAM_GAP:
        return lam - 2 * LAM_GAP
    return 1.0 - LAM_GAP if lam < 1.0 else 1.0 - LAM_GAP + 1e-9


def _z_to_lam(z: float) -> float:
    return float(z) if z <= 1.0 - LAM_GAP else float(z) + 2 * LAM_GAP


#: the mains frequency assumed when none is given and the data show no mains line
DEFAULT_MAINS_HZ = 50.0


def effect_context(records: Sequence[Record], mains_hz: float | None = None) -> dict:
    """How the effect library is configured for ``records`` (the keyword arguments of
    :func:`labrig.model.effects.library`): whether every record has a temperature channel and
    the amplifier's measured voltage, the mains frequency (given, else the line the strain shows
    at 50 or 60 Hz, :func:`~labrig.analysis.spectra.detect_mains_hz`, else
    :data:`DEFAULT_MAINS_HZ`) and the full-scale voltage (the largest ``|V|``, the reference of
    ``quadratic_term``)."""
    return {
        "temperature": all("temperature" in r.aux for r in records),
        "amplifier_voltage": all("amplifier_voltage" in r.aux for r in records),
        "mains_hz": float(mains_hz or detect_mains_hz(records) or DEFAULT_MAINS_HZ),
        "v_ref": max(float(np.max(np.abs(r.voltage_V))) for r in records),
    }


def _orthonormal(C: NDArray) -> NDArray | None:
    if C.shape[1] == 0:
        return None
    u, s, _ = np.linalg.svd(C, full_matrices=False)
    keep = s > s[0] * 1e-9
    return u[:, keep]


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


class ExtendedProblem:
    """The campaign simulated with a list of effects; fitting and held-out scoring.

    ``base_free``: the base parameters left free (``FitResult.free``); the others stay at the
    values of ``base0`` given to :meth:`fit`. ``sequences``: the simulated sequences of these
    records (:func:`~labrig.analysis.simulate.build_sequences`), to share them (and their
    effect caches) between problems on the same records.
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
    ):
        self.records = list(records)
        self.effects = list(effects)
        self.chain = chain
        self.shape = shape
        self.memory = memory
        self.family = OperatorFamily(shape, memory)
        self.offset = offset
        self.warmup_s = warmup_s
        self.base_free = tuple(base_free)
        self.bounds = dict(DEFAULT_BOUNDS)
        self.bounds.update(bounds or {})
        names = [r.name for r in self.records]
        self.scored = list(names if scored is None else [n for n in names if n in set(scored)])
        self.vol = [e for e in self.effects if e.where == "voltage"]
        self.out = [e for e in self.effects if e.where == "output"]
        self.opr = [e for e in self.effects if e.where == "operator"]
        self.glob = self.vol + self.opr + self.out  # fitted as global parameters
        self.nui = [e for e in self.effects if e.where == "nuisance"]
        self.sequences = (
            sequences if sequences is not None else build_sequences(self.records, chain)
        )
        keep = set(self.scored)
        self.segments: list[list[Segment]] = []
        #: orthonormal basis of each segment's nuisance regressors (``None`` without any)
        self.nuisance_basis: dict[str, NDArray | None] = {}
        for seq in self.sequences:
            segs = score_segments(seq, keep, warmup_s)
            for g in segs:
                self.nuisance_basis[g.name] = _orthonormal(
                    self.nuisance_columns(g.time_s, seq.rate_hz)
                )
            self.segments.append(segs)
        self._init_parameters()
        self._cache = LRUCache(48)
        self.nfev = 0

    def _init_parameters(self) -> None:
        """The parameter vector: free base parameters, then the effects' parameters."""
        self.names: list[tuple[str, str]] = [("base", n) for n in self.base_free]
        lo, hi, step = [], [], []
        for n in self.base_free:
            a, b = self.bounds[n]
            if n in LOG_PARAMS:
                a, b = np.log(a), np.log(b)
            elif n == "lam_d" and b > 1.0 + LAM_GAP:
                b = b - 2 * LAM_GAP
            lo.append(a)
            hi.append(b)
            step.append(None)
        for e in self.glob:
            for q in e.params:
                self.names.append((e.name, q.name))
                a, b = (np.log(q.lo), np.log(q.hi)) if q.log else (q.lo, q.hi)
                lo.append(a)
                hi.append(b)
                step.append(1e-5 * (b - a))
        self.lo, self.hi = np.array(lo, float), np.array(hi, float)
        self._step = step

    # -- parameters ---------------------------------------------------------------------------
    def nuisance_columns(self, t: NDArray, rate_hz: float) -> NDArray:
        """The per-entry regressors of an entry at times ``t`` (s): its offset (``offset``)
        and the nuisance effects' columns."""
        cols = [np.ones((t.size, 1))] if self.offset else []
        cols += [e.columns(t, rate_hz) for e in self.nui]
        return np.hstack(cols) if cols else np.zeros((t.size, 0))

    def _param(self, who: str, n: str):
        e = next(e for e in self.effects if e.name == who)
        return next(q for q in e.params if q.name == n)

    def _is_log(self, who: str, n: str) -> bool:
        return n in LOG_PARAMS if who == "base" else self._param(who, n).log

    def z_of(self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]) -> NDArray:
        """Coordinates of base parameters and effect parameters (clipped to the bounds)."""
        z = []
        for who, n in self.names:
            if who == "base":
                x = float(base[n])
                z.append(np.log(x) if n in LOG_PARAMS else _lam_to_z(x) if n == "lam_d" else x)
            else:
                q = self._param(who, n)
                x = float(eff.get(who, {}).get(n, q.init))
                z.append(np.log(x) if q.log else x)
        return np.clip(np.array(z, float), self.lo, self.hi)

    def unpack(self, z: NDArray, base0: Mapping[str, float]) -> tuple[dict, dict]:
        """Base parameters (the fixed ones from ``base0``) and effect parameters at ``z``."""
        base = {n: float(base0[n]) for n in PARAM_NAMES}
        eff: dict[str, dict[str, float]] = {e.name: {} for e in self.glob}
        for (who, n), x in zip(self.names, z, strict=True):
            if who == "base":
                base[n] = (
                    float(np.exp(x))
                    if n in LOG_PARAMS
                    else _z_to_lam(x)
                    if n == "lam_d"
                    else float(x)
                )
            else:
                eff[who][n] = float(np.exp(x)) if self._param(who, n).log else float(x)
        return base, eff

    # -- simulation ---------------------------------------------------------------------------
    def _vd(
        self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]
    ) -> list[tuple[NDArray, float]]:
        """``(V*, rest)`` of each sequence: ``V* = G_d G_t V'`` (``V'``: the voltage effects
        applied), the actuator held before it at ``rest`` (V), the sequence's rest voltage
        through the voltage effects (the first sample of ``V'`` when the sequence begins at a
        held voltage, else 0 V)."""
        vkey = tuple((e.name, tuple(sorted(eff.get(e.name, {}).items()))) for e in self.vol)
        lt, tt, ld, td = base["lam_t"], base["tau_t_s"], base["lam_d"], base["tau_d_s"]
        out = []
        for k, seq in enumerate(self.sequences):

            def vt(seq=seq):
                v = seq.voltage_V
                for e in self.vol:
                    v = e.apply(v, seq.context, eff.get(e.name, {}))
                vin = pad_to_block(v) if self.vol else seq.padded
                rest = float(v[0]) if seq.rest_V != 0.0 else 0.0
                return relaxor_output(tt, lt, seq.rate_hz, seq.hold, vin, rest), rest

            x_t, rest = self._cache.get(("t", k, vkey, lt, tt), vt)

            def vd(seq=seq, x_t=x_t, rest=rest):
                return relaxor_output(td, ld, seq.rate_hz, "linear", x_t, rest)[: seq.n], rest

            out.append(self._cache.get(("d", k, vkey, lt, tt, ld, td), vd))
        return out

    def _op(self, base: Mapping[str, float]) -> QuasiStaticHysteresis:
        return self.family.operator(base["alpha0_ue_per_V"], base["gamma_ue_per_V"], base["vc_V"])

    def _post(self, ys: list[NDArray], eff) -> list[NDArray]:
        out = []
        for seq, y in zip(self.sequences, ys, strict=True):
            for e in self.out:
                y = e.apply(y, seq.context, eff.get(e.name, {}))
            out.append(y)
        return out

    def _post_tangent(self, ys: list[NDArray], ds: list[NDArray], eff) -> list[NDArray]:
        """The strain derivatives ``ds`` (at the strains ``ys``) carried through the output
        effects (:meth:`~labrig.model.effects.Effect.tangent`)."""
        out = []
        for seq, y, d in zip(self.sequences, ys, ds, strict=True):
            for e in self.out:
                p = eff.get(e.name, {})
                d = e.tangent(y, d, seq.context, p)
                y = e.apply(y, seq.context, p)
            out.append(d)
        return out

    def _beside(self, x: NDArray, ctx: Context, eff) -> NDArray | float:
        """The operator effects' strain terms for the operator input ``x`` (0 without any)."""
        out: NDArray | float = 0.0
        for e in self.opr:
            out = out + e.apply(x, ctx, eff.get(e.name, {}))
        return out

    def strains(self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]):
        """Modelled strain over each simulated sequence (before nuisance terms)."""
        op = self._op(base)
        xs = self._vd(base, eff)
        return self._post(
            [
                op.apply(x, op.held_state(rest)) + self._beside(x, seq.context, eff)
                for (x, rest), seq in zip(xs, self.sequences, strict=True)
            ],
            eff,
        )

    def _project_out(self, g: Segment, d: NDArray) -> NDArray:
        """``d`` with the segment's nuisance regressors projected out."""
        Q = self.nuisance_basis[g.name]
        return d if Q is None else d - Q @ (Q.T @ d)

    def _resid(self, ys: list[NDArray], subtract: bool = True) -> NDArray:
        parts = []
        for segs, y in zip(self.segments, ys, strict=True):
            for g in segs:
                d = y[g.lo : g.hi] - g.measured_ue if subtract else y[g.lo : g.hi]
                parts.append(g.weight * self._project_out(g, d))
        return np.concatenate(parts) if parts else np.zeros(0)

    def residual(self, z: NDArray, base0: Mapping[str, float]) -> NDArray:
        self.nfev += 1
        base, eff = self.unpack(z, base0)
        return self._resid(self.strains(base, eff))

    def jacobian(self, z: NDArray, base0: Mapping[str, float], r0: NDArray | None = None):
        """Forward differences; for the parameters that move ``V*`` (relaxors, voltage effects)
        the operator is differentiated with its branch structure frozen
        (:meth:`~labrig.model.QuasiStaticHysteresis.tangent`): with the ``"last_reversal"``
        memory the operator jumps when a tiny wiggle of ``V*`` (relaxor overshoot during a
        rest) appears or disappears, which makes plain differences of it meaningless; with
        return-point memory it is continuous but has kinks where loops close."""
        if r0 is None:
            r0 = self.residual(z, base0)
        base, eff = self.unpack(z, base0)
        op = self._op(base)
        vd0 = self._vd(base, eff)
        vol_names = {e.name for e in self.vol}
        ctxs = [seq.context for seq in self.sequences]
        beside0 = [self._beside(x, c, eff) for (x, _), c in zip(vd0, ctxs, strict=True)]
        ys0 = [
            op.apply(x, op.held_state(rest)) + b for (x, rest), b in zip(vd0, beside0, strict=True)
        ]
        J = np.empty((r0.size, z.size))
        for j, (who, n) in enumerate(self.names):
            h = self._step[j] if self._step[j] is not None else 1e-6 * max(1.0, abs(z[j]))
            if z[j] + h > self.hi[j]:
                h = -h
            zp = z.copy()
            zp[j] += h
            moves_vd = (who == "base" and n in ("lam_t", "tau_t_s", "lam_d", "tau_d_s")) or (
                who in vol_names
            )
            if not moves_vd:
                J[:, j] = (self.residual(zp, base0) - r0) / h
                continue
            bp, ep = self.unpack(zp, base0)
            vdp = self._vd(bp, ep)
            ds = [
                op.tangent(x, (xp - x) / h, rest) + (self._beside(xp, c, eff) - b0) / h
                for (x, rest), (xp, _), c, b0 in zip(vd0, vdp, ctxs, beside0, strict=True)
            ]
            J[:, j] = self._resid(self._post_tangent(ys0, ds, eff), subtract=False)
        return J

    def _with_nuisance(self, g: Segment, p: NDArray) -> NDArray:
        """Prediction ``p`` of segment ``g`` plus its nuisance terms fitted on the whole
        segment."""
        Q = self.nuisance_basis[g.name]
        return p if Q is None else p + Q @ (Q.T @ (g.measured_ue - p))

    def per_entry(self, base, eff) -> dict[str, float]:
        """In-sample NRMSE of each scored entry (nuisance terms fitted on the whole entry)."""
        out = {}
        for segs, y in zip(self.segments, self.strains(base, eff), strict=True):
            for g in segs:
                out[g.name] = nrmse_pct(g.measured_ue, self._with_nuisance(g, y[g.lo : g.hi]))
        return out

    def predictions(self, base, eff) -> dict[str, NDArray]:
        """Each scored entry's modelled strain over its whole record (nuisance fitted on the
        scored samples), for plots and residual evidence."""
        out = {}
        ys = self.strains(base, eff)
        for seq, segs, y in zip(self.sequences, self.segments, ys, strict=True):
            for g in segs:
                p = y[seq.entries[g.name].start : g.hi].copy()
                p[g.i0 :] = self._with_nuisance(g, p[g.i0 :])
                out[g.name] = p
        return out

    # -- fitting ------------------------------------------------------------------------------
    def fit(
        self,
        base0: Mapping[str, float],
        eff0: Mapping[str, Mapping[str, float]] | None = None,
        tight: bool = True,
        max_nfev: int | None = None,
    ) -> FitOutcome:
        """Least squares from ``base0`` and ``eff0`` (effects absent from it start at their
        ``init``); ``tight``: converged (with uncertainties), else loose."""
        eff0 = eff0 or {}
        z0 = self.z_of(base0, eff0)
        n0 = self.nfev
        with single_thread_blas(), np.errstate(over="ignore"):
            if z0.size:
                res = bounded_least_squares(
                    lambda z: self.residual(z, base0),
                    lambda z: self.jacobian(z, base0),
                    z0,
                    (self.lo, self.hi),
                    max_nfev,
                    EXTENDED_CONVERGED if tight else LOOSE,
                )
                z = res.x
            else:
                z = z0
            r = self.residual(z, base0)
            base, eff = self.unpack(z, base0)
            sd_z = self._sd(z, base0, r) if tight and z.size else np.full(z.size, np.nan)
            per = self.per_entry(base, eff)
        return self._outcome(z, base, eff, sd_z, per, 0.5 * float(r @ r), self.nfev - n0)

    def _outcome(self, z, base, eff, sd_z, per, cost, nfev) -> FitOutcome:
        """A :class:`FitOutcome`: uncertainties in native units, effect parameters on bounds."""
        sd: dict[str, dict[str, float | None]] = {e.name: {} for e in self.glob}
        base_sd: dict[str, float | None] = dict.fromkeys(PARAM_NAMES)
        at_bound: dict[str, list[str]] = {}
        span = self.hi - self.lo
        for j, (who, n) in enumerate(self.names):
            is_log = self._is_log(who, n)
            s = float(sd_z[j] * np.exp(z[j])) if is_log else float(sd_z[j])
            s = s if np.isfinite(s) else None
            if who == "base":
                base_sd[n] = s
            else:
                sd[who][n] = s
                if min(z[j] - self.lo[j], self.hi[j] - z[j]) <= 1e-3 * span[j]:
                    at_bound.setdefault(who, []).append(n)
        return FitOutcome(base, eff, sd, base_sd, per, cost, at_bound, z, nfev)

    def _sd(self, z, base0, r) -> NDArray:
        J = self.jacobian(z, base0, r)
        dof = max(r.size - z.size, 1)
        s2 = float(r @ r) / dof
        try:
            scale = np.linalg.norm(J, axis=0)
            scale[scale == 0] = 1.0
            cov = np.linalg.pinv((J / scale).T @ (J / scale)) / np.outer(scale, scale)
            return np.sqrt(np.clip(np.diag(cov) * s2, 0, None))
        except np.linalg.LinAlgError:
            return np.full(z.size, np.nan)

    # -- held-out -----------------------------------------------------------------------------
    def heldout(self, full: FitOutcome, max_nfev: int = 25) -> dict[str, float]:
        """Leave-one-entry-out NRMSE (module docstring) of each scored entry."""
        out = {}
        for name in self.scored:
            rest = [n for n in self.scored if n != name]
            sub = ExtendedProblem(
                self.records,
                self.effects,
                chain=self.chain,
                shape=self.shape,
                memory=self.memory,
                scored=rest,
                warmup_s=self.warmup_s,
                offset=self.offset,
                base_free=self.base_free,
                bounds=self.bounds,
                sequences=self.sequences,
            )
            fo = sub.fit(full.base, full.effects, tight=False, max_nfev=max_nfev)
            self.nfev += sub.nfev
            out[name] = self.score_second_half(name, fo.base, fo.effects)
        return out

    def score_second_half(self, name: str, base, eff) -> float:
        """NRMSE of entry ``name`` on the second half of its scored samples, nuisance terms
        fitted on the first half."""
        for k, seq in enumerate(self.sequences):
            if name not in seq.entries:
                continue
            rec = next(r for r in seq.records if r.name == name)
            with single_thread_blas(), np.errstate(over="ignore"):
                y = self.strains(base, eff)[k]
            i0 = round(max(self.warmup_s, 0.0) * rec.rate_hz)
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
