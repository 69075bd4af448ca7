"""One BLAS thread for small matrix products.

The block realisation of the relaxors and the fits multiply small matrices many times; on this
class of machine OpenBLAS's threads make that 2-5x slower when another process holds a core
(measured in benchmarks/RESULTS.md). :func:`single_thread_blas` sets the OpenBLAS copies that
numpy and scipy loaded to one thread for the duration of a block and restores them after.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import glob
import os
import threading
from collections.abc import Iterator
from types import ModuleType
from typing import Any


@functools.cache
def _openblas_libs() -> list[tuple[Any, Any, Any]]:
    """(lib, set, get) for the OpenBLAS copies numpy and scipy have loaded (none if unknown)."""
    out = []
    import numpy
    import scipy

    names = (
        ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
        ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
        ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
        ("openblas_set_num_threads", "openblas_get_num_threads"),
    )
    packages: tuple[ModuleType, ...] = (numpy, scipy)  # annotated: mypy is slow to join two modules
    for pkg in packages:
        libdir = os.path.join(
            os.path.dirname(pkg.__file__ or ""), os.pardir, pkg.__name__ + ".libs"
        )
        for path in glob.glob(os.path.join(libdir, "*openblas*.so*")):
            try:
                lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
            except OSError:
                continue  # not loaded in this process
            for s, g in names:
                if hasattr(lib, s) and hasattr(lib, g):
                    out.append((lib, getattr(lib, s), getattr(lib, g)))
                    break
    return out


#: the thread count each OpenBLAS copy had when the outermost block began, and how many blocks
#: (in any thread) are open: the count is set to 1 by the first and restored by the last, so
#: blocks that overlap in several threads (a simulated bench stepping in its servers' threads
#: while a fit runs) never restore a 1 another block set
_saved: list[tuple[Any, int]] = []
_depth = 0
_lock = threading.Lock()


def _after_fork_in_child() -> None:
    """A forked child (the analysis workers of :mod:`labrig.analysis.parallel`) has only the
    forking thread: the blocks other threads had open are not its own, and the lock, held
    across the fork, is released (the count it inherited stays as it was)."""
    global _depth
    _saved.clear()
    _depth = 0
    _lock.release()


if hasattr(os, "register_at_fork"):  # POSIX: never fork while another thread holds the lock
    os.register_at_fork(
        before=_lock.acquire, after_in_parent=_lock.release, after_in_child=_after_fork_in_child
    )


@contextlib.contextmanager
def single_thread_blas() -> Iterator[None]:
    """Run the block with one OpenBLAS thread (restored afterwards); a no-op if not found.

    Thread-safe: the setting is process-wide, so it is made by the first of overlapping blocks
    (in any threads) and undone by the last."""
    global _depth
    with _lock:
        if _depth == 0:
            try:
                _saved[:] = [(s, int(g())) for _, s, g in _openblas_libs()]
                for s, _ in _saved:
                    s(1)
            except Exception:  # pragma: no cover - BLAS without the symbols: leave it alone
                _saved.clear()
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                for s, n in _saved:
                    s(n)
                _saved.clear()
