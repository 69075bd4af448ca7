"""``labrig diagnose``: from the residual to the missing physical effect, judged on held-out data.

The procedure (docs/diagnose.md has the method and its measurements):

1. **Base fit to convergence**: :func:`labrig.analysis.fit.fit_model` (staged starts, global
   least squares, tight tolerances), then polished by the engine that fits the extended models
   (:class:`~labrig.analysis.extended.ExtendedProblem`), so "before" and "after" are computed
   alike.
2. **Residual evidence** (:mod:`.evidence`): noise floor, harmonic tables, scaling with
   frequency and amplitude, correlations, spectral lines. Evidence is for the report and the
   ranking, never the decision.
3. **Ranking** (:mod:`.ranking`): a score test of each candidate's direction, projected off the
   current model's Jacobian.
4. **Refit** base + candidate with every parameter free within physical bounds, for the
   ``top_k`` best ranked (default 4), from each of the effect's starts. A candidate whose
   in-sample gain is below half the minimum gain is not cross-validated (a held-out gain is not
   larger than the in-sample one).
5. **Held-out NRMSE**, leave-one-entry-out: each entry is predicted by a fit that never saw it
   (in a chained run it stays as history); per-entry nuisance parameters are fitted on the first
   half of the held-out entry and every model is scored on the second halves.
6. **Acceptance rule** (:mod:`.acceptance`); among the candidates that pass, the lowest held-out
   NRMSE is added and the procedure repeats from the extended model (at most ``max_effects``).
7. **Verdict** (:mod:`.verdict`), ending with the creep the final model describes
   (:func:`~.evidence.modelled_creep_per_decade`): from the paper's ``G_t``, which follows most of
   a logarithmic creep of the actuator by itself, and from any added creep effect.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.diagnose.acceptance import MIN_GAIN, Candidate, accept
from labrig.analysis.diagnose.evidence import (
    Evidence,
    collect_evidence,
    modelled_creep_per_decade,
)
from labrig.analysis.diagnose.ranking import jacobian_basis, rank
from labrig.analysis.diagnose.verdict import (
    AT_FLOOR,
    creep_added_sentence,
    creep_sentence,
    signature_clause,
    verdict,
)
from labrig.analysis.extended import LAM_GAP, ExtendedProblem, FitOutcome, effect_context
from labrig.analysis.fit import PARAM_NAMES, FitResult, fit_model
from labrig.analysis.metrics import drive_frequency_hz, is_periodic
from labrig.analysis.records import Record
from labrig.analysis.simulate import build_sequences
from labrig.analysis.spectra import detect_mains_hz
from labrig.analysis.split import split_entries
from labrig.analysis.terms import (
    TermScales,
    empirical_effect,
    regression_data,
    select_terms,
    term_library,
)
from labrig.core.blas import single_thread_blas
from labrig.model import ModelParams
from labrig.model.effects import CREEP_EFFECTS, EFFECT_NAMES, Effect, library

__all__ = ["MAX_NFEV", "Diagnosis", "diagnose", "slow_mode_identifiable", "split_entries"]

#: evaluation limit of a candidate's full fit (its folds get half)
MAX_NFEV = 60

Progress = Callable[[str], Any]


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


def _mean(d: dict[str, float] | None) -> float | None:
    return None if not d else float(np.mean(list(d.values())))


def _numeric(params: ModelParams) -> dict[str, float]:
    """The fitted (numeric) parameters, without the operator family's shape and memory."""
    return {n: float(getattr(params, n)) for n in PARAM_NAMES}


def _default_chain(records: Sequence[Record]) -> bool:
    return (
        len(records) > 1
        and all("rest_after_s" in r.meta for r in records)
        and len({r.rate_hz for r in records}) == 1
        and len({r.hold for r in records}) == 1
    )


#: a slow mode (0.1-1 s) is identifiable from a record at least this long ...
SLOW_MODE_RECORD_S = 1.0
#: ... driven at or below this frequency, or not periodic (steps, holds, envelopes)
SLOW_MODE_MAX_HZ = 2.0


def slow_mode_identifiable(records: Sequence[Record]) -> bool:
    """Whether a slow viscoelastic mode (time constant 0.1-1 s) can be told apart in
    ``records``: some record is at least :data:`SLOW_MODE_RECORD_S` long and driven at or
    below :data:`SLOW_MODE_MAX_HZ`, or is not periodic (a step, a hold, an envelope). A
    campaign of fast sines only sees such a mode as a gain change."""
    for r in records:
        if r.duration_s < SLOW_MODE_RECORD_S:
            continue
        f = drive_frequency_hz(r)
        if f is None or f <= SLOW_MODE_MAX_HZ or not is_periodic(r.voltage_V, r.rate_hz, f):
            return True
    return False


def diagnose(
    records: list[Record],
    params: ModelParams | None = None,
    *,
    chain: bool | None = None,
    offset: bool = False,
    warmup_s: float = 0.0,
    effects: Sequence[str] | None = None,
    max_effects: int = 2,
    top_k: int = 4,
    min_gain: float = MIN_GAIN,
    mains_hz: float | None = None,
    always: Sequence[str] = (),
    progress: Progress | None = None,
) -> Diagnosis:
    """Diagnose what the dynamic model misses in ``records`` (module docstring).

    - ``params``: a start for the base fit (and its hysteresis shape).
    - ``chain``: simulate the entries as one run with their rests (default: when every record
      carries ``meta["rest_after_s"]``, i.e. comes from a ``labrig run`` file).
    - ``offset``: one free strain offset per entry in every model (sensors with no fixed zero).
    - ``effects``: the library names to consider (default all of :data:`EFFECT_NAMES`).
    - ``mains_hz``: the mains frequency (default: the line the strain shows at 50 or 60 Hz;
      without one, ``mains_pickup`` is not tried).
    - ``always``: names tried even where the records cannot identify them (``--also``):
      ``viscoelastic_creep`` is otherwise left out without a long, slow entry.
    """
    t0 = time.perf_counter()
    if len(records) < 3:
        raise ValueError("diagnose needs at least 3 entries (leave-one-entry-out)")
    proc = _Procedure(
        records,
        params,
        _default_chain(records) if chain is None else chain,
        offset,
        warmup_s,
        top_k,
        min_gain,
        progress or (lambda _msg: None),
    )
    proc.fit_base(effects, mains_hz, always)
    for rnd in range(max_effects):
        if not proc.next_round(rnd):
            break
    proc.empirical_round(len(proc.rounds))
    d = proc.result()
    d.elapsed_s = time.perf_counter() - t0
    return d


class _Procedure:
    """The state of one diagnosis: the current model, the rounds so far."""

    def __init__(
        self,
        records: list[Record],
        params: ModelParams | None,
        chain: bool,
        offset: bool,
        warmup_s: float,
        top_k: int,
        min_gain: float,
        say: Progress,
    ):
        self.records = records
        self.params = params
        self.chain = chain
        self.warmup_s = warmup_s
        self.top_k = top_k
        self.min_gain = min_gain
        self.say = say
        self.shape = params.shape if params is not None else "exponential"
        self.memory = params.memory if params is not None else "return_point"
        self.messages: list[str] = []
        self.fr_kwargs = {
            "shape": self.shape,
            "memory": self.memory,
            "initial": params,
            "heldout": False,
            "warmup_s": warmup_s,
            "chain": chain,
            "offset": offset,
        }
        self.offset = offset
        self.rounds: list[list[Candidate]] = []
        self.added: list[dict[str, Any]] = []
        self.added_cands: list[Candidate] = []

    # -- 1. the base model --------------------------------------------------------------------
    def fit_base(
        self, effects: Sequence[str] | None, mains_hz: float | None, always: Sequence[str] = ()
    ) -> None:
        """Fit the base model, configure the library, cross-validate the base."""
        self.say("fitting the base model")
        fr = fit_model(self.records, **self.fr_kwargs)
        self.messages += fr.messages
        base0 = _numeric(fr.params)
        sequences = build_sequences(self.records, self.chain)
        self.span_s = max(s.n / s.rate_hz for s in sequences)
        self.lib_context = effect_context(self.records, mains_hz)
        self.lib = library(**self.lib_context)
        self.names = [n for n in dict.fromkeys(effects or EFFECT_NAMES) if n in self.lib]
        if "viscoelastic_creep" in self.names and not slow_mode_identifiable(self.records):
            why = (
                "no entry long and slow enough to identify a slow viscoelastic mode "
                f"(at least {SLOW_MODE_RECORD_S:g} s at {SLOW_MODE_MAX_HZ:g} Hz or below, or a "
                "step)"
            )
            if "viscoelastic_creep" in always:
                self.messages.append(f"{why}: viscoelastic_creep tried as asked (--also)")
            else:
                self.names.remove("viscoelastic_creep")
                self.messages.append(f"{why}: viscoelastic_creep not tried")
        if mains_hz is None and "mains_pickup" in self.names and not detect_mains_hz(self.records):
            self.names.remove("mains_pickup")
            self.messages.append(
                "no mains line at 50 or 60 Hz in the strain: mains_pickup not tried "
                "(--mains-hz sets the frequency and tries it)"
            )
        self.common = {
            "chain": self.chain,
            "shape": self.shape,
            "memory": self.memory,
            "warmup_s": self.warmup_s,
            "offset": self.offset,
            "base_free": fr.free,
            "sequences": sequences,
        }
        if "lam_d" in fr.free and abs(base0["lam_d"] - 1.0) < LAM_GAP:
            self._restart_off_lam_gap(fr, base0)
        self.current: list[Effect] = []
        self.cur_prob = ExtendedProblem(self.records, self.current, **self.common)
        self.cur = self.cur_prob.fit(base0)
        self.say("cross-validating the base model")
        self.cur_held = self.cur_prob.heldout(self.cur)
        self.before_fit, self.before_held = self.cur, self.cur_held
        self.before_prob = self.cur_prob
        self.ev_before = self._evidence()

    def _restart_off_lam_gap(self, fr: FitResult, base0: dict[str, float]) -> None:
        """The relaxor's modal realisation is discontinuous at lam = 1; the engine skips a gap
        around it (:data:`~labrig.analysis.extended.LAM_GAP`): start on the better side."""
        trial = {}
        for side in (1.0 - LAM_GAP, 1.0 + LAM_GAP):
            pr = ExtendedProblem(self.records, [], **self.common)
            b = dict(base0, lam_d=side)
            r = pr.residual(pr.z_of(b, {}), b)
            trial[side] = float(r @ r)
        base0["lam_d"] = min(trial, key=trial.get)
        self.messages.append(
            f"the base fit ended at lam_d = {fr.params.lam_d:.4g}, at the relaxor realisation's "
            f"discontinuity (lam = 1); diagnose restarts it at {base0['lam_d']:g}"
        )

    def _evidence(self) -> Evidence:
        preds = self.cur_prob.predictions(self.cur.base, self.cur.effects)
        return collect_evidence(self.records, preds, self.warmup_s)

    # -- 2-6. one round -----------------------------------------------------------------------
    def next_round(self, rnd: int) -> bool:
        """Rank, refit and cross-validate the remaining candidates; add the best that passes.
        Returns whether an effect was added."""
        remaining = [self.lib[n] for n in self.names if n not in {e.name for e in self.current}]
        if not remaining:
            return False
        self.say(f"round {rnd + 1}: ranking {len(remaining)} candidates")
        ranked = rank(self.records, self.current, self.cur, self.cur_prob, remaining, self.common)
        ev_cur = self._evidence()
        cands: list[Candidate] = []
        problems: dict[str, ExtendedProblem] = {}
        for k, (eff, score, probe) in enumerate(ranked):
            c = Candidate(eff.name, rnd, score)
            cands.append(c)
            if k >= self.top_k:
                c.evidence = (
                    f"ranked {k + 1} of {len(ranked)}: its direction explains "
                    f"{100 * score:.1f} % of the residual; not refitted"
                )
                continue
            problems[eff.name] = self._try(c, eff, probe, ev_cur, rnd)
        self.rounds.append(cands)
        passed = [c for c in cands if c.accepted]
        if not passed:
            return False
        best = min(passed, key=lambda c: c.heldout_nrmse_pct)
        self._add(best, self.lib[best.effect], problems[best.effect])
        return True

    def _add(self, best: Candidate, eff: Effect, prob: ExtendedProblem) -> None:
        """Extend the current model with the accepted candidate ``best``."""
        self.lib.setdefault(eff.name, eff)
        self.current = [*self.current, eff]
        self.cur_prob = prob
        self.cur, self.cur_held = best.fit, best.heldout_per_entry
        self.added_cands.append(best)
        self.added.append(
            {
                "effect": best.effect,
                "params": _json_params(eff, best.fit),
                "evidence": best.evidence,
            }
        )

    # -- when no named effect passes: terms found in the data --------------------------------
    def empirical_round(self, rnd: int) -> None:
        """Sparse regression of the residual over physically readable terms
        (:mod:`labrig.analysis.terms`) when the model is not yet within the noise; the selected
        terms, as one empirical effect, are refitted, cross-validated and judged by the same
        acceptance rule as a named effect. Empirical, never a physical attribution."""
        ev = self._evidence()
        if ev.ratio <= AT_FLOOR:
            return
        self.say(f"round {rnd + 1}: sparse regression of the residual")
        scales = TermScales.from_records(self.records)
        terms = list(term_library(scales).values())
        with single_thread_blas(), np.errstate(over="ignore", invalid="ignore"):
            data = regression_data(self.cur_prob, self.cur.base, self.cur.effects, terms)
            B = jacobian_basis(self.cur_prob.jacobian(self.cur.z, self.cur.base))
        sel = select_terms(data.residual, data.columns, terms, data.weights, B)
        if not sel.terms:
            self.messages.append(
                "sparse regression of the residual selected no term "
                f"(the best explains {100 * sel.share:.1f} % of it)"
            )
            return
        eff = empirical_effect(sel.keys, scales)
        c = Candidate(eff.name, rnd, sel.share)
        found = ", ".join(f"{t.name} ({t.coefficient_ue:+.3g} ue at full scale)" for t in sel.terms)
        prob = self._try(c, eff, sel.start(), ev, rnd)
        c.evidence = (
            f"sparse regression of the residual selects {found} "
            f"({100 * sel.share:.0f} % of the residual); " + c.evidence
        )
        self.rounds.append([c])
        if c.accepted:
            self._add(c, eff, prob)

    def _start(self, prob: ExtendedProblem, eff: Effect, probe: dict[str, float]):
        """The base start of a refit: the current base or, for a voltage effect, the staged fit
        of the records driven through the effect when that is better (the base compensated the
        distorted drive)."""
        start = self.cur.base
        if eff.where != "voltage":
            return start
        alt = _voltage_start(self.records, eff, probe, self.common, self.fr_kwargs)
        if alt is None:
            return start
        e0 = {**self.cur.effects, eff.name: probe}
        costs = []
        for b in (self.cur.base, alt):
            rb = prob.residual(prob.z_of(b, e0), b)
            costs.append(float(rb @ rb))
        return alt if costs[1] < costs[0] else start

    def _refit(self, prob: ExtendedProblem, eff: Effect, probe: dict[str, float]) -> FitOutcome:
        """Base + candidate: first the effect with the operator's gains only (V* does not move),
        then everything free; from each of the effect's starts (a filter's time constant traded
        against G_d has local optima), the lowest cost wins."""
        start = self._start(prob, eff, probe)
        lin = [n for n in ("alpha0_ue_per_V", "gamma_ue_per_V") if n in self.common["base_free"]]
        pre = ExtendedProblem(
            self.records, [*self.current, eff], **{**self.common, "base_free": lin}
        )
        fo = None
        for e0 in eff.refit_starts(probe):
            f1 = pre.fit(start, {**self.cur.effects, eff.name: e0}, tight=False, max_nfev=30)
            f2 = prob.fit(f1.base, f1.effects, max_nfev=MAX_NFEV)
            fo = f2 if fo is None or f2.cost < fo.cost else fo
        assert fo is not None
        return fo

    def _try(
        self, c: Candidate, eff: Effect, probe: dict[str, float], ev_cur: Evidence, rnd: int
    ) -> ExtendedProblem:
        """Refit one candidate, cross-validate it if it gains enough in-sample, judge it."""
        self.say(f"round {rnd + 1}: fitting base + {eff.name}")
        prob = ExtendedProblem(self.records, [*self.current, eff], **self.common)
        fo = self._refit(prob, eff, probe)
        c.tried, c.fit = True, fo
        c.insample_gain = 1.0 - fo.nrmse_pct / self.cur.nrmse_pct
        clause = signature_clause(eff, ev_cur)
        desc = eff.describe(fo.effects.get(eff.name, {}), fo.sd.get(eff.name, {}))
        if c.insample_gain < 0.5 * self.min_gain:
            c.reasons.append(
                f"in-sample gain only {100 * c.insample_gain:.1f} %, not cross-validated"
            )
            c.evidence = (
                f"{clause}; adding {eff.name} ({desc}) changes the in-sample NRMSE from "
                f"{self.cur.nrmse_pct:.3g} % to {fo.nrmse_pct:.3g} % only: not cross-validated"
            )
            return prob
        self.say(f"round {rnd + 1}: cross-validating base + {eff.name}")
        c.heldout_per_entry = prob.heldout(fo)
        c.heldout_nrmse_pct = _mean(c.heldout_per_entry)
        a = accept(eff, fo, c.heldout_per_entry, self.cur_held, self.min_gain, self.span_s)
        c.judged(a)
        verb = "cuts" if a.gain > 0 else "raises"
        c.evidence = (
            f"{clause}; adding {eff.name} ({desc}) {verb} held-out NRMSE from "
            f"{_mean(self.cur_held):.3g} % to {c.heldout_nrmse_pct:.3g} % "
            f"(better in {a.wins}, worse in {a.losses} of {len(self.cur_held)} folds)"
            + ("" if a.accepted else "; rejected: " + "; ".join(a.reasons))
            + ("; suspicious: " + "; ".join(a.suspicious) if a.suspicious and a.accepted else "")
        )
        return prob

    # -- 7. the result ------------------------------------------------------------------------
    def _candidates_json(self) -> list[dict[str, Any]]:
        """Every effect tried: its latest round's result."""
        latest: dict[str, Candidate] = {}
        for cands in self.rounds:
            for c in cands:
                if c.tried or c.effect not in latest:
                    latest[c.effect] = c
        return [
            {
                "effect": c.effect,
                "heldout_nrmse_pct": c.heldout_nrmse_pct,
                "evidence": c.evidence,
            }
            for c in sorted(latest.values(), key=lambda c: (c.round, -c.score))
        ]

    def _creep(self, text: str) -> tuple[str, float, float]:
        """The verdict with its creep sentence; the base's and the final model's creep."""
        step_V = self.lib_context["v_ref"]
        creep = modelled_creep_per_decade(self.before_fit.params(self.shape, self.memory), step_V)
        slow = [(self.lib[n], p) for n, p in self.cur.effects.items() if n in CREEP_EFFECTS]
        creep_after = creep_gt = creep
        if slow:
            after_params = self.cur.params(self.shape, self.memory)
            creep_after = modelled_creep_per_decade(after_params, step_V, creep_effects=slow)
            creep_gt = modelled_creep_per_decade(after_params, step_V)
        if slow and np.isfinite(creep_after) and np.isfinite(creep_gt):
            names = [e.name for e, _ in slow]
            text += creep_added_sentence(creep_after, creep_gt, step_V, self.records, names)
        elif np.isfinite(creep):
            text += creep_sentence(creep, step_V, self.records)
        return text, creep, creep_after

    def result(self) -> Diagnosis:
        ev_after = self._evidence()
        before = {
            "nrmse_pct": self.before_fit.nrmse_pct,
            "heldout_nrmse_pct": _mean(self.before_held),
            "per_entry": dict(self.before_fit.per_entry),
        }
        after = {
            "nrmse_pct": self.cur.nrmse_pct,
            "heldout_nrmse_pct": _mean(self.cur_held),
            "per_entry": dict(self.cur.per_entry),
        }
        cand_json = self._candidates_json()
        cls, text = verdict(
            self.ev_before, ev_after, before, after, self.added_cands, self.rounds, self.lib
        )
        text, creep, creep_after = self._creep(text)
        bf = self.before_fit
        return Diagnosis(
            before=before,
            after=after,
            effects_added=self.added,
            candidates=cand_json,
            verdict=text,
            classification=cls,
            evidence_before=self.ev_before,
            evidence_after=ev_after,
            predictions_before=self.before_prob.predictions(bf.base, bf.effects),
            predictions_after=self.cur_prob.predictions(self.cur.base, self.cur.effects),
            rounds=self.rounds,
            base_params=dict(bf.base),
            after_params=dict(self.cur.base),
            base_creep_pct_per_decade=100.0 * creep if np.isfinite(creep) else None,
            after_creep_pct_per_decade=100.0 * creep_after if np.isfinite(creep_after) else None,
            messages=self.messages,
        )


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
    for seq in common["sequences"]:
        v = eff.apply(seq.voltage_V, seq.context, probe)
        for r in seq.records:
            sl = seq.entries[r.name]
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
