"""The diagnosis's state as small frozen records passed between its steps.

- :class:`Settings`: what was asked (operator family, chaining, offsets, warm-up, search breadth
  and acceptance size);
- :class:`Setup`: what is fixed once the base is fitted (the records, their simulated sequences,
  the effect library configured for them, the candidates, the engine's shared simulations);
- :class:`Model`: one model of the procedure (base + the effects added so far): its problem, its
  fit, its held-out NRMSE per entry and the evidence of its residual.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labrig.analysis.diagnose.evidence import Evidence, collect_evidence
from labrig.analysis.extended import ExtendedProblem, FitOutcome
from labrig.analysis.records import Record
from labrig.analysis.simulate import SimSequence
from labrig.model import ModelParams
from labrig.model.effects import Effect

__all__ = ["Model", "Settings", "Setup", "mean_of"]


def mean_of(d: Mapping[str, float] | None) -> float | None:
    """The mean of a per-entry table (``None`` for none)."""
    return None if not d else float(np.mean(list(d.values())))


@dataclass(frozen=True)
class Settings:
    """What the diagnosis was asked to do (:func:`~.procedure.diagnose`'s arguments)."""

    chain: bool
    offset: bool
    warmup_s: float
    top_k: int
    min_gain: float
    shape: str = "exponential"
    memory: str = "return_point"
    initial: ModelParams | None = None
    #: processes for the independent pieces (held-out folds, the candidates of a round)
    workers: int = 1

    def fit_kwargs(self) -> dict[str, Any]:
        """The keyword arguments of :func:`~labrig.analysis.fit.fit_model` for the base."""
        return {
            "shape": self.shape,
            "memory": self.memory,
            "initial": self.initial,
            "heldout": False,
            "warmup_s": self.warmup_s,
            "chain": self.chain,
            "offset": self.offset,
        }


@dataclass(frozen=True)
class Setup:
    """What is fixed once the base model is fitted (module docstring).

    ``library``: every effect configured for these records, by name; ``candidates``: the names
    tried in the rounds, in order; ``context``: how the library was configured
    (:func:`~labrig.analysis.extended.effect_context`); ``span_s``: the longest simulated
    sequence (s); ``shared``: the engine's simulations, shared by every problem of the
    diagnosis."""

    records: tuple[Record, ...]
    sequences: tuple[SimSequence, ...]
    base_free: tuple[str, ...]
    library: Mapping[str, Effect]
    candidates: tuple[str, ...]
    context: Mapping[str, Any]
    span_s: float
    shared: Any = field(repr=False, compare=False, default=None)

    def problem(
        self, settings: Settings, effects: Sequence[Effect], base_free: Sequence[str] | None = None
    ) -> ExtendedProblem:
        """The base model with ``effects`` over the records (the base parameters ``base_free``
        free, by default those of the base fit), sharing the diagnosis's simulations."""
        return ExtendedProblem(
            self.records,
            effects,
            chain=settings.chain,
            shape=settings.shape,
            memory=settings.memory,
            warmup_s=settings.warmup_s,
            offset=settings.offset,
            base_free=self.base_free if base_free is None else base_free,
            sequences=list(self.sequences),
            shared=self.shared,
        )


@dataclass(frozen=True)
class Model:
    """One model of the procedure: base + ``effects``, fitted (``fit``), its held-out NRMSE per
    entry (leave-one-entry-out, second halves) and the evidence of its residual."""

    effects: tuple[Effect, ...]
    problem: ExtendedProblem = field(repr=False)
    fit: FitOutcome
    heldout: Mapping[str, float]
    evidence: Evidence = field(repr=False)

    @classmethod
    def of(
        cls,
        effects: Sequence[Effect],
        problem: ExtendedProblem,
        fit: FitOutcome,
        heldout: Mapping[str, float],
        records: Sequence[Record],
        warmup_s: float,
    ) -> Model:
        """The model with the evidence of its residual collected."""
        preds = problem.predictions(fit.base, fit.effects)
        ev = collect_evidence(list(records), preds, warmup_s)
        return cls(tuple(effects), problem, fit, dict(heldout), ev)

    @property
    def heldout_pct(self) -> float | None:
        return mean_of(self.heldout)

    def scores(self) -> dict[str, Any]:
        """``before`` / ``after`` of ``diagnose --json``: in-sample and held-out NRMSE."""
        return {
            "nrmse_pct": self.fit.nrmse_pct,
            "heldout_nrmse_pct": self.heldout_pct,
            "per_entry": dict(self.fit.per_entry),
        }
