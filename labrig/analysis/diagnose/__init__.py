"""``labrig diagnose``: residual evidence, candidate effects, held-out selection, a verdict.

- :mod:`.procedure`: :func:`diagnose`, the procedure that ties the steps together;
- :mod:`.evidence`: what the residual looks like (noise floor, harmonics, features);
- :mod:`.ranking`: a score test that orders the candidate effects;
- :mod:`.acceptance`: the held-out rule that decides whether a candidate is added;
- :mod:`.verdict`: the verdict in words;
- :mod:`.campaign`: synthetic campaigns on the virtual bench, to test and measure all of it.
"""

from labrig.analysis.diagnose.acceptance import FOLD_TOL, MIN_GAIN, Acceptance, Candidate, accept
from labrig.analysis.diagnose.evidence import (
    EntryEvidence,
    Evidence,
    collect_evidence,
    modelled_creep_per_decade,
)
from labrig.analysis.diagnose.procedure import MAX_NFEV, Diagnosis, diagnose, split_entries
from labrig.analysis.diagnose.verdict import AT_FLOOR, CONFUSABLE_MARGIN, tell_apart

__all__ = [
    "AT_FLOOR",
    "CONFUSABLE_MARGIN",
    "FOLD_TOL",
    "MAX_NFEV",
    "MIN_GAIN",
    "Acceptance",
    "Candidate",
    "Diagnosis",
    "EntryEvidence",
    "Evidence",
    "accept",
    "collect_evidence",
    "diagnose",
    "modelled_creep_per_decade",
    "split_entries",
    "tell_apart",
]
