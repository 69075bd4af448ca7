"""How long the candidates of a round have left, for the progress lines of ``labrig diagnose``.

The candidates of a round are refitted one after another (one worker) and cost about the same,
so after ``k`` of ``n`` the round has about ``(n - k) * elapsed / k`` seconds left. Nothing is
said before the first one ends (no rate yet), and nothing beyond the round: whether there is
another round depends on what this one accepts.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["RoundClock"]


class RoundClock:
    """The time left in a round of ``total`` candidates, from when it was made.

    Parameters
    ----------
    total : int
        Candidates in the round.
    clock : callable, optional
        Seconds from an arbitrary origin (default :func:`time.monotonic`).

    Examples
    --------
    >>> t = iter([0.0, 20.0])
    >>> c = RoundClock(4, clock=lambda: next(t))
    >>> c.before(1)  # the second candidate starts 20 s after the first
    'candidate 2 of 4, about 60 s left in this round'
    """

    def __init__(self, total: int, clock: Callable[[], float] = time.monotonic):
        self.total = total
        self.clock = clock
        self.start = clock()

    def before(self, k: int) -> str:
        """The words for the candidate of index ``k`` (0-based) about to start."""
        words = f"candidate {k + 1} of {self.total}"
        if k == 0:
            return words
        left = (self.total - k) * (self.clock() - self.start) / k
        return f"{words}, about {_duration(left)} left in this round"


def _duration(s: float) -> str:
    """``s`` seconds in words a person reads at a glance: 5 s, 40 s, 3 min."""
    if s < 10:
        return f"{max(s, 0.0):.0f} s"
    if s < 90:
        return f"{round(s / 10) * 10:.0f} s"
    return f"{round(s / 60):.0f} min"
