"""The ``labrig`` process freezes the collector at exit (``LabrigTyper.__call__``): the script
and ``python -m labrig`` pass there, the tests' in-process runner does not."""

from __future__ import annotations

import atexit
import gc
import subprocess
import sys

import pytest

from labrig.cli import app

from helpers import ROOT, invoke


def test_the_script_entry_registers_gc_freeze_at_exit(monkeypatch):
    registered: list = []
    monkeypatch.setattr(atexit, "register", lambda fn, *a, **k: registered.append(fn))
    with pytest.raises(SystemExit) as ended:
        app(["--version"], prog_name="labrig")
    assert ended.value.code in (0, None)
    assert gc.freeze in registered


def test_the_in_process_runner_leaves_the_collector_alone(monkeypatch):
    registered: list = []
    monkeypatch.setattr(atexit, "register", lambda fn, *a, **k: registered.append(fn))
    res = invoke("--version")
    assert res.exit_code == 0, res.output
    assert gc.freeze not in registered


def test_exit_handlers_still_run_after_the_freeze(tmp_path):
    """A handler registered before the command starts runs after the freeze (exit handlers
    run last registered first) and still runs: the freeze skips the collector's walk, not
    the exit."""
    mark = tmp_path / "ran"
    code = (
        "import atexit, sys, pathlib\n"
        "from labrig.cli import app\n"
        f"atexit.register(pathlib.Path({str(mark)!r}).write_text, 'yes')\n"
        "sys.argv = ['labrig', '--version']\n"
        "app(prog_name='labrig')\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0, res.stderr
    assert mark.read_text() == "yes"
