"""The yardstick every benchmark times beside its own figures: the CPU seconds of
``numpy.sort`` of 1e6 uniform floats (seed 0), so that results taken at different loads and on
different machines can be compared as ratios (benchmarks/README.md)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np


def yardstick_s(repeats: int = 5, pick: Callable[[Sequence[float]], float] = min) -> float:
    """CPU seconds of one ``numpy.sort`` of 1e6 floats: ``pick`` (the best by default, or
    ``statistics.median``) of ``repeats`` timings in this process."""
    x = np.random.default_rng(0).random(1_000_000)
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        np.sort(x)
        times.append(time.process_time() - t0)
    return float(pick(times))
