"""``--help`` of every command without placeholders (``<bool>``, ``<path>``, ``<list[Path]>``,
``{run_file}``), every option's value named (``--out FILE``), every command built by labrig's
classes, and usage errors (an unknown option or command, a bad choice or number, a missing
argument or option) exiting 64, distinct from a bad input file (2)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer

from labrig.cli import app
from labrig.cli.typer_app import EXIT_USAGE, LabrigCommand, LabrigGroup

from helpers import invoke as run_cli

pytestmark = pytest.mark.timeout(120)

#: what typer draws when a parameter has no metavar of ours
PLACEHOLDER = re.compile(r"<[A-Za-z_\[\]|, ]+>|\{[a-z_]+\}|list\[")


def invoke(*args: object):
    return run_cli(*args, columns=200)


def commands(cmd=None, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], object]]:
    """Every command and group of the ``labrig`` tree with its path of names."""
    cmd = cmd or typer.main.get_command(app)
    yield path, cmd
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from commands(sub, (*path, name))


ALL = [path for path, _ in commands()]


def test_the_tree_has_every_command() -> None:
    names = {" ".join(p) for p in ALL}
    for expected in ("check", "run", "drivers", "info", "runs", "fit", "report", "diagnose",
                     "validate", "model figures", "batch diagnose", "sim fleet"):  # fmt: skip
        assert expected in names, names


def test_every_command_is_built_by_labrig_classes() -> None:
    """Commands registered without naming a class get labrig's (LabrigTyper's default)."""
    for path, cmd in commands():
        assert isinstance(cmd, LabrigGroup | LabrigCommand), (path, type(cmd))


@pytest.mark.parametrize("path", ALL, ids=[" ".join(p) or "labrig" for p in ALL])
def test_help_has_no_placeholders(path: tuple[str, ...]) -> None:
    res = invoke(*path, "--help")
    assert res.exit_code == 0, res.output
    assert res.stdout.lstrip().startswith("Usage: labrig")
    found = PLACEHOLDER.findall(res.stdout)
    assert not found, (found, res.stdout)


@pytest.mark.parametrize("path", ALL, ids=[" ".join(p) or "labrig" for p in ALL])
def test_every_option_names_its_value(path: tuple[str, ...]) -> None:
    """An option that takes a value shows a metavar in capitals; a flag shows none."""
    cmd = dict(commands())[path]
    text = " ".join(invoke(*path, "--help").stdout.split())
    for p in cmd.params:
        if p.param_type_name != "option" or getattr(p, "hidden", False):
            continue
        long = max(p.opts, key=len)
        if p.is_flag:
            assert re.search(re.escape(long) + r"(?: |,|/|$)(?![A-Z]{2,})", text), (long, text)
        else:
            assert re.search(re.escape(long) + r"(?:, --[a-z-]+)? [A-Z][A-Z_]+\b", text), long


def test_outputs_say_file_or_folder() -> None:
    for cmd, kind in (("fit", "FILE"), ("report", "FILE"), ("info", "FILE"), ("check", "FILE"),
                      ("run", "FILE"), ("import", "FILE"), ("validate", "FILE"),
                      ("diagnose", "DIR"), ("export", "DIR")):  # fmt: skip
        text = " ".join(invoke(cmd, "--help").stdout.split())
        assert f"--out {kind}" in text or f"--out, --csv {kind}" in text, (cmd, text)


def test_usage_line_names_arguments_in_capitals() -> None:
    assert "Usage: labrig fit [OPTIONS] RUN_FILE" in invoke("fit", "--help").stdout
    assert "Usage: labrig runs [OPTIONS] [PATHS]..." in invoke("runs", "--help").stdout
    assert "Usage: labrig info [OPTIONS] RUN_FILES..." in invoke("info", "--help").stdout


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["fit", "x.h5", "--bogus"], "No such option: --bogus"),
        (["fit", "x.h5", "--method", "newton"], "newton: not a fit method"),
        (["fit"], "Missing argument 'RUN_FILE'"),
        (["export", "x.h5"], "Missing option '--out'"),
        (["diagnose", "x.h5", "--max-effects", "nine"], "Invalid value for '--max-effects'"),
        (["diagnose", "x.h5", "--max-effects", "9"], "less than or equal to 4"),
        (["bogus"], "No such command 'bogus'"),
        (["model", "demo", "--preset", "X"], "X: not a parameter preset"),
        (["batch", "fit", "x.h5"], "Missing option '--out'"),
    ],
)
def test_usage_errors_exit_64(args: list[str], says: str) -> None:
    res = invoke(*args)
    assert res.exit_code == EXIT_USAGE == 64, res.output
    assert says in " ".join(res.stderr.replace("│", " ").split()), res.stderr
    assert "Traceback" not in res.output and res.stdout == ""


def test_a_bad_input_file_is_2_not_64(tmp_path: Path) -> None:
    res = invoke("fit", tmp_path / "missing.h5")
    assert res.exit_code == 2, res.output
    assert "run file not found" in res.stderr


def test_the_installed_command_exits_64() -> None:
    """The console script (typer's standalone mode), not only the test runner."""
    res = subprocess.run(
        [sys.executable, "-m", "labrig.cli", "fit", "--method", "newton", "x.h5"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 64, res.stderr


def test_batch_summary_counts_in_words(tmp_path: Path) -> None:
    """One run that fails (not a run file): "1 run", "1 worker" (exit 4: some runs failed)."""
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not a run file")
    res = invoke("batch", "fit", bad, "--out", tmp_path / "out", "--serial")
    assert res.exit_code == 4, res.output
    line = res.stdout.splitlines()[0]
    assert line.startswith("1 run: 0 succeeded, 1 failed"), line
    assert "on 1 worker," in line


def test_python_dash_m_labrig_is_the_command():
    """``python -m labrig`` runs the same command line as the ``labrig`` script (usage errors
    exit 64 there too)."""
    from labrig.core.version import __version__

    ok = subprocess.run(
        [sys.executable, "-m", "labrig", "--version"], capture_output=True, text=True, timeout=60
    )
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.strip() == f"labrig {__version__}"
    bad = subprocess.run(
        [sys.executable, "-m", "labrig", "no-such-command"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == EXIT_USAGE
    assert "no-such-command" in bad.stderr


def test_the_package_says_it_is_typed():
    """PEP 561: the installed package carries ``py.typed`` so type checkers read its hints."""
    from importlib import resources

    assert resources.files("labrig").joinpath("py.typed").is_file()


def test_resume_names_a_folder_or_a_pipe_as_such(tmp_path: Path) -> None:
    """``--resume`` given something that exists but is no file says what it is (a missing
    file is "not found")."""
    sweep = Path(__file__).resolve().parents[2] / "experiments" / "sweep.yaml"
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for target, says in ((tmp_path, "a folder, not a run file"),
                         (fifo, "not a regular file, not a run file"),
                         (tmp_path / "missing.h5", "run file not found")):  # fmt: skip
        res = invoke("run", sweep, "--resume", target)
        assert res.exit_code == 2, res.output
        assert f"--resume {target}: {says}" in res.stderr, res.stderr
