"""The time left in a diagnosis round (``labrig diagnose``'s progress lines)."""

from __future__ import annotations

import pytest

from labrig.analysis.diagnose.eta import RoundClock


def clock_at(*times: float):
    it = iter(times)
    return lambda: next(it)


def test_nothing_is_promised_before_the_first_candidate_ends() -> None:
    c = RoundClock(4, clock=clock_at(100.0))
    assert c.before(0) == "candidate 1 of 4"


@pytest.mark.parametrize(
    ("k", "elapsed", "words"),
    [
        (1, 2.0, "about 6 s left"),  # 3 left at 2 s each
        (2, 8.0, "about 8 s left"),  # 2 left at 4 s each
        (3, 9.0, "about 3 s left"),
        (1, 3.4, "about 10 s left"),  # 10.2 s: tens from 10 s on
        (1, 29.0, "about 90 s left"),  # 87 s: still in seconds just under 90 ...
        (1, 30.0, "about 2 min left"),  # ... 90 s and more in minutes
    ],
)
def test_the_rest_of_the_round_at_the_rate_so_far(k: int, elapsed: float, words: str) -> None:
    c = RoundClock(4, clock=clock_at(0.0, elapsed))
    said = c.before(k)
    assert said.startswith(f"candidate {k + 1} of 4, ") and said.endswith(" in this round")
    assert words in said
