"""``labrig diagnose``: from the residual to the missing physical effect, judged on held-out data.

Procedure (spec ``residuals.md``, "a procedure that does not fool itself")
------------------------------------------------------------------------
1. **Base fit to convergence**: :func:`labrig.analysis.fit.fit_model` (staged starts, global
   least squares, tight tolerances), then polished by the same engine that fits the extended
   models (:class:`~labrig.analysis.diagnose_fit.ExtendedProblem`), so "before" and "after" are
   computed alike.
2. **Residual evidence** (:mod:`labrig.analysis.diagnose_evidence`): noise floor from
   period-to-period differences, harmonic tables, scaling with frequency and amplitude,
   correlation with ``|dV/dt|``, ``V^2``, the input, the temperature, the amplifier's measured
   voltage, spectral lines. Evidence is for the report and the ranking, never the decision.
3. **Ranking** (a score / Lagrange-multiplier test used as a ranking, not a p-value): each
   candidate's direction (the change of the weighted residual when the effect is moved from its
   null value to a small physical probe value; several probes for threshold-like effects; the
   per-entry regressors for nuisance effects) is projected off the current model's Jacobian,
   and the share of the residual it explains (with the physical sign) ranks the candidates.
4. **Refit** base + candidate with every parameter free within physical bounds, for the
   ``top_k`` best ranked (default 3). A candidate whose in-sample gain is below half the minimum
   gain is not cross-validated (a held-out gain is not larger than the in-sample one).
5. **Held-out NRMSE**, leave-one-entry-out: each entry is predicted by a fit that never saw it
   (in a chained run it stays as history); per-entry nuisance parameters are fitted on the first
   half of the held-out entry and every model is scored on the second halves.
6. **Acceptance rule** (:data:`MIN_GAIN`, :func:`accept`): the held-out mean NRMSE drops by at
   least 15 % relative; the candidate is better (by more than 2 %) in at least two folds and in
   at least twice as many folds as it is worse; none of its physical parameters ends on a bound
   or on the wrong side of its null value. Among the candidates that pass, the lowest held-out
   NRMSE is added; the procedure repeats from the extended model (at most ``max_effects``).
7. **Verdict**: "consistent with noise" when nothing was added and the residual is within
   :data:`AT_FLOOR` times the noise floor; "unexplained" when nothing passed but the residual is
   above it; "explained" when the added effects bring the residual to the floor with plausible
   parameters; "partially explained" otherwise. Confusable runner-ups (candidates within
   :data:`CONFUSABLE_MARGIN` of the winner's gain) are named with the experiment that would tell
   them apart. An effect's own caveats (:meth:`~labrig.model.effects.Effect.caveats`, e.g. a
   creep seen over less than two decades of time) count as suspicious points. Every verdict
   ends with the creep the final model describes
   (:func:`~labrig.analysis.diagnose_evidence.modelled_creep_per_decade`): from the seed's
   ``G_t``, which follows most of a logarithmic creep of the actuator by itself, and from any
   added creep effect.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.diagnose_evidence import (
    Evidence,
    collect_evidence,
    modelled_creep_per_decade,
)
from labrig.analysis.diagnose_fit import (
    LAM_GAP,
    ExtendedProblem,
    FitOutcome,
    _build_sequences,
    effect_context,
)
from labrig.analysis.fit import PARAM_NAMES, fit_model
from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record
from labrig.blas import single_thread_blas
from labrig.model import ModelParams
from labrig.model.effects import CREEP_EFFECTS, EFFECT_NAMES, Effect, library

__all__ = [
    "AT_FLOOR",
    "CONFUSABLE_MARGIN",
    "MIN_GAIN",
    "Candidate",
    "Diagnosis",
    "accept",
    "diagnose",
    "split_entries",
]

#: evaluation limit of a candidate's full fit (its folds get half)
MAX_NFEV = 60
#: minimum relative held-out gain for an effect to be added
MIN_GAIN = 0.15
#: a fold counts as better / worse when it changes by more than this (relative)
FOLD_TOL = 0.02
#: residual within this factor of the noise floor: "consistent with noise"
AT_FLOOR = 1.3
#: a runner-up whose held-out gain is within this fraction of the winner's is "confusable"
CONFUSABLE_MARGIN = 0.25

Progress = Callable[[str], Any]


@dataclass
class Candidate:
    """One candidate effect in one round."""

    effect: str
    round: int
    score: float  # share of the residual its direction explains (ranking)
    tried: bool = False
    fit: FitOutcome | None = None
    heldout_per_entry: dict[str, float] | None = None
    heldout_nrmse_pct: float | None = None
    gain: float | None = None  # relative held-out gain over the model of its round
    insample_gain: float | None = None
    wins: int = 0
    losses: int = 0
    accepted: bool = False
    reasons: list[str] = field(default_factory=list)
    suspicious: list[str] = field(default_factory=list)
    evidence: str = ""


@dataclass
class Diagnosis:
    """The result of :func:`diagnose`; :meth:`to_json` is the contract of ``--json``."""

    before: dict[str, Any]
    after: dict[str, Any]
    effects_added: list[dict[str, Any]]
    candidates: list[dict[str, Any]]
    verdict: str
    classification: str  # consistent_with_noise | unexplained | explained | partially_explained
    evidence_before: Evidence
    evidence_after: Evidence
    predictions_before: dict[str, NDArray] = field(repr=False, default_factory=dict)
    predictions_after: dict[str, NDArray] = field(repr=False, default_factory=dict)
    rounds: list[list[Candidate]] = field(default_factory=list, repr=False)
    base_params: dict[str, float] = field(default_factory=dict)
    after_params: dict[str, float] = field(default_factory=dict)
    #: creep the base model describes (%/decade, 1-100 s after a full-scale step)
    base_creep_pct_per_decade: float | None = None
    #: creep the final model describes (its base and any added creep effect), same measure
    after_creep_pct_per_decade: float | None = None
    elapsed_s: float = 0.0
    messages: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "before": self.before,
            "after": self.after,
            "effects_added": self.effects_added,
            "candidates": self.candidates,
            "verdict": self.verdict,
        }


# -- ranking -----------------------------------------------------------------------------------


def _basis(J: NDArray) -> NDArray:
    if J.shape[1] == 0:
        return np.zeros((J.shape[0], 0))
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    u, s, _ = np.linalg.svd(J / scale, full_matrices=False)
    return u[:, s > s[0] * 1e-8] if s.size and s[0] > 0 else np.zeros((J.shape[0], 0))


def _nuisance_directions(prob: ExtendedProblem, eff: Effect) -> NDArray:
    blocks, pos, cols = [], 0, []
    for s in prob.seqs:
        for g in s.segs:
            C = eff.columns(g.t, s.ctx.rate_hz)
            if g.Q is not None:
                C = C - g.Q @ (g.Q.T @ C)
            blocks.append((pos, g.w * C))
            pos += g.meas.size
    n = pos
    for start, C in blocks:
        M = np.zeros((n, C.shape[1]))
        M[start : start + C.shape[0]] = C
        cols.append(M)
    return np.hstack(cols) if cols else np.zeros((n, 0))


def _rank(
    records: Sequence[Record],
    current: list[Effect],
    cur: FitOutcome,
    cur_prob: ExtendedProblem,
    candidates: list[Effect],
    common: dict[str, Any],
) -> list[tuple[Effect, float, dict[str, float]]]:
    """(effect, explained share, best probe) for each candidate, best first."""
    with single_thread_blas(), np.errstate(over="ignore", invalid="ignore"):
        r = cur_prob.residual(cur.z, cur.base)
        B = _basis(cur_prob.jacobian(cur.z, cur.base, r))
        rr = float(r @ r)
        out = []
        for eff in candidates:
            probe_best: dict[str, float] = eff.init
            if eff.where == "nuisance":
                D = _nuisance_directions(cur_prob, eff)
                D = D - B @ (B.T @ D)
                coef, *_ = np.linalg.lstsq(D, -r, rcond=None)
                expl = float(np.sum((D @ coef) ** 2)) / rr if rr > 0 else 0.0
                out.append((eff, expl, probe_best))
                continue
            prob = ExtendedProblem(records, [*current, eff], **common)
            r0 = r  # the effect at its null value (or, without parameters, absent)
            cols, costs, probes = [], [], eff.probes([c for _, c in prob.groups])
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


# -- acceptance --------------------------------------------------------------------------------


def accept(
    eff: Effect,
    fo: FitOutcome,
    held: dict[str, float],
    held_ref: dict[str, float],
    min_gain: float = MIN_GAIN,
    span_s: float = float("inf"),
) -> tuple[bool, float, int, int, list[str], list[str]]:
    """The acceptance rule (module docstring, step 6). ``span_s``: the longest simulated
    sequence (s), for the effect's own caveats (:meth:`Effect.caveats`).

    Returns ``(accepted, gain, wins, losses, reasons against, suspicious points)``.
    """
    names = list(held_ref)
    c = np.array([held[n] for n in names])
    b = np.array([held_ref[n] for n in names])
    gain = 1.0 - float(c.mean()) / float(b.mean())
    wins = int(np.sum(c < b * (1 - FOLD_TOL)))
    losses = int(np.sum(c > b * (1 + FOLD_TOL)))
    reasons, suspicious = [], []
    if gain < min_gain:
        reasons.append(
            f"held-out gain {100 * gain:.0f} % is below the {100 * min_gain:.0f} % minimum"
        )
    if wins < max(2, 2 * losses):
        reasons.append(f"better in {wins} and worse in {losses} of {len(names)} folds")
    p = fo.effects.get(eff.name, {})
    sd = fo.sd.get(eff.name, {})
    for q in eff.params:
        v = p.get(q.name)
        if v is None:
            continue
        if q.check_bounds and q.name in fo.at_bound.get(eff.name, []):
            reasons.append(f"{q.name} = {v:.3g} ends on its bound")
        elif q.sign > 0 and not v > q.null:
            reasons.append(f"{q.name} = {v:.3g} has the unphysical sign")
        if q.expect > 0 and v < q.null:
            suspicious.append(f"{q.name} = {v:.3g} has an unexpected (negative) sign")
        s = sd.get(q.name)
        # a log-scaled parameter (a time constant) never reaches its null: judge its spread
        # against its value
        scale = abs(v) if q.log else abs(v - q.null)
        if q.check_bounds and s is not None and s > 0.5 * scale:
            suspicious.append(f"{q.name} is poorly determined ({v:.3g} +- {s:.2g})")
    suspicious += eff.caveats(p, span_s)
    return not reasons, gain, wins, losses, reasons, suspicious


# -- main --------------------------------------------------------------------------------------


def _mean(d: dict[str, float] | None) -> float | None:
    return None if not d else float(np.mean(list(d.values())))


def _numeric(params: ModelParams) -> dict[str, float]:
    """The fitted (numeric) parameters, without the operator family's shape and memory."""
    return {n: float(getattr(params, n)) for n in PARAM_NAMES}


def split_entries(records: Sequence[Record], parts: int = 4) -> list[Record]:
    """A single long record cut into ``parts`` consecutive entries (at whole drive periods when
    the record is periodic), chained with no rest: leave-one-entry-out then has folds. The
    pieces simulated back to back reproduce the original record exactly."""
    out: list[Record] = []
    for r in records:
        f = drive_frequency_hz(r)
        per = round(r.rate_hz / f) if f else 1
        per = per if 1 <= per <= r.n // parts else 1
        edges = [round(k * (r.n // per) / parts) * per for k in range(parts)] + [r.n]
        for k in range(parts):
            a, b = edges[k], edges[k + 1]
            meta = {**r.meta, "rest_after_s": 0.0, "split_of": r.name}
            out.append(
                Record(
                    f"{r.name}_part{k + 1}",
                    r.rate_hz,
                    r.time_s[a:b],
                    r.voltage_V[a:b],
                    r.strain_ue[a:b],
                    {n: x[a:b] for n, x in r.aux.items()},
                    r.hold,
                    meta,
                )
            )
    return out


def _default_chain(records: Sequence[Record]) -> bool:
    return (
        len(records) > 1
        and all("rest_after_s" in r.meta for r in records)
        and len({r.rate_hz for r in records}) == 1
        and len({r.hold for r in records}) == 1
    )


def _signature_clause(eff: Effect, ev: Evidence) -> str:
    f = ev.features
    ents = list(ev.entries.values())
    n = eff.name
    if n in ("sensor_lowpass", "time_delay"):
        parts = []
        cf = f.get("excess_vs_log_frequency")
        if cf is not None:
            parts.append(
                "the residual grows with frequency"
                if cf > 0.5
                else "the residual does not grow clearly with frequency"
            )
        q = f.get("mean_quadrature_fraction")
        if q is not None:
            hi = max(ents, key=lambda e: e.frequency_hz or 0)
            lag = hi.lag_deg
            parts.append(
                f"its fundamental is {100 * q:.0f} % in quadrature"
                + (f" ({lag:+.0f} deg at {hi.frequency_hz:g} Hz)" if lag is not None else "")
            )
        return "; ".join(parts) or eff.signature
    if n == "amplifier_current_limit":
        dep = [e.amp_departure_V for e in ents if e.amp_departure_V is not None]
        c = f.get("abs_residual_vs_abs_dVdt")
        s = f"|residual| vs |dV/dt| r = {c:.2f}" if c is not None else ""
        if dep:
            worst = max(ents, key=lambda e: e.amp_departure_V or 0)
            s += (
                f"; the measured amplifier voltage departs from the command by up to "
                f"{worst.amp_departure_V:.3g} V ({worst.name})"
            )
        return s
    if n == "thermal_drift":
        ct = f.get("residual_vs_strain_x_temperature")
        rise = [e.temperature_rise_K for e in ents if e.temperature_rise_K is not None]
        if ct is not None:
            return (
                f"the residual follows strain x temperature (r = {ct:.2f}); the stack warmed by "
                f"up to {max(rise):.2g} K within an entry"
            )
        return "gain error building up over the hot entries (no temperature channel)"
    if n == "mains_pickup":
        lines = [ln for e in ents for ln in e.lines]
        if lines:
            top = max(lines, key=lambda x: x["amplitude_ue"])
            return (
                f"the residual spectrum has a line at {top['frequency_hz']:.1f} Hz "
                f"({top['amplitude_ue']:.2g} ue) that is not a drive harmonic"
            )
        return "no clear non-synchronous line in the residual spectrum"
    if n in ("offset_drift", "creep"):
        ts = f.get("mean_trend_share")
        return (
            f"linear trends within entries carry {100 * (ts or 0):.0f} % of the residual variance"
        )
    if n == "quadratic_term":
        c = f.get("residual_vs_V2")
        ev2 = [h["amplitude_pct"] for e in ents for h in e.harmonics if h["k"] == 2]
        return f"residual vs V^2 r = {c:.2f}" + (
            f", 2nd harmonic up to {max(ev2):.2g} % of the fundamental" if ev2 else ""
        )
    return eff.signature


def diagnose(
    records: list[Record],
    params: ModelParams | None = None,
    *,
    chain: bool | None = None,
    offset: bool = False,
    warmup_s: float = 0.0,
    effects: Sequence[str] | None = None,
    max_effects: int = 2,
    top_k: int = 3,
    min_gain: float = MIN_GAIN,
    mains_hz: float | None = None,
    progress: Progress | None = None,
) -> Diagnosis:
    """Diagnose what the dynamic model misses in ``records`` (module docstring).

    - ``params``: a start for the base fit (and its hysteresis shape).
    - ``chain``: simulate the entries as one run with their rests (default: when every record
      carries ``meta["rest_after_s"]``, i.e. comes from a ``labrig run`` file).
    - ``offset``: one free strain offset per entry in every model (sensors with no fixed zero).
    - ``effects``: the library names to consider (default all of :data:`EFFECT_NAMES`).
    """
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    if len(records) < 3:
        raise ValueError("diagnose needs at least 3 entries (leave-one-entry-out)")
    chain = _default_chain(records) if chain is None else chain
    shape = params.shape if params is not None else "exponential"
    memory = params.memory if params is not None else "return_point"
    messages: list[str] = []
    say("fitting the base model")
    fr_kwargs = {
        "shape": shape,
        "memory": memory,
        "initial": params,
        "heldout": False,
        "warmup_s": warmup_s,
        "chain": chain,
        "offset": offset,
    }
    fr = fit_model(records, **fr_kwargs)
    messages += fr.messages
    base0 = _numeric(fr.params)
    contexts = _build_sequences(records, chain)
    span_s = max(ctx.n / ctx.rate_hz for _, ctx in contexts)
    lib_context = effect_context(records, mains_hz)
    lib = library(**lib_context)
    names = [n for n in (effects or EFFECT_NAMES) if n in lib]
    common = {
        "chain": chain,
        "shape": shape,
        "memory": memory,
        "warmup_s": warmup_s,
        "offset": offset,
        "base_free": fr.free,
        "contexts": contexts,
    }
    if "lam_d" in fr.free and abs(base0["lam_d"] - 1.0) < LAM_GAP:
        # the relaxor's modal realisation is discontinuous at lam = 1; the engine skips a gap
        # around it (diagnose_fit.LAM_GAP): start on the better side
        trial = {}
        for side in (1.0 - LAM_GAP, 1.0 + LAM_GAP):
            pr = ExtendedProblem(records, [], **common)
            b = dict(base0, lam_d=side)
            r = pr.residual(pr.z_of(b, {}), b)
            trial[side] = float(r @ r)
        base0["lam_d"] = min(trial, key=trial.get)
        messages.append(
            f"the base fit ended at lam_d = {fr.params.lam_d:.4g}, at the relaxor realisation's "
            f"discontinuity (lam = 1); diagnose restarts it at {base0['lam_d']:g}"
        )

    current: list[Effect] = []
    cur_prob = ExtendedProblem(records, current, **common)
    cur = cur_prob.fit(base0)
    say("cross-validating the base model")
    cur_held = cur_prob.heldout(cur)
    before_fit, before_held, before_prob = cur, cur_held, cur_prob
    ev_before = collect_evidence(records, cur_prob.predictions(cur.base, cur.effects), warmup_s)

    rounds: list[list[Candidate]] = []
    added: list[dict[str, Any]] = []
    added_cands: list[Candidate] = []
    for rnd in range(max_effects):
        remaining = [lib[n] for n in names if n not in {e.name for e in current}]
        if not remaining:
            break
        say(f"round {rnd + 1}: ranking {len(remaining)} candidates")
        ranked = _rank(records, current, cur, cur_prob, remaining, common)
        ev_cur = collect_evidence(records, cur_prob.predictions(cur.base, cur.effects), warmup_s)
        cands = []
        for k, (eff, score, probe) in enumerate(ranked):
            c = Candidate(eff.name, rnd, score)
            cands.append(c)
            if k >= top_k:
                c.evidence = (
                    f"ranked {k + 1} of {len(ranked)}: its direction explains "
                    f"{100 * score:.1f} % of the residual; not refitted"
                )
                continue
            say(f"round {rnd + 1}: fitting base + {eff.name}")
            prob = ExtendedProblem(records, [*current, eff], **common)
            start = cur.base
            if eff.where == "voltage":
                # the base compensated the distorted drive: restart it from the staged fit of
                # the records driven through the effect, keep whichever start is better
                alt = _voltage_start(records, eff, probe, common, fr_kwargs)
                if alt is not None:
                    e0 = {**cur.effects, eff.name: probe}
                    costs = []
                    for b in (cur.base, alt):
                        rb = prob.residual(prob.z_of(b, e0), b)
                        costs.append(float(rb @ rb))
                    start = alt if costs[1] < costs[0] else cur.base
            # stage 1: the effect with the operator's gains (V* does not move), then everything
            # free; from each of the effect's starts (a filter's time constant traded against
            # G_d has local optima), the lowest cost wins
            lin = [n for n in ("alpha0_ue_per_V", "gamma_ue_per_V") if n in common["base_free"]]
            pre = ExtendedProblem(records, [*current, eff], **{**common, "base_free": lin})
            fo = None
            for e0 in eff.refit_starts(probe):
                f1 = pre.fit(start, {**cur.effects, eff.name: e0}, tight=False, max_nfev=30)
                f2 = prob.fit(f1.base, f1.effects, max_nfev=MAX_NFEV)
                fo = f2 if fo is None or f2.cost < fo.cost else fo
            assert fo is not None
            c.tried, c.fit = True, fo
            c.insample_gain = 1.0 - fo.nrmse_pct / cur.nrmse_pct
            clause = _signature_clause(eff, ev_cur)
            desc = eff.describe(fo.effects.get(eff.name, {}), fo.sd.get(eff.name, {}))
            if c.insample_gain < 0.5 * min_gain:
                c.reasons.append(
                    f"in-sample gain only {100 * c.insample_gain:.1f} %, not cross-validated"
                )
                c.evidence = (
                    f"{clause}; adding {eff.name} ({desc}) changes the in-sample NRMSE from "
                    f"{cur.nrmse_pct:.3g} % to {fo.nrmse_pct:.3g} % only: not cross-validated"
                )
                continue
            say(f"round {rnd + 1}: cross-validating base + {eff.name}")
            c.heldout_per_entry = prob.heldout(fo)
            c.heldout_nrmse_pct = _mean(c.heldout_per_entry)
            ok, gain, wins, losses, reasons, susp = accept(
                eff, fo, c.heldout_per_entry, cur_held, min_gain, span_s
            )
            c.accepted, c.gain, c.wins, c.losses = ok, gain, wins, losses
            c.reasons += reasons
            c.suspicious = susp
            verb = "cuts" if gain > 0 else "raises"
            c.evidence = (
                f"{clause}; adding {eff.name} ({desc}) {verb} held-out NRMSE from "
                f"{_mean(cur_held):.3g} % to {c.heldout_nrmse_pct:.3g} % "
                f"(better in {wins}, worse in {losses} of {len(cur_held)} folds)"
                + ("" if ok else "; rejected: " + "; ".join(reasons))
                + ("; suspicious: " + "; ".join(susp) if susp and ok else "")
            )
            c._problem = prob  # type: ignore[attr-defined]
        rounds.append(cands)
        passed = [c for c in cands if c.accepted]
        if not passed:
            break
        best = min(passed, key=lambda c: c.heldout_nrmse_pct)
        eff = lib[best.effect]
        current = [*current, eff]
        cur_prob = best._problem  # type: ignore[attr-defined]
        cur, cur_held = best.fit, best.heldout_per_entry
        added_cands.append(best)
        added.append(
            {
                "effect": best.effect,
                "params": _json_params(eff, best.fit),
                "evidence": best.evidence,
            }
        )

    ev_after = collect_evidence(records, cur_prob.predictions(cur.base, cur.effects), warmup_s)
    before = {
        "nrmse_pct": before_fit.nrmse_pct,
        "heldout_nrmse_pct": _mean(before_held),
        "per_entry": dict(before_fit.per_entry),
    }
    after = {
        "nrmse_pct": cur.nrmse_pct,
        "heldout_nrmse_pct": _mean(cur_held),
        "per_entry": dict(cur.per_entry),
    }
    # every effect tried: its latest round's result
    latest: dict[str, Candidate] = {}
    for cands in rounds:
        for c in cands:
            if c.tried or c.effect not in latest:
                latest[c.effect] = c
    cand_json = [
        {
            "effect": c.effect,
            "heldout_nrmse_pct": c.heldout_nrmse_pct,
            "evidence": c.evidence,
        }
        for c in sorted(latest.values(), key=lambda c: (c.round, -c.score))
    ]
    cls, verdict = _verdict(ev_before, ev_after, before, after, added_cands, rounds, lib)
    step_V = lib_context["v_ref"]
    creep = modelled_creep_per_decade(before_fit.params(shape, memory), step_V)
    slow = [(lib[n], p) for n, p in cur.effects.items() if n in CREEP_EFFECTS]
    creep_after = creep_gt = creep
    if slow:
        after_params = cur.params(shape, memory)
        creep_after = modelled_creep_per_decade(after_params, step_V, creep_effects=slow)
        creep_gt = modelled_creep_per_decade(after_params, step_V)
    if slow and np.isfinite(creep_after) and np.isfinite(creep_gt):
        names = [e.name for e, _ in slow]
        verdict += _creep_added_sentence(creep_after, creep_gt, step_V, records, names)
    elif np.isfinite(creep):
        verdict += _creep_sentence(creep, step_V, records)
    d = Diagnosis(
        before=before,
        after=after,
        effects_added=added,
        candidates=cand_json,
        verdict=verdict,
        classification=cls,
        evidence_before=ev_before,
        evidence_after=ev_after,
        predictions_before=before_prob.predictions(before_fit.base, before_fit.effects),
        predictions_after=cur_prob.predictions(cur.base, cur.effects),
        rounds=rounds,
        base_params=dict(before_fit.base),
        after_params=dict(cur.base),
        base_creep_pct_per_decade=100.0 * creep if np.isfinite(creep) else None,
        after_creep_pct_per_decade=100.0 * creep_after if np.isfinite(creep_after) else None,
        messages=messages,
    )
    for cands in rounds:
        for c in cands:
            c.__dict__.pop("_problem", None)
    d.elapsed_s = time.perf_counter() - t0
    return d


def _voltage_start(
    records: Sequence[Record],
    eff: Effect,
    probe: dict[str, float],
    common: dict[str, Any],
    fr_kwargs: dict[str, Any],
) -> dict[str, float] | None:
    """Base parameters fitted (``fit_model``) to the records driven by the voltage effect at
    ``probe``: a start for base + a voltage effect."""
    new = []
    for grp, ctx in common["contexts"]:
        v = eff.apply(ctx.v, ctx, probe)
        for r in grp:
            sl = ctx.entries[r.name]
            new.append(
                Record(r.name, r.rate_hz, r.time_s, v[sl], r.strain_ue, {}, r.hold, dict(r.meta))
            )
    try:
        fr = fit_model(new, **fr_kwargs)
    except (ValueError, RuntimeError):
        return None
    b = _numeric(fr.params)
    if abs(b["lam_d"] - 1.0) < LAM_GAP:
        b["lam_d"] = 1.0 + LAM_GAP
    return b


def _json_params(eff: Effect, fo: FitOutcome) -> dict[str, Any]:
    p = fo.effects.get(eff.name, {})
    out: dict[str, Any] = {}
    for k, v in eff.physical(p).items():
        out[k] = v if isinstance(v, str) else (float(v) if np.isfinite(v) else None)
    for k, s in fo.sd.get(eff.name, {}).items():
        out[f"{k}_sd"] = s
    if eff.where == "nuisance":
        out["description"] = eff.describe({}, {})
    return out


def tell_apart(a: Effect, b: Effect) -> str:
    """The experiment that separates effects ``a`` and ``b``: the one written for the pair (in
    ``a``'s or ``b``'s list of confusions), else both effects' own."""
    if b.name in a.confusable:
        return a.tell_apart
    if a.name in b.confusable:
        return b.tell_apart
    return f"for {a.name}: {a.tell_apart}; for {b.name}: {b.tell_apart}"


def _creep_where(records: Sequence[Record]) -> str:
    longest = max(float(r.time_s[-1] - r.time_s[0]) for r in records)
    return "" if longest >= 100.0 else f", extrapolated beyond the longest entry ({longest:.3g} s)"


def _creep_sentence(creep: float, step_V: float, records: Sequence[Record]) -> str:
    """The creep the base model already describes (:func:`modelled_creep_per_decade`): a log
    creep of the actuator that ``G_t`` follows within the noise is measured here."""
    return (
        f" Creep: the base model's slow relaxor G_t makes the strain creep by "
        f"{100 * creep:.1f} %/decade from 1 s to 100 s after a {step_V:.3g} V step"
        f"{_creep_where(records)}; any logarithmic creep of the actuator that G_t follows within "
        "the noise is part of this figure and is not added as a separate effect."
    )


def _creep_added_sentence(
    total: float, from_gt: float, step_V: float, records: Sequence[Record], names: list[str]
) -> str:
    """The whole model's creep once creep effects (``names``) are in it, and what ``G_t`` alone
    gives."""
    return (
        f" Creep: the model makes the strain creep by {100 * total:.1f} %/decade from 1 s to "
        f"100 s after a {step_V:.3g} V step{_creep_where(records)}, against "
        f"{100 * from_gt:.1f} %/decade from its slow relaxor G_t without {' and '.join(names)}."
    )


def _confusions_sentence(
    first: Candidate, its_round: list[Candidate], added: list[str], lib: dict[str, Effect]
) -> str:
    """What became of the first added effect's usual confusions, as it happened: cross-validated
    and worse, not refitted (ranked low or no in-sample gain), or added themselves later."""
    by_name = {c.effect: c for c in its_round}
    tested, untried, later = [], [], []
    for name in lib[first.effect].confusable:
        if name not in lib or name not in by_name:
            continue
        if name in added:
            later.append(name)
        elif by_name[name].heldout_nrmse_pct is not None:
            tested.append(name)
        else:
            untried.append(name)
    out = ""
    if tested:
        out += (
            f" Usual confusions ({', '.join(tested)}) were cross-validated and fit clearly worse."
        )
    if untried:
        out += (
            f" {', '.join(untried)} (usually confused with {first.effect}) explained too little of "
            "the residual to be cross-validated."
        )
    if later:
        out += (
            f" {', '.join(later)} (usually confused with {first.effect}) "
            f"{'was' if len(later) == 1 else 'were'} added after it: "
            f"{lib[first.effect].tell_apart}."
        )
    return out


def _verdict(
    ev_before: Evidence,
    ev_after: Evidence,
    before: dict,
    after: dict,
    added: list[Candidate],
    rounds: list[list[Candidate]],
    lib: dict[str, Effect],
) -> tuple[str, str]:
    hb, ha = before["heldout_nrmse_pct"], after["heldout_nrmse_pct"]
    floor = ev_before.floor_pct
    tried = [c for cands in rounds for c in cands if c.tried]
    if not added:
        if ev_before.ratio <= AT_FLOOR:
            s = (
                f"The residual of the base model is consistent with noise: NRMSE "
                f"{before['nrmse_pct']:.3g} % (held-out {hb:.3g} %) against a noise floor of "
                f"{floor:.3g} % ({ev_before.ratio:.2g} times the floor). No effect of the library "
                f"improved held-out prediction by the required {100 * MIN_GAIN:.0f} %"
            )
            best = min(
                (c for c in tried if c.heldout_nrmse_pct is not None),
                key=lambda c: c.heldout_nrmse_pct,
                default=None,
            )
            if best is not None:
                s += f" (best: {best.effect}, held-out {best.heldout_nrmse_pct:.3g} %)"
            return "consistent_with_noise", s + "; nothing was added."
        desc = "; ".join(ev_before.sentences[1:-1]) or "no clear signature"
        tried_s = ", ".join(
            f"{c.effect} ({c.heldout_nrmse_pct:.3g} %)"
            if c.heldout_nrmse_pct is not None
            else f"{c.effect} (in-sample gain {100 * (c.insample_gain or 0):.0f} %)"
            for c in tried
        )
        return "unexplained", (
            f"Unexplained: the base model's residual (NRMSE {before['nrmse_pct']:.3g} %, held-out "
            f"{hb:.3g} %) is {ev_before.ratio:.2g} times the noise floor ({floor:.3g} %), but no "
            f"effect of the library passed the acceptance rule (tried: {tried_s}); nothing is "
            f"attributed. What the residual looks like: {desc}."
        )
    parts = []
    for c in added:
        eff = lib[c.effect]
        text = eff.describe(c.fit.effects.get(c.effect, {}), c.fit.sd.get(c.effect, {}))
        parts.append(f"{c.effect} ({text})")
    susp = [s for c in added for s in c.suspicious]
    at_floor = ev_after.ratio <= AT_FLOOR
    head = (
        f"adding {' then '.join(parts)} cuts held-out NRMSE from {hb:.3g} % to {ha:.3g} % "
        f"(in-sample {before['nrmse_pct']:.3g} % to {after['nrmse_pct']:.3g} %)"
    )
    # confusable runner-ups of the first added effect
    first = added[0]
    runners = [
        c
        for c in rounds[first.round]
        if c is not first
        and c.gain is not None
        and first.gain
        and c.gain >= (1 - CONFUSABLE_MARGIN) * first.gain
    ]
    conf = ""
    if runners:
        r = min(runners, key=lambda c: c.heldout_nrmse_pct)
        conf = (
            f" {r.effect} fits almost as well (held-out {r.heldout_nrmse_pct:.3g} % against "
            f"{first.heldout_nrmse_pct:.3g} %): the data do not fully separate them; "
            f"{tell_apart(lib[first.effect], lib[r.effect])}."
        )
    else:
        conf = _confusions_sentence(first, rounds[first.round], [c.effect for c in added], lib)
    if at_floor and not susp:
        return "explained", (
            f"Explained: {head}; the remaining residual is {ev_after.ratio:.2g} times the noise "
            f"floor ({ev_after.floor_pct:.3g} %), consistent with noise.{conf}"
        )
    why = []
    if not at_floor:
        why.append(
            f"the remaining residual is still {ev_after.ratio:.2g} times the noise floor "
            f"({ev_after.floor_pct:.3g} %)"
        )
    why += susp
    rest = "; ".join(ev_after.sentences[1:-1])
    return "partially_explained", (
        f"Partially explained: {head}, but {'; '.join(why)}.{conf}"
        + (f" What remains: {rest}." if rest and not at_floor else "")
    )
