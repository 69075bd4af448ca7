"""Random seeds: the range a run file can record.

A run file keeps its simulated rig's seed in ``/run/seed``, a signed 64-bit integer in which
-1 means none (:mod:`labrig.store.writer`), so a seed is an integer from 0 to :data:`MAX_SEED`.
A larger one (Python's integers have no bound) cannot be written, and a negative one is refused
by NumPy's random generators.
"""

from __future__ import annotations

from labrig.core.errors import InputFileError, InputIssue

#: the largest seed: 2**63 - 1
MAX_SEED = 2**63 - 1


def check_seed(seed: int | None, where: str = "seed") -> int | None:
    """``seed`` if it is None or an integer from 0 to :data:`MAX_SEED`; otherwise
    :class:`~labrig.core.errors.InputFileError` (exit code 2) naming ``where``."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise InputFileError(
            [InputIssue(where, None, "", f"{seed!r}: expected an integer from 0 to 2^63-1")]
        )
    return seed
