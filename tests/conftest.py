"""Fixtures shared by the test packages (tests mirror labrig's packages: tests/model,
tests/analysis, tests/diagnose, ...). Helpers that are not fixtures are in ``helpers.py``."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from helpers import TINY, run_protocol

#: test files that take the longest (CPU seconds measured on the suite, cold caches for mypy),
#: handed out first: with ``--dist loadfile`` a file runs on one worker, and a long file started
#: last keeps the other workers idle at the end of the run (``--no-loadscope-reorder`` in
#: pyproject.toml keeps this order; pytest-xdist would otherwise hand out files by their number
#: of tests, the type check's two tests last)
LONGEST_FIRST = (
    "tests/test_types.py",
    "tests/fleet/test_fleet.py",
    "tests/cli/test_readme_quick_tour.py",
    "tests/runner/test_runner_signals.py",
    "tests/drivers/test_drivers.py",
    "tests/model/test_relaxor.py",
    "tests/store/test_safety_disk_full.py",
    "tests/drivers/test_sim_serve.py",
    "tests/store/test_corrupt_runfiles.py",
    "tests/api/test_api.py",
    "tests/runner/test_live.py",
)


def pytest_configure(config: pytest.Config) -> None:
    """Lets this session and the commands its tests start cache bytecode even where the
    environment sets ``PYTHONDONTWRITEBYTECODE``: the tests start hundreds of ``labrig``
    processes, and each would otherwise compile labrig's ~200 modules from source (about
    0.25 s of CPU per process). The caches are ``__pycache__`` folders, ignored by git."""
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    sys.dont_write_bytecode = False


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
