"""Fixtures shared by the test packages (tests mirror labrig's packages: tests/model,
tests/analysis, tests/diagnose, ...). Helpers that are not fixtures are in ``helpers.py``."""

from __future__ import annotations

import contextlib
import functools
import gc
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer.main
import typer.testing
from compile_kernels import GROUPS

from helpers import ROOT, TINY, run_protocol

#: test files that take the longest (wall-clock seconds per file on a new checkout's suite,
#: 2026-11-29: 44 s for the type check with mypy's cache cold down to 12 s), handed out
#: first: with ``--dist loadfile`` a file runs on one worker, and a long file started last
#: keeps the other workers idle at the end of the run (``--no-loadscope-reorder`` in
#: pyproject.toml keeps this order; pytest-xdist would otherwise hand out files by their number
#: of tests, the type check's two tests last)
LONGEST_FIRST = (
    "tests/test_types.py",
    "tests/runner/test_live.py",
    "tests/fleet/test_fleet.py",
    "tests/store/test_store_isolation.py",
    "tests/store/test_corrupt_runfiles.py",
    "tests/runner/test_runner_signals.py",
    "tests/model/test_relaxor.py",
    "tests/cli/test_fuzz_parsers.py",
    "tests/api/test_api.py",
    "tests/model/test_mittag_leffler.py",
    "tests/store/test_seal_additions.py",
    "tests/cli/test_cli_validate.py",
    "tests/control/test_control_remanence.py",
    "tests/store/test_safety_disk_full.py",
    "tests/runner/test_resume.py",
    "tests/report/test_report_figures.py",
    "tests/cli/test_readme_quick_tour.py",
)


def pytest_configure(config: pytest.Config) -> None:
    """Lets this session and the commands its tests start cache bytecode even where the
    environment sets ``PYTHONDONTWRITEBYTECODE``: the tests start hundreds of ``labrig``
    processes, and each would otherwise compile labrig's ~200 modules from source (about
    0.25 s of CPU per process). The caches are ``__pycache__`` folders, ignored by git.

    In the controller of a parallel session, before the workers start: fills numba's cache
    when it is empty (:func:`compiling_kernels`) and, meanwhile, writes the test modules'
    rewritten bytecode (:func:`rewrite_test_modules`)."""
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    sys.dont_write_bytecode = False
    parallel = config.getoption("numprocesses", None) and not config.getoption("collectonly")
    if parallel and not hasattr(config, "workerinput"):
        with compiling_kernels():
            rewrite_test_modules(config)


#: typer's CliRunner turns the app into a click command on every ``invoke`` (about 20 ms for
#: labrig's commands; the suite invokes the CLI in-process 956 times, counted 2026-11-29): one
#: command per app for the session. Click commands are made to be invoked again and again
#: (labrig's group and commands keep nothing between invocations); only the test runner's
#: module is changed, not labrig's entry point, which builds its command once per process.
if hasattr(typer.testing, "_get_command"):
    typer.testing._get_command = functools.cache(typer.main.get_command)


#: the modules of numba kernels, each cached in the ``__pycache__`` beside it
KERNEL_MODULES = (
    ROOT / "labrig" / "model" / "compiled.py",
    ROOT / "labrig" / "analysis" / "baseline_kernels.py",
)


def kernel_cache_is_cold(
    modules: tuple[Path, ...] = KERNEL_MODULES, cache_dir: str | None = None
) -> bool:
    """Whether one of ``modules`` has no numba index for this Python (``*.py311.nbi``) at least
    as new as its source: a new checkout, or a kernel edited since it was last compiled. The
    indexes are in the ``__pycache__`` beside each module, or anywhere under ``cache_dir``
    (default ``$NUMBA_CACHE_DIR``) when that is set, as numba itself places them."""
    cache_dir = os.environ.get("NUMBA_CACHE_DIR") if cache_dir is None else cache_dir
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    for src in modules:
        made = src.stat().st_mtime
        pattern = f"{src.stem}.*.{tag}.nbi"
        index = (
            Path(cache_dir).rglob(pattern)
            if cache_dir
            else (src.parent / "__pycache__").glob(pattern)
        )
        if not any(f.stat().st_mtime >= made for f in index):
            return True
    return False


@contextlib.contextmanager
def compiling_kernels(timeout_s: float = 300.0) -> Iterator[None]:
    """Compiles the numba kernels into their cache, when it is cold, while the ``with`` block
    runs and until it is done: ``tests/compile_kernels.py``'s two groups at once (about 15 s
    of wall clock on 2 cores in a new checkout), instead of every worker and every ``labrig``
    command the first tests start compiling the same kernels at the same time. Only a
    warm-up: a failure or a timeout here leaves the kernels to be compiled where they are
    first used."""
    if not kernel_cache_is_cold():
        yield
        return
    script = ROOT / "tests" / "compile_kernels.py"
    procs = [
        subprocess.Popen(
            [sys.executable, str(script), group],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for group in GROUPS
    ]
    deadline = time.monotonic() + timeout_s
    try:
        yield
        for p in procs:
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        pass
    finally:  # past the timeout, or the session interrupted: none is left running
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def rewrite_test_modules(config: pytest.Config) -> None:
    """Writes the bytecode of every test module whose assertions pytest rewrites (its
    ``__pycache__/*-pytest-*.pyc``), where it is missing or older than its source, as pytest's
    import hook does on import. In a new checkout each worker would otherwise rewrite all of
    them at once on collecting (about 7.6 s of CPU per worker); they now load the files
    written here. Relies on pytest's internal ``_pytest.assertion.rewrite``: when that
    changes, it does nothing, and each worker rewrites as before."""
    try:
        from _pytest.assertion import rewrite

        state = config.stash[rewrite.assertstate_key]
        for fn in sorted((ROOT / "tests").rglob("test_*.py")):
            pyc = rewrite.get_cache_dir(fn) / (fn.name[:-3] + rewrite.PYC_TAIL)
            if rewrite._read_pyc(fn, pyc) is None and rewrite.try_makedirs(pyc.parent):
                source_hash, co = rewrite._rewrite_test(fn, config)
                rewrite._write_pyc(state, co, source_hash, pyc)
    except (ImportError, AttributeError, KeyError, TypeError, OSError, SyntaxError):
        return


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """In a worker of a parallel session, after its last test: moves every object to the
    collector's permanent generation (``gc.freeze``), so the interpreter's last collections at
    exit do not walk the heap a whole session has built (numba, scipy, matplotlib, pandas,
    dask). The controller waited about 2 s for each worker to end, 0.3 s with this (one worker
    on tests/fleet and tests/report, 2026-11-29). Nothing of the session runs after it."""
    if hasattr(config, "workerinput"):
        gc.freeze()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Puts the files of :data:`LONGEST_FIRST` first, in that order; the rest keep theirs."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run file of :data:`helpers.TINY` (seed 1) on the simulated rig, shared read-only."""
    return run_protocol(TINY, tmp_path_factory.mktemp("tiny"), seed=1)


def pytest_make_parametrize_id(config: pytest.Config, val: object, argname: str) -> str | None:
    """Sets in test ids in sorted order: a set's order varies between processes (string hashing
    is salted), and pytest-xdist's workers must collect the same ids."""
    if isinstance(val, set | frozenset):
        return repr(sorted(val, key=repr))
    return None
