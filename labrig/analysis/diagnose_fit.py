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

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.fit import DEFAULT_BOUNDS, PARAM_NAMES, _Family
from labrig.analysis.metrics import nrmse_pct, second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.blas import single_thread_blas
from labrig.model import ModelParams, QuasiStaticHysteresis, Relaxor
from labrig.model.effects import Context, Effect
from labrig.model.modal import run_bank

__all__ = ["ExtendedProblem", "FitOutcome", "effect_context", "mains_hz_of"]


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


_LOG = frozenset({"vc_V", "tau_t_s", "tau_d_s"})
_BLOCK = 128
_TIGHT = {"ftol": 1e-9, "xtol": 1e-9, "gtol": 1e-9}
_LOOSE = {"ftol": 1e-6, "xtol": 1e-6, "gtol": 1e-6}


@dataclass
class _Seg:
    name: str
    lo: int  # first scored sample in the sequence
    i0: int  # the same in the record
    meas: NDArray
    w: float
    t: NDArray  # the record's time at the scored samples
    Q: NDArray | None = None  # orthonormal nuisance basis (scored samples)

    @property
    def hi(self) -> int:
        return self.lo + self.meas.size


@dataclass
class _Seq:
    ctx: Context
    hold: str
    v_pad: NDArray
    segs: list[_Seg]
    starts: dict[str, int]


def _pad(v: NDArray) -> NDArray:
    out = np.empty(-(-v.size // _BLOCK) * _BLOCK)
    out[: v.size] = v
    out[v.size :] = v[-1] if v.size else 0.0
    return out


def _fill_rests(parts: list[tuple[int, NDArray | None]], n: int, rest_value: str) -> NDArray:
    """One aux channel over a chained sequence: entries' samples, rests filled by linear
    interpolation (``"interp"``, temperatures) or zeros (``"zero"``, voltages)."""
    out = np.full(n, np.nan)
    for start, x in parts:
        out[start : start + x.size] = x
    if rest_value == "zero":
        # a voltage: towards 0 V after each entry at the fastest slope seen in that entry (an
        # amplifier at its current limit is still slewing when the rest begins)
        for k, (start, x) in enumerate(parts):
            a = start + x.size
            b = parts[k + 1][0] if k + 1 < len(parts) else n
            if b <= a or x.size < 2:
                continue
            step = max(float(np.max(np.abs(np.diff(x)))), 1e-9)
            ramp = x[-1] - np.sign(x[-1]) * step * np.arange(1, b - a + 1)
            out[a:b] = np.where(np.sign(ramp) == np.sign(x[-1]), ramp, 0.0)
        return np.nan_to_num(out, nan=0.0)
    idx = np.arange(n)
    ok = np.isfinite(out)
    return np.interp(idx, idx[ok], out[ok])


def _build_sequences(records: Sequence[Record], chain: bool) -> list[tuple[list[Record], Context]]:
    groups = [list(records)] if chain else [[r] for r in records]
    out = []
    for grp in groups:
        rate = grp[0].rate_hz
        parts_v, entries, pos = [], {}, 0
        amp_parts, temp_parts = [], []
        has_amp = all("amplifier_voltage" in r.aux for r in grp)
        has_temp = all("temperature" in r.aux for r in grp)
        for r in grp:
            entries[r.name] = slice(pos, pos + r.n)
            parts_v.append(r.voltage_V)
            if has_amp:
                amp_parts.append((pos, r.aux["amplifier_voltage"]))
            if has_temp:
                temp_parts.append((pos, r.aux["temperature"]))
            pos += r.n
            rest = float(r.meta.get("rest_after_s", 0.0) or 0.0) if chain else 0.0
            n_rest = round(max(rest, 0.0) * rate)
            if n_rest:
                parts_v.append(np.zeros(n_rest))
                pos += n_rest
        v = np.concatenate(parts_v)
        ctx = Context(
            rate,
            v,
            entries,
            _fill_rests(amp_parts, v.size, "zero") if has_amp else None,
            _fill_rests(temp_parts, v.size, "interp") if has_temp else None,
        )
        out.append((grp, ctx))
    return out


def mains_hz_of(records: Sequence[Record]) -> float:
    """50 or 60 Hz: whichever carries more residual-free strain power near it (a guess from the
    measurement itself; mains lines are rarely drive harmonics at both)."""
    p50 = p60 = 0.0
    for r in records:
        x = r.strain_ue - np.mean(r.strain_ue)
        if x.size < 512:
            continue
        spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
        f = np.fft.rfftfreq(x.size, 1 / r.rate_hz)
        for fm in (50.0, 60.0):
            band = np.abs(f - fm) < 1.0
            if band.any():
                val = float(spec[band].max()) / (float(np.median(spec)) + 1e-12)
                if fm == 50.0:
                    p50 += val
                else:
                    p60 += val
    return 60.0 if p60 > 1.5 * p50 else 50.0


def effect_context(records: Sequence[Record], mains_hz: float | None = None) -> dict:
    """How the effect library is configured for ``records`` (the keyword arguments of
    :func:`labrig.model.effects.library`): whether every record has a temperature channel and
    the amplifier's measured voltage, the mains frequency (:func:`mains_hz_of` unless given) and
    the full-scale voltage (the largest ``|V|``, the reference of ``quadratic_term``)."""
    return {
        "temperature": all("temperature" in r.aux for r in records),
        "amplifier_voltage": all("amplifier_voltage" in r.aux for r in records),
        "mains_hz": float(mains_hz or mains_hz_of(records)),
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
        return _Family(shape, memory).params(self.base)


class ExtendedProblem:
    """The campaign simulated with a list of effects; fitting and held-out scoring.

    ``base_free``: the base parameters left free (``FitResult.free``); the others stay at the
    values of ``base0`` given to :meth:`fit`.
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
        contexts: list[tuple[list[Record], Context]] | None = None,
    ):
        self.records = list(records)
        self.effects = list(effects)
        self.chain = chain
        self.shape = shape
        self.memory = memory
        self.family = _Family(shape, memory)
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
        self.groups = contexts if contexts is not None else _build_sequences(self.records, chain)
        self.seqs: list[_Seq] = []
        keep = set(self.scored)
        for grp, ctx in self.groups:
            segs = []
            starts = {r.name: ctx.entries[r.name].start for r in grp}
            for r in grp:
                if r.name not in keep:
                    continue
                i0 = round(max(warmup_s, 0.0) * r.rate_hz)
                meas = np.asarray(r.strain_ue[i0:], dtype=float)
                span = float(np.ptp(meas))
                if not span > 0:
                    raise ValueError(f"entry {r.name!r}: constant strain, NRMSE undefined")
                seg = _Seg(
                    r.name,
                    starts[r.name] + i0,
                    i0,
                    meas,
                    1 / (span * np.sqrt(meas.size)),
                    r.time_s[i0:],
                )
                C = self.nuisance_columns(seg.t, r.rate_hz)
                seg.Q = _orthonormal(C)
                segs.append(seg)
            self.seqs.append(_Seq(ctx, grp[0].hold, _pad(ctx.v), segs, starts))
        # parameter vector: free base parameters, then the effects' parameters
        self.names: list[tuple[str, str]] = [("base", n) for n in self.base_free]
        lo, hi, step = [], [], []
        for n in self.base_free:
            a, b = self.bounds[n]
            if n in _LOG:
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
        self._cache: OrderedDict = OrderedDict()
        self.nfev = 0

    # -- parameters ---------------------------------------------------------------------------
    def nuisance_columns(self, t: NDArray, rate_hz: float) -> NDArray:
        cols = [np.ones((t.size, 1))] if self.offset else []
        cols += [e.columns(t, rate_hz) for e in self.nui]
        return np.hstack(cols) if cols else np.zeros((t.size, 0))

    def z_of(self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]) -> NDArray:
        z = []
        for who, n in self.names:
            if who == "base":
                x = float(base[n])
                z.append(np.log(x) if n in _LOG else _lam_to_z(x) if n == "lam_d" else x)
            else:
                e = next(e for e in self.effects if e.name == who)
                q = next(q for q in e.params if q.name == n)
                x = float(eff.get(who, {}).get(n, q.init))
                z.append(np.log(x) if q.log else x)
        z = np.array(z, float)
        pad = 1e-10 * np.maximum(1.0, np.abs(self.lo))
        padh = 1e-10 * np.maximum(1.0, np.abs(self.hi))
        return np.clip(z, self.lo + pad * 0, self.hi - padh * 0)

    def unpack(self, z: NDArray, base0: Mapping[str, float]) -> tuple[dict, dict]:
        base = {n: float(base0[n]) for n in PARAM_NAMES}
        eff: dict[str, dict[str, float]] = {e.name: {} for e in self.glob}
        for (who, n), x in zip(self.names, z, strict=True):
            if who == "base":
                base[n] = (
                    float(np.exp(x)) if n in _LOG else _z_to_lam(x) if n == "lam_d" else float(x)
                )
            else:
                e = next(e for e in self.effects if e.name == who)
                q = next(q for q in e.params if q.name == n)
                eff[who][n] = float(np.exp(x)) if q.log else float(x)
        return base, eff

    # -- simulation ---------------------------------------------------------------------------
    def _get(self, key, make):
        hit = self._cache.get(key)
        if hit is None:
            hit = make()
            self._cache[key] = hit
            while len(self._cache) > 48:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        return hit

    def _vd(self, base: Mapping[str, float], eff: Mapping[str, Mapping[str, float]]):
        """``V* = G_d G_t V'`` of each sequence (``V'``: the voltage effects applied)."""
        vkey = tuple((e.name, tuple(sorted(eff.get(e.name, {}).items()))) for e in self.vol)
        lt, tt, ld, td = base["lam_t"], base["tau_t_s"], base["lam_d"], base["tau_d_s"]
        out = []
        for k, s in enumerate(self.seqs):
            ctx = s.ctx

            def vt(s=s, ctx=ctx):
                v = ctx.v
                for e in self.vol:
                    v = e.apply(v, ctx, eff.get(e.name, {}))
                vin = _pad(v) if self.vol else s.v_pad
                with np.errstate(over="ignore"):
                    b = Relaxor(tt, lt).bank(ctx.rate_hz, s.hold)
                return run_bank(b, vin, block=_BLOCK)[0]

            x_t = self._get(("t", k, vkey, lt, tt), vt)

            def vd(ctx=ctx, x_t=x_t):
                with np.errstate(over="ignore"):
                    b = Relaxor(td, ld).bank(ctx.rate_hz, "linear")
                return run_bank(b, x_t, block=_BLOCK)[0][: ctx.n]

            out.append(self._get(("d", k, vkey, lt, tt, ld, td), vd))
        return out

    def _op(self, base: Mapping[str, float]) -> QuasiStaticHysteresis:
        return self.family.operator(base["alpha0_ue_per_V"], base["gamma_ue_per_V"], base["vc_V"])

    def _post(self, ys: list[NDArray], eff) -> list[NDArray]:
        out = []
        for s, y in zip(self.seqs, ys, strict=True):
            for e in self.out:
                y = e.apply(y, s.ctx, eff.get(e.name, {}))
            out.append(y)
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
            [op.apply(x) + self._beside(x, s.ctx, eff) for x, s in zip(xs, self.seqs, strict=True)],
            eff,
        )

    def _resid(self, ys: list[NDArray], subtract: bool = True) -> NDArray:
        parts = []
        for s, y in zip(self.seqs, ys, strict=True):
            for g in s.segs:
                d = y[g.lo : g.hi] - g.meas if subtract else y[g.lo : g.hi]
                if g.Q is not None:
                    d = d - g.Q @ (g.Q.T @ d)
                parts.append(g.w * d)
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
        beside0 = [self._beside(x, s.ctx, eff) for x, s in zip(vd0, self.seqs, strict=True)]
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
                op.tangent(x, (xp - x) / h) + (self._beside(xp, s.ctx, eff) - b0) / h
                for x, xp, s, b0 in zip(vd0, vdp, self.seqs, beside0, strict=True)
            ]
            J[:, j] = self._resid(self._post(ds, eff), subtract=False)
        return J

    def per_entry(self, base, eff) -> dict[str, float]:
        """In-sample NRMSE of each scored entry (nuisance terms fitted on the whole entry)."""
        out = {}
        for s, y in zip(self.seqs, self.strains(base, eff), strict=True):
            for g in s.segs:
                p = y[g.lo : g.hi]
                if g.Q is not None:
                    p = p + g.Q @ (g.Q.T @ (g.meas - p))
                out[g.name] = nrmse_pct(g.meas, p)
        return out

    def predictions(self, base, eff) -> dict[str, NDArray]:
        """Each scored entry's modelled strain over its whole record (nuisance fitted on the
        scored samples), for plots and residual evidence."""
        out = {}
        for s, y in zip(self.seqs, self.strains(base, eff), strict=True):
            for g in s.segs:
                a = s.starts[g.name]
                p = y[a : g.hi].copy()
                if g.Q is not None:
                    q = p[g.i0 :]
                    corr = g.Q @ (g.Q.T @ (g.meas - q))
                    p[g.i0 :] = q + corr
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
        eff0 = eff0 or {}
        z0 = self.z_of(base0, eff0)
        n0 = self.nfev
        with single_thread_blas(), np.errstate(over="ignore"):
            if z0.size:
                res = optimize.least_squares(
                    lambda z: self.residual(z, base0),
                    z0,
                    jac=lambda z: self.jacobian(z, base0),
                    bounds=(self.lo, self.hi),
                    method="trf",
                    x_scale="jac",
                    max_nfev=max_nfev,
                    **(_TIGHT if tight else _LOOSE),
                )
                z = res.x
            else:
                z = z0
            r = self.residual(z, base0)
            base, eff = self.unpack(z, base0)
            sd_z = self._sd(z, base0, r) if tight and z.size else np.full(z.size, np.nan)
            per = self.per_entry(base, eff)
        sd: dict[str, dict[str, float | None]] = {e.name: {} for e in self.glob}
        base_sd: dict[str, float | None] = dict.fromkeys(PARAM_NAMES)
        at_bound: dict[str, list[str]] = {}
        span = self.hi - self.lo
        for j, (who, n) in enumerate(self.names):
            val = np.exp(z[j]) if (n in _LOG if who == "base" else self._is_log(who, n)) else z[j]
            is_log = n in _LOG if who == "base" else self._is_log(who, n)
            s = float(sd_z[j] * val) if is_log else float(sd_z[j])
            s = s if np.isfinite(s) else None
            if who == "base":
                base_sd[n] = s
            else:
                sd[who][n] = s
                if min(z[j] - self.lo[j], self.hi[j] - z[j]) <= 1e-3 * span[j]:
                    at_bound.setdefault(who, []).append(n)
        return FitOutcome(
            base, eff, sd, base_sd, per, 0.5 * float(r @ r), at_bound, z, self.nfev - n0
        )

    def _is_log(self, who: str, n: str) -> bool:
        e = next(e for e in self.effects if e.name == who)
        return next(q for q in e.params if q.name == n).log

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
                contexts=self.groups,
            )
            fo = sub.fit(full.base, full.effects, tight=False, max_nfev=max_nfev)
            self.nfev += sub.nfev
            out[name] = self.score_second_half(name, fo.base, fo.effects)
        return out

    def score_second_half(self, name: str, base, eff) -> float:
        """NRMSE of entry ``name`` on the second half of its scored samples, nuisance terms
        fitted on the first half."""
        for k, (_seq, (grp, ctx)) in enumerate(zip(self.seqs, self.groups, strict=True)):
            if name not in ctx.entries:
                continue
            rec = next(r for r in grp if r.name == name)
            with single_thread_blas(), np.errstate(over="ignore"):
                y = self.strains(base, eff)[k]
            i0 = round(max(self.warmup_s, 0.0) * rec.rate_hz)
            a = ctx.entries[name].start
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
