"""Fixtures shared by the test packages (tests mirror labrig's packages: tests/model,
tests/analysis, tests/diagnose, ...). Helpers that are not fixtures are in ``helpers.py``."""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers import TINY, run_protocol


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
