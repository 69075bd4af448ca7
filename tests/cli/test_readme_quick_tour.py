"""The README's "Quick tour", run as written: every command of its code blocks, parsed from
README.md (so the test and the README cannot drift), through the installed ``labrig`` entry
point, in a fresh folder holding a copy of ``experiments/`` (as the repository root does), on the
simulated rig; then its Python block.

``runs/<file>.h5`` is the run file the tour's first ``labrig run`` wrote (the path it printed);
``their.csv``, another lab's file, is made from a run: time, voltage and a displacement in um
over an 18 mm stack, with a units row.

- slow tier: the tour as written (the paper's 11-entry campaign, a fleet of 50; an hour or
  more), and the same commands on a 3-entry protocol in place of ``experiments/paper.yaml`` and
  ``experiments/sweep.yaml`` with a fleet of 3 of it (the only changes, listed in :data:`FAST`;
  about 5 minutes on the loaded 2-core machine);
- default tier: on that 3-entry protocol, the tour's commands that write and read files
  (``check``, ``run``, ``info``, ``runs``, ``export``, ``import``, ``sim fleet``), without the
  analysis ones (:data:`ANALYSIS`: ``fit``, ``report``, ``diagnose``, ``batch`` and the Python
  block, each tested on its own elsewhere), with a fleet of 1 (:data:`FILES_ONLY`: no batch
  reads the fleet here; the fleets of several actuators are tests/fleet/'s). The ``run
  --live`` command goes through the installed entry point (a Ctrl-C ends it); the others run
  in this process (typer's runner, in the tour's folder), each new process costing a second or
  two of CPU in imports and the compiled kernels' loading, the slow tier's business.
"""

from __future__ import annotations

import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import ROOT, TINY, invoke

README = ROOT / "README.md"
EXE = Path(sys.executable).parent / "labrig"
#: the fast tier's changes to the tour's commands (text -> replacement)
FAST = {"sim fleet 50": "sim fleet 3 --protocol experiments/paper.yaml"}
#: the tour's analysis commands, left out of the default tier (minutes each on a loaded machine)
ANALYSIS = ("labrig fit", "labrig report", "labrig diagnose", "labrig batch")
#: the default tier's changes (without the analysis commands): a fleet of one actuator
FILES_ONLY = {"sim fleet 50": "sim fleet 1 --protocol experiments/paper.yaml"}


def tour() -> tuple[list[str], str]:
    """The Quick tour's shell commands (comments dropped) and its Python block, from README.md."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## Quick tour", 1)[1].split("\n## ", 1)[0]
    commands = [
        line.strip()
        for line in section.splitlines()
        if line.startswith("    labrig ")  # an indented code block's line
    ]
    python = re.search(r"```python\n(.*?)```", section, re.S)
    assert commands and python, "the README's Quick tour has no commands or no Python block"
    return commands, python.group(1)


def their_csv(run_file: Path, out: Path) -> None:
    """Another lab's file: the run's entries back to back, strain as a displacement (um, 18 mm
    stack), a header and a units row."""
    import labrig

    run = labrig.open(run_file)
    t, v, d = [], [], []
    t0 = 0.0
    for name in run.entries:
        e = run[name]
        t.append(e.time + t0)
        t0 = float(t[-1][-1]) + 1.0 / e.rate_hz
        v.append(e["command_voltage"])
        d.append(e["strain"] * 1e-6 * 18e-3 * 1e6)  # ue over 18 mm, in um
    rows = np.column_stack([np.concatenate(t), np.concatenate(v), np.concatenate(d)])
    with out.open("w") as f:
        f.write("time,voltage,disp\ns,V,um\n")
        np.savetxt(f, rows, fmt="%.9g", delimiter=",")


def run_live(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``labrig run ... --live`` as a user runs it: the run ends and its view stays on until
    Ctrl-C; the test presses Ctrl-C (SIGINT) once the terminal (stderr) says the finished run is
    being served, and the command must then exit with the run's code (0). Bounded: 10 minutes."""
    proc = subprocess.Popen(
        [str(EXE), *args[1:]], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    said: list[str] = []
    deadline = time.monotonic() + 600
    assert proc.stderr is not None
    try:
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:  # the command ended without holding the view
                break
            said.append(line)
            if "serving the finished run" in line:
                proc.send_signal(signal.SIGINT)
                break
        out, rest = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, "".join(said) + rest)


def in_this_process(args: list[str]) -> subprocess.CompletedProcess:
    """``labrig ARGS`` through typer's runner in this process (the current folder the tour's)."""
    res = invoke(*args[1:])
    return subprocess.CompletedProcess(args, res.exit_code, res.stdout, res.stderr)


def run_tour(tmp_path: Path, fast: bool, analysis: bool = True, in_process: bool = False) -> None:
    """The tour in ``tmp_path``; ``in_process``: the commands but ``run --live`` in this process
    (the caller has made ``tmp_path`` the current folder)."""
    commands, python = tour()
    if not analysis:
        commands = [c for c in commands if not c.startswith(ANALYSIS)]
    shutil.copytree(ROOT / "experiments", tmp_path / "experiments")
    if fast:
        for name in ("paper.yaml", "sweep.yaml"):
            (tmp_path / "experiments" / name).write_text(TINY)
    first_run: Path | None = None
    for command in commands:
        if fast:
            for old, new in (FAST if analysis else FILES_ONLY).items():
                command = command.replace(old, new)
        if "<file>" in command:
            assert first_run is not None, "the tour names a run file before it runs one"
            command = command.replace("runs/<file>.h5", str(first_run.relative_to(tmp_path)))
        if command.startswith("labrig import their.csv") and not (tmp_path / "their.csv").exists():
            assert first_run is not None
            their_csv(first_run, tmp_path / "their.csv")
        args = shlex.split(command, comments=True)
        if "--live" in args:
            res = run_live(args, tmp_path)
        elif in_process:
            res = in_this_process(args)
        else:
            res = subprocess.run(
                [str(EXE), *args[1:]], cwd=tmp_path, capture_output=True, text=True, timeout=7200
            )
        assert res.returncode == 0, f"{command}\n{res.stdout}\n{res.stderr}"
        assert "Traceback" not in res.stderr, command
        if args[1] == "run" and first_run is None:
            first_run = tmp_path / res.stdout.strip().splitlines()[-1]
            assert first_run.is_file(), res.stdout
        if args[1] == "runs":
            assert str(first_run.relative_to(tmp_path)) in res.stdout, res.stdout
    if not analysis:
        assert len(list((tmp_path / "csv").glob("*.csv"))) == 3
        assert (tmp_path / "theirs.h5").is_file() and (tmp_path / "fleet/truth.json").is_file()
        assert [p.name for p in (tmp_path / "fleet").glob("*.h5")] == ["A0001.h5"]
        return
    (tmp_path / "tour.py").write_text(python)
    res = subprocess.run(
        [sys.executable, "tour.py"], cwd=tmp_path, capture_output=True, text=True, timeout=7200
    )
    assert res.returncode == 0, res.stderr
    assert '"params"' in res.stdout and '"nrmse_pct"' in res.stdout  # JSON, as `fit --json`
    for made in ("params.json", "report.html", "diagnosis/diagnosis.json", "theirs.h5",
                 "theirs-diagnosis/diagnosis.html", "fleet/truth.json", "fleet/batch/fleet.html",
                 "runs/sweep.h5"):  # fmt: skip
        assert (tmp_path / made).is_file(), made
    assert len(list((tmp_path / "csv").glob("*.csv"))) == (3 if fast else 11)


def test_the_tour_parses():
    commands, python = tour()
    assert commands[0].startswith("labrig check experiments/paper.yaml")
    assert any("<file>" in c for c in commands) and "import labrig" in python
    assert all(old in " ".join(commands) for old in FAST), "FAST no longer matches the README"
    assert FILES_ONLY.keys() == FAST.keys(), "FILES_ONLY no longer matches the README"


@pytest.mark.skipif(not EXE.exists(), reason="needs the labrig entry point")
@pytest.mark.timeout(600)
def test_the_quick_tours_files_on_a_three_entry_protocol(tmp_path: Path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run_tour(tmp_path, fast=True, analysis=False, in_process=True)


@pytest.mark.slow
@pytest.mark.skipif(not EXE.exists(), reason="needs the labrig entry point")
@pytest.mark.timeout(1800)
def test_the_quick_tour_on_a_three_entry_protocol(tmp_path: Path):
    run_tour(tmp_path, fast=True)


@pytest.mark.slow
@pytest.mark.skipif(not EXE.exists(), reason="needs the labrig entry point")
@pytest.mark.timeout(4 * 3600)
def test_the_quick_tour_as_written(tmp_path: Path):
    run_tour(tmp_path, fast=False)
