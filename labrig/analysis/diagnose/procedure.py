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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.diagnose.acceptance import MIN_GAIN, Candidate
from labrig.analysis.diagnose.eta import RoundClock
from labrig.analysis.diagnose.evidence import Evidence, modelled_creep_per_decade
from labrig.analysis.diagnose.ranking import jacobian_basis, rank
from labrig.analysis.diagnose.sparse_ode import sparse_ode_step
from labrig.analysis.diagnose.state import Model, Settings, Setup
from labrig.analysis.diagnose.trial import MAX_NFEV, json_params, numeric, try_candidate
from labrig.analysis.diagnose.verdict import (
    AT_FLOOR,
    creep_added_sentence,
    creep_sentence,
    headline,
    verdict,
)
from labrig.analysis.engine import LAM_GAP, SharedSimulations
from labrig.analysis.extended import DEFAULT_MAINS_HZ, ExtendedProblem, effect_context
from labrig.analysis.fit import FitResult, fit_model
from labrig.analysis.metrics import drive_frequency_hz, is_periodic
from labrig.analysis.parallel import map_tasks
from labrig.analysis.records import Record
from labrig.analysis.simulate import build_sequences
from labrig.analysis.spectra import detect_mains_hz
from labrig.analysis.split import split_entries, whole_records
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

__all__ = [
    "MAX_NFEV",
    "Diagnosis",
    "base_fit_reusable",
    "diagnose",
    "drives_against_poling",
    "holds_set_aside",
    "slow_mode_identifiable",
    "split_entries",
]

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
    #: the verdict in one line (:func:`~labrig.analysis.diagnose.verdict.headline`)
    headline: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "before": self.before,
            "after": self.after,
            "effects_added": self.effects_added,
            "candidates": self.candidates,
            "headline": self.headline,
            "verdict": self.verdict,
            "messages": list(self.messages),
        }


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
    campaign of fast sines only sees such a mode as a gain change. The parts of a record cut
    for the folds (``meta["split_of"]``, simulated back to back) are judged as the record they
    were cut from: a 2 s capture in four parts is 2 s long."""
    for r in whole_records(records):
        if r.duration_s < SLOW_MODE_RECORD_S:
            continue
        f = drive_frequency_hz(r)
        if f is None or f <= SLOW_MODE_MAX_HZ or not is_periodic(r.voltage_V, r.rate_hz, f):
            return True
    return False


#: a drive goes against the poling when some record reaches below minus this share of the
#: largest |V| of the records (V): there ``negative_field_asymmetry`` is not identically null
AGAINST_POLING_SHARE = 0.2


def drives_against_poling(records: Sequence[Record]) -> bool:
    """Whether some record's voltage goes below ``-AGAINST_POLING_SHARE`` times the largest
    ``|V|`` of ``records``: a bipolar or negatively biased drive, where a poled ceramic's
    ``d33`` falling against its poling (``negative_field_asymmetry``) can be seen. On a
    unipolar drive the effect is identically null."""
    top = max((float(np.max(np.abs(r.voltage_V))) for r in records if r.voltage_V.size), default=0)
    low = min((float(np.min(r.voltage_V)) for r in records if r.voltage_V.size), default=0.0)
    return top > 0 and low < -AGAINST_POLING_SHARE * top


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
    workers: int = 1,
    base_fit: FitResult | None = None,
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
    - ``workers``: processes for the held-out folds and the candidates of a round
      (:func:`~labrig.analysis.parallel.map_tasks`); the result does not depend on it.
    - ``base_fit``: a finished :func:`~labrig.analysis.fit.fit_model` of these very records
      (``labrig fit`` of the same run, with or without its held-out folds), used as step 1's
      fit instead of fitting again when it was made as the diagnosis would make it
      (:func:`base_fit_reusable`; otherwise the base is fitted as usual). The diagnosis is
      then the same, number for number: the held-out folds of ``fit_model`` come after its
      parameters and do not change them.

    The whole procedure runs with one BLAS thread (:func:`~labrig.core.blas.single_thread_blas`,
    as the fits always did): its products are small or memory-bound, and on a shared machine
    OpenBLAS's waiting threads cost far more CPU than they save (a correlation of two
    87 500-sample residuals: 1.2 ms of CPU on one thread, 18 ms on two at load 10).
    """
    t0 = time.perf_counter()
    if len(records) < 3:
        raise ValueError("diagnose needs at least 3 entries (leave-one-entry-out)")
    settings = Settings(
        chain=_default_chain(records) if chain is None else chain,
        offset=offset,
        warmup_s=warmup_s,
        top_k=top_k,
        min_gain=min_gain,
        shape=params.shape if params is not None else "exponential",
        memory=params.memory if params is not None else "return_point",
        initial=params,
        workers=max(1, int(workers)),
    )
    say = progress or (lambda _msg: None)
    reuse = (
        base_fit
        if base_fit is not None and base_fit_reusable(base_fit, records, settings)
        else None
    )
    with single_thread_blas():
        d = _procedure(records, settings, effects, max_effects, mains_hz, always, say, reuse)
    d.elapsed_s = time.perf_counter() - t0
    return d


def holds_set_aside(records: Sequence[Record]) -> list[str]:
    """What cutting a single record into parts did with its long holds
    (:func:`~labrig.analysis.split.split_entries`' ``idle_lead_s`` and ``idle_trail_s``), for
    the diagnosis' messages (shown on diagnosis.html), not only the command's progress."""
    out = []
    if records and (lead := records[0].meta.get("idle_lead_s")):
        out.append(
            f"{records[0].meta.get('split_of', records[0].name)}: its first {lead:.3g} s (a hold "
            "before the drive) left out; the parts start from rest where the voltage first moves"
        )
    if records and (hold := records[-1].meta.get("idle_trail_s")):
        out.append(
            f"{records[-1].meta.get('split_of', records[-1].name)}: its last {hold:.3g} s (a hold "
            "after the drive) kept as the last part's tail; the parts are cut over the drive"
        )
    return out


def _procedure(
    records: list[Record],
    settings: Settings,
    effects: Sequence[str] | None,
    max_effects: int,
    mains_hz: float | None,
    always: Sequence[str],
    say: Progress,
    base_fit: FitResult | None = None,
) -> Diagnosis:
    """The steps of :func:`diagnose` (its arguments)."""
    messages: list[str] = list(holds_set_aside(records))
    setup, before = fit_base(records, settings, effects, mains_hz, always, say, messages, base_fit)
    current, rounds, added = before, [], []
    for rnd in range(max_effects):
        cands, best, nxt = next_round(setup, settings, current, rnd, say)
        if cands:
            rounds.append(cands)
        if best is None or nxt is None:
            break
        current = nxt
        added.append(best)
    cands, best, nxt = empirical_round(setup, settings, current, len(rounds), say, messages)
    if cands:
        rounds.append(cands)
    if best is not None and nxt is not None:
        current = nxt
        added.append(best)
    d = result(setup, settings, before, current, rounds, added, messages)
    return sparse_ode_step(d, setup, settings, before, current, len(rounds), say)


# -- 1. the base model -----------------------------------------------------------------------


def base_fit_reusable(fr: FitResult, records: Sequence[Record], settings: Settings) -> bool:
    """Whether ``fr`` is the base fit :func:`fit_base` would make of ``records``: the global
    method on every record scored, with the same chaining, warm-up, offset and operator family,
    and no start parameters asked for (``settings.initial``, an extra start of the fit).
    ``fr`` must be of these records' data (the caller's promise: the same run file as read
    once, as ``batch diagnose`` does)."""
    p = fr.params
    return (
        settings.initial is None
        and fr.method == "global"
        and list(fr.entries) == [r.name for r in records]
        and bool(fr.chain) == settings.chain
        and float(fr.warmup_s) == float(settings.warmup_s)
        and (fr.offsets_ue is not None) == settings.offset
        and p.shape == settings.shape
        and p.memory == settings.memory
    )


def candidate_names(
    records: Sequence[Record],
    lib: Mapping[str, Effect],
    effects: Sequence[str] | None,
    mains_given: bool,
    mains_seen: bool,
    always: Sequence[str],
    messages: list[str],
) -> tuple[str, ...]:
    """The library names tried in the rounds, with a message for each one left out."""
    names = [n for n in dict.fromkeys(effects or EFFECT_NAMES) if n in lib]
    if "viscoelastic_creep" in names and not slow_mode_identifiable(records):
        why = (
            "no record long and slow enough to identify a slow viscoelastic mode "
            f"(at least {SLOW_MODE_RECORD_S:g} s at {SLOW_MODE_MAX_HZ:g} Hz or below, or a "
            "step)"
        )
        if "viscoelastic_creep" in always:
            messages.append(f"{why}: viscoelastic_creep tried as asked (--also)")
        else:
            names.remove("viscoelastic_creep")
            messages.append(f"{why}: viscoelastic_creep not tried")
    if "negative_field_asymmetry" in names and not drives_against_poling(records):
        # identically null on such drives: left out without a word unless asked for
        if "negative_field_asymmetry" in always:
            messages.append(
                f"no drive below -{AGAINST_POLING_SHARE:g} x the largest |V| (against the "
                "poling): negative_field_asymmetry tried as asked (--also), its effect is null"
            )
        else:
            names.remove("negative_field_asymmetry")
    if not mains_given and "mains_pickup" in names and not mains_seen:
        names.remove("mains_pickup")
        messages.append(
            "no mains line at 50 or 60 Hz in the strain: mains_pickup not tried "
            "(--mains-hz sets the frequency and tries it)"
        )
    return tuple(names)


def fit_base(
    records: Sequence[Record],
    settings: Settings,
    effects: Sequence[str] | None,
    mains_hz: float | None,
    always: Sequence[str],
    say: Progress,
    messages: list[str],
    base_fit: FitResult | None = None,
) -> tuple[Setup, Model]:
    """Fit the base model (or take ``base_fit``, already checked with
    :func:`base_fit_reusable`), configure the library, cross-validate the base."""
    say("fitting the base model")
    fr = base_fit if base_fit is not None else fit_model(list(records), **settings.fit_kwargs())
    messages += fr.messages
    base0 = numeric(fr.params)
    sequences = build_sequences(records, settings.chain)
    seen = detect_mains_hz(records) if mains_hz is None else None
    context = effect_context(records, mains_hz or seen or DEFAULT_MAINS_HZ)
    lib = library(**context)
    names = candidate_names(
        records, lib, effects, mains_hz is not None, seen is not None, always, messages
    )
    setup = Setup(
        records=tuple(records),
        sequences=tuple(sequences),
        base_free=tuple(fr.free),
        library=lib,
        candidates=names,
        context=context,
        span_s=max(s.n / s.rate_hz for s in sequences),
        shared=SharedSimulations(),
    )
    if "lam_d" in fr.free and abs(base0["lam_d"] - 1.0) < LAM_GAP:
        base0 = _off_lam_gap(setup, settings, fr, base0, messages)
    prob = setup.problem(settings, [])
    fo = prob.fit(base0)
    say("cross-validating the base model")
    held = prob.heldout(fo, workers=settings.workers)
    return setup, Model.of([], prob, fo, held, records, settings.warmup_s)


def _off_lam_gap(
    setup: Setup, settings: Settings, fr: FitResult, base0: dict[str, float], messages: list[str]
) -> dict[str, float]:
    """The relaxor's modal realisation is discontinuous at lam = 1; the engine skips a gap
    around it (:data:`~labrig.analysis.engine.LAM_GAP`): start on the better side."""
    trial = {}
    pr = setup.problem(settings, [])
    for side in (1.0 - LAM_GAP, 1.0 + LAM_GAP):
        b = dict(base0, lam_d=side)
        r = pr.residual(pr.z_of(b, {}), b)
        trial[side] = float(r @ r)
    out = dict(base0, lam_d=min(trial, key=lambda s: trial[s]))
    messages.append(
        f"the base fit ended at lam_d = {fr.params.lam_d:.4g}, at the relaxor realisation's "
        f"discontinuity (lam = 1); diagnose restarts it at {out['lam_d']:g}"
    )
    return out


# -- 2-6. one round --------------------------------------------------------------------------


def _extended(current: Model, c: Candidate, eff: Effect, prob: ExtendedProblem) -> Model:
    """The current model with the accepted candidate ``c`` added."""
    assert c.fit is not None and c.heldout_per_entry is not None
    return Model.of(
        [*current.effects, eff],
        prob,
        c.fit,
        c.heldout_per_entry,
        current.problem.records,
        current.problem.warmup_s,
    )


def next_round(
    setup: Setup, settings: Settings, current: Model, rnd: int, say: Progress
) -> tuple[list[Candidate], Candidate | None, Model | None]:
    """Rank the remaining candidates, refit and cross-validate the best :attr:`Settings.top_k`,
    and add the best that passes: ``(candidates, the added one, the extended model)``."""
    have = {e.name for e in current.effects}
    remaining = [setup.library[n] for n in setup.candidates if n not in have]
    if not remaining:
        return [], None, None
    say(f"round {rnd + 1}: ranking {len(remaining)} candidates")
    ranked = rank(current.effects, current.fit, current.problem, remaining, setup, settings)
    chosen = ranked[: settings.top_k]
    if settings.workers > 1 and len(chosen) > 1:
        say(f"round {rnd + 1}: fitting and cross-validating {len(chosen)} candidates on "
            f"{min(settings.workers, len(chosen))} processes")  # fmt: skip

    clock = RoundClock(len(chosen))

    def trial(k: int) -> Candidate:
        eff, score, probe = chosen[k]
        quiet = settings.workers > 1 and len(chosen) > 1
        first = [True]

        def say_k(msg: str) -> None:  # the candidate's first line says how far the round is
            if first[0]:
                msg, first[0] = f"{msg} ({clock.before(k)})", False
            say(msg)

        c, _ = try_candidate(
            setup,
            settings,
            current,
            eff,
            probe,
            rnd,
            score,
            (lambda _m: None) if quiet else say_k,
            1 if quiet else settings.workers,
        )
        return c

    workers = settings.workers if len(chosen) > 1 else 1
    cands = map_tasks(trial, len(chosen), workers)
    for k, (eff, score, _probe) in enumerate(ranked[settings.top_k :], start=settings.top_k):
        c = Candidate(eff.name, rnd, score)
        c.evidence = (
            f"ranked {k + 1} of {len(ranked)}: its direction explains "
            f"{100 * score:.1f} % of the residual; not refitted"
        )
        cands.append(c)
    passed = [c for c in cands if c.accepted]
    if not passed:
        return cands, None, None
    best = min(passed, key=lambda c: c.heldout_nrmse_pct or np.inf)
    eff = setup.library[best.effect]
    prob = setup.problem(settings, [*current.effects, eff])
    return cands, best, _extended(current, best, eff, prob)


# -- when no named effect passes: terms found in the data ------------------------------------


def empirical_round(
    setup: Setup,
    settings: Settings,
    current: Model,
    rnd: int,
    say: Progress,
    messages: list[str],
) -> tuple[list[Candidate], Candidate | None, Model | None]:
    """Sparse regression of the residual over physically readable terms
    (:mod:`labrig.analysis.terms`) when the model is not yet within the noise; the selected
    terms, as one empirical effect, are refitted, cross-validated and judged by the same
    acceptance rule as a named effect. Empirical, never a physical attribution."""
    if current.evidence.ratio <= AT_FLOOR:
        return [], None, None
    say(f"round {rnd + 1}: sparse regression of the residual")
    scales = TermScales.from_records(setup.records)
    terms = list(term_library(scales).values())
    prob, fo = current.problem, current.fit
    with single_thread_blas(), np.errstate(over="ignore", invalid="ignore"):
        data = regression_data(prob, fo.base, fo.effects, terms)
        B = jacobian_basis(prob.jacobian(fo.z, fo.base))
    sel = select_terms(data.residual, data.columns, terms, data.weights, B)
    if not sel.terms:
        messages.append(
            "sparse regression of the residual selected no term "
            f"(the best explains {100 * sel.share:.1f} % of it)"
        )
        return [], None, None
    eff = empirical_effect(sel.keys, scales)
    found = ", ".join(
        f"{t.name} ({t.coefficient_ue:+.3g} {scales.strain_unit} at full scale)" for t in sel.terms
    )
    c, eprob = try_candidate(
        setup, settings, current, eff, sel.start(), rnd, sel.share, say, settings.workers
    )
    c.evidence = (
        f"sparse regression of the residual selects {found} "
        f"({100 * sel.share:.0f} % of the residual); " + c.evidence
    )
    if not c.accepted:
        return [c], None, None
    return [c], c, _extended(current, c, eff, eprob)


# -- 7. the result -----------------------------------------------------------------------------


def _candidates_json(rounds: list[list[Candidate]]) -> list[dict[str, Any]]:
    """Every effect tried: its latest round's result."""
    latest: dict[str, Candidate] = {}
    for cands in rounds:
        for c in cands:
            if c.tried or c.effect not in latest:
                latest[c.effect] = c
    return [
        {
            "effect": c.effect,
            "round": c.round + 1,
            "heldout_nrmse_pct": c.heldout_nrmse_pct,
            "evidence": c.evidence,
        }
        for c in sorted(latest.values(), key=lambda c: (c.round, -c.score))
    ]


def _creep(
    text: str,
    setup: Setup,
    settings: Settings,
    before: Model,
    after: Model,
    library: Mapping[str, Effect],
) -> tuple[str, float, float]:
    """The verdict with its creep sentence; the base's and the final model's creep."""
    step_V = setup.context["v_ref"]
    shape, memory = settings.shape, settings.memory
    creep = modelled_creep_per_decade(before.fit.params(shape, memory), step_V)
    slow = [(library[n], p) for n, p in after.fit.effects.items() if n in CREEP_EFFECTS]
    creep_after = creep_gt = creep
    if slow:
        after_params = after.fit.params(shape, memory)
        creep_after = modelled_creep_per_decade(after_params, step_V, creep_effects=slow)
        creep_gt = modelled_creep_per_decade(after_params, step_V)
    if slow and np.isfinite(creep_after) and np.isfinite(creep_gt):
        names = [e.name for e, _ in slow]
        text += creep_added_sentence(creep_after, creep_gt, step_V, setup.records, names)
    elif np.isfinite(creep):
        text += creep_sentence(creep, step_V, setup.records)
    return text, creep, creep_after


def result(
    setup: Setup,
    settings: Settings,
    before: Model,
    after: Model,
    rounds: list[list[Candidate]],
    added: list[Candidate],
    messages: list[str],
) -> Diagnosis:
    """The :class:`Diagnosis` of the procedure's models and rounds."""
    lib = {**setup.library, **{e.name: e for e in after.effects}}
    sb, sa = before.scores(), after.scores()
    cls, text = verdict(before.evidence, after.evidence, sb, sa, added, rounds, lib)
    text, creep, creep_after = _creep(text, setup, settings, before, after, lib)
    effects_added = [
        {
            "effect": c.effect,
            "params": json_params(lib[c.effect], c.fit),
            "evidence": c.evidence,
        }
        for c in added
        if c.fit is not None
    ]
    bf, af = before.fit, after.fit
    return Diagnosis(
        before=sb,
        after=sa,
        effects_added=effects_added,
        candidates=_candidates_json(rounds),
        verdict=text,
        classification=cls,
        headline=headline(cls, before.evidence, after.evidence, sb, sa, [c.effect for c in added]),
        evidence_before=before.evidence,
        evidence_after=after.evidence,
        predictions_before=before.problem.predictions(bf.base, bf.effects),
        predictions_after=after.problem.predictions(af.base, af.effects),
        rounds=rounds,
        base_params=dict(bf.base),
        after_params=dict(af.base),
        base_creep_pct_per_decade=100.0 * creep if np.isfinite(creep) else None,
        after_creep_pct_per_decade=100.0 * creep_after if np.isfinite(creep_after) else None,
        messages=messages,
    )
