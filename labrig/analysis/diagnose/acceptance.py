"""The acceptance rule of ``labrig diagnose``: when a candidate effect is added.

A candidate is added when, on held-out data (leave-one-entry-out, scored on the second half of
each held-out entry):

- the mean held-out NRMSE drops by at least :data:`MIN_GAIN` (15 %) relative to the current
  model, and by more than rounding (:data:`NUMERICAL_PCT`, for noise-free data);
- it is better (by more than :data:`FOLD_TOL`, 2 %) in at least two folds and in at least twice
  as many folds as it is worse;
- none of its physical parameters ends on a bound or on the wrong side of its null value.

Points that do not reject the candidate but make it doubtful (an unexpected sign, a poorly
determined parameter, the effect's own caveats) are kept as "suspicious" for the verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from labrig.analysis.extended import FitOutcome
from labrig.model.effects import Effect

__all__ = ["FOLD_TOL", "MIN_GAIN", "NUMERICAL_PCT", "Acceptance", "Candidate", "accept"]

#: minimum relative held-out gain for an effect to be added
MIN_GAIN = 0.15
#: a fold counts as better / worse when it changes by more than this (relative)
FOLD_TOL = 0.02
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
) -> Acceptance:
    """The acceptance rule (module docstring) for effect ``eff`` fitted as ``fo``, its held-out
    NRMSE per entry ``held`` against the current model's ``held_ref``. ``span_s``: the longest
    simulated sequence (s), for the effect's own caveats (:meth:`Effect.caveats`)."""
    names = list(held_ref)
    c = np.array([held[n] for n in names])
    b = np.array([held_ref[n] for n in names])
    gain = 1.0 - float(c.mean()) / float(b.mean())
    wins = int(np.sum(c < b * (1 - FOLD_TOL)))
    losses = int(np.sum(c > b * (1 + FOLD_TOL)))
    reasons, suspicious = [], []
    if float(b.mean()) - float(c.mean()) < NUMERICAL_PCT:
        reasons.append(
            f"held-out gain below numerical precision ({NUMERICAL_PCT:g} % of NRMSE): the "
            "model already reproduces the data"
        )
    elif gain < min_gain:
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
    return Acceptance(not reasons, gain, wins, losses, reasons, suspicious)


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
