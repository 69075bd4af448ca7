"""The acceptance rule of ``labrig diagnose``: when a candidate effect is added.

A candidate is added when, on held-out data (leave-one-entry-out, scored on the second half of
each held-out entry):

- the mean held-out NRMSE drops by at least :data:`MIN_GAIN` (15 %) relative to the current
  model, and by more than rounding (:data:`NUMERICAL_PCT`, for noise-free data); or, when the
  current model is near the noise floor (its held-out NRMSE at least :data:`NEAR_FLOOR_RATIO`
  times the floor, so there is an excess to explain, but a 15 % gain of the total may not even
  be available), the candidate removes at least :data:`EXCESS_GAIN` (half) of the excess over
  the floor and at least :data:`MIN_NEAR_GAIN` (5 %) of the total: a named effect that
  explains most of what is left is named instead of being left to empirical terms;
- it is better (by more than :data:`FOLD_TOL`, 2 %) in at least two folds and in at least twice
  as many folds as it is worse;
- none of its physical parameters ends on a bound or on the wrong side of its null value, and
  the effect finds nothing meaningless in its fit (:meth:`Effect.refusals`, e.g. a sensor
  low-pass whose damping ends at its resonant end).

Points that do not reject the candidate but make it doubtful (an unexpected sign, a poorly
determined parameter, the effect's own caveats) are kept as "suspicious" for the verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from labrig.analysis.extended import FitOutcome
from labrig.model.effects import Effect

__all__ = [
    "EXCESS_GAIN",
    "FOLD_TOL",
    "MIN_GAIN",
    "MIN_NEAR_GAIN",
    "NEAR_FLOOR_RATIO",
    "NUMERICAL_PCT",
    "ROUNDING",
    "WORSE",
    "Acceptance",
    "Candidate",
    "accept",
]

#: the reasons of a candidate that does not lower the held-out NRMSE: it raises it, or changes
#: it by less than rounding
WORSE = "held-out NRMSE rises"
ROUNDING = "held-out gain below numerical precision"
#: minimum relative held-out gain for an effect to be added
MIN_GAIN = 0.15
#: a fold counts as better / worse when it changes by more than this (relative)
FOLD_TOL = 0.02
#: near the floor: the current model's held-out NRMSE over the noise floor must be at least this
#: (an excess worth explaining; a model at the floor has none) ...
NEAR_FLOOR_RATIO = 1.1
#: ... the candidate must remove at least this fraction of that excess ...
EXCESS_GAIN = 0.5
#: ... and at least this fraction of the total held-out NRMSE
MIN_NEAR_GAIN = 0.05
#: a held-out gain smaller than this (NRMSE %) is rounding, not a gain (noise-free data)
NUMERICAL_PCT = 1e-6


@dataclass
class Acceptance:
    """What the acceptance rule says of one candidate."""

    accepted: bool
    gain: float  # relative held-out gain over the current model
    wins: int  # folds better by more than FOLD_TOL
    losses: int  # folds worse by more than FOLD_TOL
    reasons: list[str]  # why it is rejected (empty when accepted)
    suspicious: list[str]  # points that make it doubtful


def accept(
    eff: Effect,
    fo: FitOutcome,
    held: dict[str, float],
    held_ref: dict[str, float],
    min_gain: float = MIN_GAIN,
    span_s: float = float("inf"),
    floor_pct: float | None = None,
) -> Acceptance:
    """The acceptance rule (module docstring) for effect ``eff`` fitted as ``fo``, its held-out
    NRMSE per entry ``held`` against the current model's ``held_ref``. ``span_s``: the longest
    simulated sequence (s), for the effect's own caveats (:meth:`Effect.caveats`);
    ``floor_pct``: the noise floor (NRMSE %, the current model's residual evidence) for the
    rule near the floor (none: that route is closed)."""
    names = list(held_ref)
    c = np.array([held[n] for n in names])
    b = np.array([held_ref[n] for n in names])
    gain = 1.0 - float(c.mean()) / float(b.mean())
    wins = int(np.sum(c < b * (1 - FOLD_TOL)))
    losses = int(np.sum(c > b * (1 + FOLD_TOL)))
    reasons, suspicious = [], []
    drop = float(b.mean()) - float(c.mean())
    if drop <= -NUMERICAL_PCT:
        reasons.append(f"{WORSE} ({float(b.mean()):.3g} % -> {float(c.mean()):.3g} %)")
    elif drop < NUMERICAL_PCT:
        reasons.append(
            f"{ROUNDING} ({NUMERICAL_PCT:g} % of NRMSE): the model already reproduces the data"
        )
    elif gain < min_gain and not _removes_the_excess(c.mean(), b.mean(), gain, floor_pct):
        reasons.append(
            f"held-out gain {100 * gain:.0f} % is below the {100 * min_gain:.0f} % minimum"
            + _excess_clause(c.mean(), b.mean(), floor_pct)
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
        elif q.name in sd and s is None:  # no direction of the fit moves it (fit_uncertainty)
            suspicious.append(f"{q.name} = {v:.3g} is not determined by these data")
    reasons += eff.refusals(p, sd)
    suspicious += eff.caveats(p, span_s)
    return Acceptance(not reasons, gain, wins, losses, reasons, suspicious)


def _removes_the_excess(cand: float, ref: float, gain: float, floor_pct: float | None) -> bool:
    """The rule near the floor (module docstring): ``ref`` at least :data:`NEAR_FLOOR_RATIO`
    times the floor, at least :data:`EXCESS_GAIN` of its excess removed, and a total gain of at
    least :data:`MIN_NEAR_GAIN`."""
    if floor_pct is None or not floor_pct > 0 or ref < NEAR_FLOOR_RATIO * floor_pct:
        return False
    return (ref - cand) >= EXCESS_GAIN * (ref - floor_pct) and gain >= MIN_NEAR_GAIN


def _excess_clause(cand: float, ref: float, floor_pct: float | None) -> str:
    if floor_pct is None or not floor_pct > 0 or ref < NEAR_FLOOR_RATIO * floor_pct:
        return ""
    share = (ref - cand) / (ref - floor_pct)
    return (
        f" and it removes {100 * share:.0f} % of the excess over the noise floor "
        f"({floor_pct:.3g} %), under the {100 * EXCESS_GAIN:.0f} % that the rule near the floor "
        "asks"
    )


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

    def judged(self, verdict: Acceptance) -> None:
        """Record the acceptance rule's verdict on this candidate."""
        self.accepted, self.gain = verdict.accepted, verdict.gain
        self.wins, self.losses = verdict.wins, verdict.losses
        self.reasons += verdict.reasons
        self.suspicious = verdict.suspicious
