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
