"""The verdict of ``labrig diagnose`` in words, and the evidence sentences of candidates.

Classes: "consistent with noise" when nothing was added and the residual is within
:data:`AT_FLOOR` times the noise floor; "unexplained" when nothing passed but the residual is
above it; "explained" when the added effects bring the residual to the floor with plausible
parameters; "partially explained" otherwise. Confusable runner-ups (candidates within
:data:`CONFUSABLE_MARGIN` of the winner's held-out gain) are named with the experiment that would
tell them apart.
"""

from __future__ import annotations

from collections.abc import Sequence

from labrig.analysis.diagnose.acceptance import MIN_GAIN, Candidate
from labrig.analysis.diagnose.evidence import Evidence
from labrig.analysis.records import Record
from labrig.model.effects import Effect

__all__ = [
    "AT_FLOOR",
    "CONFUSABLE_MARGIN",
    "confusions_sentence",
    "creep_added_sentence",
    "creep_sentence",
    "signature_clause",
    "tell_apart",
    "verdict",
]

#: residual within this factor of the noise floor: "consistent with noise"
AT_FLOOR = 1.3
#: a runner-up whose held-out gain is within this fraction of the winner's is "confusable"
CONFUSABLE_MARGIN = 0.25


def signature_clause(eff: Effect, ev: Evidence) -> str:
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


def creep_sentence(creep: float, step_V: float, records: Sequence[Record]) -> str:
    """The creep the base model already describes (:func:`modelled_creep_per_decade`): a log
    creep of the actuator that ``G_t`` follows within the noise is measured here."""
    return (
        f" Creep: the base model's slow relaxor G_t makes the strain creep by "
        f"{100 * creep:.1f} %/decade from 1 s to 100 s after a {step_V:.3g} V step"
        f"{_creep_where(records)}; any logarithmic creep of the actuator that G_t follows within "
        "the noise is part of this figure and is not added as a separate effect."
    )


def creep_added_sentence(
    total: float, from_gt: float, step_V: float, records: Sequence[Record], names: list[str]
) -> str:
    """The whole model's creep once creep effects (``names``) are in it, and what ``G_t`` alone
    gives."""
    return (
        f" Creep: the model makes the strain creep by {100 * total:.1f} %/decade from 1 s to "
        f"100 s after a {step_V:.3g} V step{_creep_where(records)}, against "
        f"{100 * from_gt:.1f} %/decade from its slow relaxor G_t without {' and '.join(names)}."
    )


def confusions_sentence(
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


def verdict(
    ev_before: Evidence,
    ev_after: Evidence,
    before: dict,
    after: dict,
    added: list[Candidate],
    rounds: list[list[Candidate]],
    lib: dict[str, Effect],
) -> tuple[str, str]:
    """``(class, sentence)``: the verdict (module docstring) from the evidence before and after,
    the scores ``before``/``after`` (``nrmse_pct``, ``heldout_nrmse_pct``), the added candidates
    and every round's candidates."""
    if not added:
        tried = [c for cands in rounds for c in cands if c.tried]
        return _nothing_added(ev_before, before, tried)
    return _effects_added(ev_before, ev_after, before, after, added, rounds, lib)


def _nothing_added(ev_before: Evidence, before: dict, tried: list[Candidate]) -> tuple[str, str]:
    hb = before["heldout_nrmse_pct"]
    floor = ev_before.floor_pct
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


def _effects_added(
    ev_before: Evidence,
    ev_after: Evidence,
    before: dict,
    after: dict,
    added: list[Candidate],
    rounds: list[list[Candidate]],
    lib: dict[str, Effect],
) -> tuple[str, str]:
    hb, ha = before["heldout_nrmse_pct"], after["heldout_nrmse_pct"]
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
    # confusable runner-ups of the first added effect (not one added too: both are kept)
    first = added[0]
    kept = {c.effect for c in added}
    runners = [
        c
        for c in rounds[first.round]
        if c is not first
        and c.effect not in kept
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
        conf = confusions_sentence(first, rounds[first.round], [c.effect for c in added], lib)
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


#: the headline's words for each verdict class
HEADLINE_WORDS = {
    "consistent_with_noise": "Consistent with noise",
    "unexplained": "Unexplained",
    "explained": "Explained",
    "partially_explained": "Partially explained",
}


def headline(
    cls: str, ev_before: Evidence, ev_after: Evidence, before: dict, after: dict, added: list[str]
) -> str:
    """The verdict in one line, before its paragraph: the class, what was added, the held-out
    NRMSE before and after (%) and how many times the noise floor (%) that held-out figure is,
    with the in-sample ratio beside it (the one the verdict's class is decided on:
    :data:`AT_FLOOR`)."""
    hb, ha = before["heldout_nrmse_pct"], after["heldout_nrmse_pct"]
    words = HEADLINE_WORDS[cls]
    if not added:
        return (
            f"{words}: nothing added; held-out NRMSE {hb:.3g} % is "
            f"{_times(hb, ev_before.floor_pct)}x the noise floor ({ev_before.floor_pct:.3g} %; "
            f"in-sample {ev_before.ratio:.2g}x)."
        )
    return (
        f"{words}: added {' then '.join(added)}; held-out NRMSE {hb:.3g} % -> {ha:.3g} %, "
        f"{_times(ha, ev_after.floor_pct)}x the noise floor ({ev_after.floor_pct:.3g} %; "
        f"in-sample {ev_after.ratio:.2g}x)."
    )


def _times(nrmse_pct: float, floor_pct: float) -> str:
    """``nrmse_pct / floor_pct`` to two significant figures (``-`` without a floor)."""
    return f"{nrmse_pct / floor_pct:.2g}" if floor_pct > 0 else "-"
