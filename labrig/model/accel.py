"""Where the compiled kernels come from, and the numpy fallback when they cannot.

The hot loops of the model (the hysteresis operator's sequential pass, the relaxor banks'
recursion) are compiled with numba in :mod:`labrig.model.compiled`. numba is imported only
when a kernel is first needed, never when ``labrig`` or ``labrig.model`` is imported, so the
command line starts without it (what its start costs: benchmarks/RESULTS.md).

Compiled machine code is cached on disk (``@njit(cache=True)``): numba writes it to the
``__pycache__`` folder beside ``compiled.py`` when that folder is writable, else to its
user-wide cache folder (``$NUMBA_CACHE_DIR`` if set, else ``~/.cache/numba`` or the platform's
equivalent). The first use on a machine compiles (seconds); later processes load the cache.

If numba cannot be imported, or its kernels cannot be loaded (with no writable cache folder
numba refuses ``cache=True`` functions), :func:`kernels` warns once and returns ``None``; every
caller then runs its numpy code, which gives the same results.
"""

from __future__ import annotations

import functools
import warnings
from types import ModuleType


@functools.cache
def kernels() -> ModuleType | None:
    """The module of compiled kernels, or ``None`` (one warning per process) without numba.

    Returns
    -------
    module or None
        :mod:`labrig.model.compiled`, or ``None`` when numba or its cache is not available.
    """
    try:
        import numba  # noqa: F401
    except Exception as exc:  # ImportError, or numba's own errors on an unsupported platform
        warnings.warn(
            f"numba is not available ({type(exc).__name__}: {exc}); the model runs its "
            "numpy code instead (same results, several times slower)",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    try:
        from labrig.model import compiled
    except Exception as exc:  # e.g. no writable folder for numba's cache
        warnings.warn(
            f"the model's compiled kernels could not be loaded ({type(exc).__name__}: {exc}); "
            "if numba found no writable folder for its cache, set NUMBA_CACHE_DIR to one. "
            "The model runs its numpy code instead (same results, several times slower)",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    return compiled


def loaded() -> bool:
    """Whether this process has already loaded the compiled kernels (without loading them).

    A caller whose work is small next to numba's start (its import and first kernel loads,
    once per process; a compilation on a machine whose cache is empty) runs the numpy code
    unless the kernels are already there: the simulated rig (:func:`stream_engine`).

    Returns
    -------
    bool
        ``True`` when :func:`kernels` has returned the compiled module in this process.
    """
    return kernels.cache_info().currsize > 0 and kernels() is not None  # the cached answer


def stream_engine() -> str:
    """The engine for a model run block by block alongside other work (the simulated rig):
    ``"compiled"`` when the kernels are already loaded in this process, else ``"numpy"``.

    The numpy code costs more per block than the compiled code but needs no start, so it is
    the cheaper choice for a short run; a run long enough to repay numba's start
    (:func:`labrig.runner.execute.repays_kernels`), a job that simulates many campaigns in one
    process (``labrig sim fleet``) and a server with no set end (``labrig sim serve``) load the
    kernels first. The two engines' records agree to 1e-10 of full scale (the compiled stream
    keeps fewer relaxor modes; tests/drivers/test_sim_physics.py), below one code of the
    simulated converters.

    Returns
    -------
    str
        ``"compiled"`` or ``"numpy"``.
    """
    return "compiled" if loaded() else "numpy"


def reset() -> None:
    """Forget whether numba loaded (for tests that hide it)."""
    kernels.cache_clear()
