"""Independent pieces of an analysis (held-out folds, candidate effects) on several processes.

:func:`map_tasks` runs ``task(i)`` for ``i = 0..n-1`` and returns the results in order. With one
worker (the default) it runs them in this process, one after the other. With more, it forks
worker processes that inherit everything already computed (records, simulations, compiled
kernels) and sends back only the results, which must be picklable. Each task's result depends
on its inputs only, never on which process ran it or on what ran before it there, so a result
is the same whatever the number of workers (the tests compare them). Where processes cannot be
forked (Windows), the tasks run one after the other.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["available_workers", "map_tasks"]

T = TypeVar("T")

#: the task of the pool being run (workers are forked, so they find it here)
_TASK: Callable[[int], Any] | None = None


def _run(i: int) -> Any:
    if _TASK is None:  # set before the pool forks its workers
        raise RuntimeError("map_tasks: a worker started without its task")
    return _TASK(i)


def available_workers() -> int:
    """The processors this process may use (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return max(1, os.cpu_count() or 1)


def _can_fork() -> bool:
    return "fork" in multiprocessing.get_all_start_methods()


def map_tasks(task: Callable[[int], T], n: int, workers: int = 1) -> list[T]:
    """``[task(0), ..., task(n - 1)]``, on ``workers`` forked processes when more than one."""
    global _TASK
    if workers <= 1 or n <= 1 or not _can_fork():
        return [task(i) for i in range(n)]
    previous, _TASK = _TASK, task
    try:
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(max_workers=min(workers, n), mp_context=ctx) as pool:
            return list(pool.map(_run, range(n)))
    finally:
        _TASK = previous
