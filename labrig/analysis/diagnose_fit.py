"""Former name of :mod:`labrig.analysis.extended` (kept while callers move over)."""

from labrig.analysis.extended import ExtendedProblem, FitOutcome, effect_context, mains_hz_of

__all__ = ["ExtendedProblem", "FitOutcome", "effect_context", "mains_hz_of"]
