"""Signals for real: SIGINT, SIGTERM, SIGHUP, SIGQUIT and SIGKILL sent to a running ``labrig run``.

Each test starts the run in a subprocess on the simulated rig (``labrig run``, or the runner in a
fork of the test's process), paced to the wall clock (``--realtime``), lets it write for a while
and signals it:

- SIGINT (Ctrl-C), SIGTERM, SIGHUP (terminal or SSH session closed), SIGQUIT (Ctrl-\\): exit
  code 128 + signal number (130, 143, 129, 131), a valid file whose run and running entry are
  ``aborted`` with the signal named, the exit code recorded, a ramp to 0 V recorded from the
  voltage the run was at, and the amplifier at 0 V at the end. The simulators live in the
  signalled process, so the 0 V is read from the file: the runner stores the amplifier's
  read-back voltage after the ramp as ``/run/final_amplifier_voltage_V``.
- SIGKILL: no cleanup at all. The file must open as it is (labrig has no ``recover`` step:
  blocks are flushed as they are written), hold every block the run reported flushed before
  the kill, intact, and read as incomplete (status ``running``).
"""

from __future__ import annotations

import fcntl
import os
import pty
import queue
import select
import signal
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.runner.execute import execute, preflight
from labrig.store import read_run

from helpers import fork_saying, pipe_lines, reaped

ROOT = Path(__file__).resolve().parents[2]
SWEEP = ROOT / "experiments" / "sweep.yaml"

pytestmark = pytest.mark.timeout(120)


def labrig_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "labrig"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]


class Proc:
    """A subprocess whose stdout and stderr lines are collected by threads (no pipe stalls)."""

    def __init__(self, args: list[str], cwd: Path):
        self.p = subprocess.Popen(
            args,
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "COLUMNS": "120"},
        )
        self.lines: queue.Queue[tuple[str, str]] = queue.Queue()
        self.out: list[str] = []
        self.err: list[str] = []
        for name, stream, sink in (
            ("out", self.p.stdout, self.out),
            ("err", self.p.stderr, self.err),
        ):
            threading.Thread(target=self._pump, args=(name, stream, sink), daemon=True).start()

    def _pump(self, name, stream, sink) -> None:
        for line in stream:
            sink.append(line)
            self.lines.put((name, line))

    def wait_line(self, pred, timeout: float) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                _, line = self.lines.get(timeout=0.1)
            except queue.Empty:
                if self.p.poll() is not None:
                    break
                continue
            if pred(line):
                return line
        raise AssertionError(f"no such line; stderr so far:\n{''.join(self.err)}")

    def finish(self, timeout: float = 30) -> int:
        try:
            return self.p.wait(timeout=timeout)
        finally:
            if self.p.poll() is None:
                self.p.kill()
                self.p.wait(5)

    @property
    def stderr(self) -> str:
        time.sleep(0.05)  # let the pump threads drain
        return "".join(self.err)


def wait_for_file(path: Path, proc: Proc, timeout: float = 30) -> None:
    end = time.monotonic() + timeout
    while not path.exists():
        assert proc.p.poll() is None, f"the run ended early:\n{proc.stderr}"
        assert time.monotonic() < end, "the run file never appeared"
        time.sleep(0.02)


def check_prefix(entry, plan_step) -> None:
    """The samples in the file are the first n of the entry, intact: time and command."""
    n = entry.n_samples
    assert n > 0
    np.testing.assert_allclose(entry["time"], np.arange(n) / plan_step.rate_hz, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(entry["command_voltage"], plan_step.samples(0, n))
    for ch in entry.channels:
        assert np.all(np.isfinite(entry[ch])), ch


#: signal -> (exit code, words of the run's status_reason)
EXPECTED = {
    signal.SIGINT: (130, "Ctrl-C"),
    signal.SIGTERM: (143, "SIGTERM"),
    signal.SIGHUP: (129, "SIGHUP"),
    signal.SIGQUIT: (131, "SIGQUIT"),
}
#: the ramp's limit on the default rig: 0.5 x 0.18 A / (6 uF x 1.7)
RAMP_LIMIT_V_PER_S = 0.5 * 0.18 / (6e-6 * 1.7)


@pytest.mark.parametrize(
    ("sig", "repeats"),
    [
        (signal.SIGINT, 1),
        (signal.SIGTERM, 1),
        # the default tier keeps SIGINT and SIGTERM (and the closed terminal below: SIGHUP)
        pytest.param(signal.SIGHUP, 1, marks=pytest.mark.slow),
        pytest.param(signal.SIGQUIT, 1, marks=pytest.mark.slow),
        pytest.param(signal.SIGINT, 5, marks=pytest.mark.slow),
        pytest.param(signal.SIGHUP, 3, marks=pytest.mark.slow),
    ],
    ids=["SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT", "SIGINTx5", "SIGHUPx3"],
)
def test_interrupt_stops_at_0V_with_an_aborted_valid_file(tmp_path, sig, repeats):
    """One signal, or an impatient burst (Ctrl-C pressed five times within 40 ms; a closing
    terminal's repeated SIGHUP): the repeats must not interrupt the ramp to 0 V or the closing
    of the file, nor swallow the first one."""
    code_expected, words = EXPECTED[sig]
    out = tmp_path / "run.h5"
    proc = Proc([*labrig_cmd(), "run", str(SWEEP), "--realtime", "--out", str(out)], tmp_path)
    try:
        proc.wait_line(lambda s: "entries" in s, timeout=30)
        wait_for_file(out, proc)
        time.sleep(2.5)  # sine_50V_1Hz is 5 s long: this lands mid-entry, near its 50 V peak
        proc.p.send_signal(sig)
        for gap in (0.0, 0.002, 0.005, 0.01, 0.02)[: repeats - 1]:
            time.sleep(gap)  # a burst: repeats land in the different phases of the cleanup
            if proc.p.poll() is None:
                proc.p.send_signal(sig)
        code = proc.finish(timeout=30)
    finally:
        proc.finish(timeout=5)
    err = proc.stderr
    assert "Traceback" not in err
    if repeats == 1:
        assert code == code_expected, err
        assert "run aborted" in err
        assert "".join(proc.out).strip().splitlines()[-1] == str(out)  # prints the path
    else:
        # a repeat arriving after the run was cleaned up (while the CLI prints) may end the
        # process by the signal itself: the shell shows 128 + n either way
        assert code in (code_expected, -sig), err

    f = read_run(out)
    assert f.status == "aborted" and words in f.reason
    assert f.exit_code == code_expected
    assert f.end_time
    assert len(f.planned_entries) == 10
    entries = list(f)
    assert entries and entries[-1].status == "aborted"
    assert all(e.status == "complete" for e in entries[:-1])
    plan, _ = preflight(SWEEP, None)
    last = entries[-1]
    check_prefix(last, plan.step(last.name))
    # it stopped promptly: the entry was cut short (the file, not a wall clock, says so: under
    # load the entry may start late, and the ramp and closing take longer)
    assert 0.0 < last.duration_s < last.step["duration_s"]
    with h5py.File(out, "r") as h:
        v = h["run/final_amplifier_voltage_V"]
        assert float(v[()]) == 0.0 and v.attrs["units"] == "V"
        ramp = h["run/ramp_to_zero"]
        t, volts = ramp["time"][()], ramp["voltage"][()]
        v0 = float(ramp.attrs["start_voltage_V"])
    # it ramped from where the run was to 0 V, and the recorded times of the writes keep to the
    # limit; where the run was is the sine's value at the stop, anywhere within its amplitude
    # (0 V exactly when the stop falls on a block boundary at a zero crossing, as under load)
    assert abs(v0) <= 50.0 + 1e-9 and volts[0] == v0 and volts[-1] == 0.0
    assert t[-1] >= 0.9 * v0 / RAMP_LIMIT_V_PER_S
    assert np.all(np.abs(volts) >= abs(v0) - RAMP_LIMIT_V_PER_S * t - 1e-9)


def run_reporting_blocks(proto: Path, out: Path, said: int) -> None:
    """The runner, paced to the clock, saying ``flushed K ENTRY N`` on the pipe ``said`` after
    each block of an entry is appended (and flushed)."""
    plan, rig = preflight(proto, None)

    def progress(k, n, name, frac, left):
        if name == plan.steps[k].name:  # not a rest
            n_done = round(frac * plan.steps[k].n_samples)
            os.write(said, f"flushed {k} {name} {n_done}\n".encode())

    execute(plan, rig, out, seed=5, realtime=True, progress=progress)


KILL_PROTOCOL = """\
name: kill test
rate_hz: 2000
rest_s: 0.3
steps:
  - kind: sine
    amplitude_V: 50
    frequency_hz: 5
    cycles: 3
  - kind: sine
    amplitude_V: 100
    frequency_hz: 2
    cycles: 10
"""


def test_sigkill_keeps_every_reported_block(tmp_path):
    """The runner's progress callback runs after each block is appended (and flushed); the
    child running it says so on a pipe, the test kills it mid-entry and reads the file as it is:
    every reported block there, the file incomplete, and (paced to the clock) no more samples
    than the time since the file appeared."""
    proto = tmp_path / "kill.yaml"
    proto.write_text(KILL_PROTOCOL)
    out = tmp_path / "run.h5"
    # the run in a fork of this process (labrig loaded): killed as any process
    pid, read_fd = fork_saying(lambda said: run_reporting_blocks(proto, out, said))
    reported: dict[str, int] = {}
    killed = False
    try:
        end = time.monotonic() + 30
        while not out.exists():
            assert os.waitpid(pid, os.WNOHANG) == (0, 0), "the run ended early"
            assert time.monotonic() < end, "the run file never appeared"
            time.sleep(0.02)
        t0 = time.monotonic()  # (the lines meanwhile wait in the pipe, none lost)
        for line in pipe_lines(read_fd, 30):
            _, k, name, n = line.split()
            reported[name] = max(reported.get(name, 0), int(n))
            if int(k) == 1 and int(n) >= 1500 and not killed:  # 0.75 s into the second entry
                os.kill(pid, signal.SIGKILL)
                elapsed = time.monotonic() - t0
                killed = True
            # lines written between our read and the kill were reported too: read on to the end
    finally:
        os.close(read_fd)
        status = reaped(pid)
    assert killed and os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status

    plan, _ = preflight(proto, None)
    f = read_run(out)  # no repair step needed
    assert f.status == "running" and f.incomplete
    assert f.seed == 5
    first, second = plan.steps
    assert set(reported) == {first.name, second.name}
    e1, e2 = f[first.name], f[second.name]
    assert e1.status == "complete" and e1.n_samples == first.n_samples
    assert e2.status == "running"
    assert e2.n_samples >= reported[second.name]
    assert e2.n_samples < second.n_samples
    check_prefix(e1, first)
    check_prefix(e2, second)
    # paced to the clock: the samples never ahead of the time it ran, give or take one block
    assert e1.duration_s + e2.duration_s <= elapsed + 0.2


@pytest.mark.slow
def test_sigkill_of_the_cli_leaves_a_readable_incomplete_file(tmp_path):
    """SIGKILL of ``labrig run`` itself: the file as it was, readable, incomplete (``running``),
    its samples intact and never ahead of the clock. (No cleanup runs on SIGKILL: what is in
    the file is what the runner had flushed, as in the test above, which kills the runner's
    process at a known block.)

    Fast equivalent in the default tier: tests/runner/test_runner_signals.py::test_sigkill_keeps_every_reported_block
    """  # noqa: E501
    out = tmp_path / "run.h5"
    proc = Proc([*labrig_cmd(), "run", str(SWEEP), "--realtime", "--out", str(out)], tmp_path)
    try:
        proc.wait_line(lambda s: "entries" in s, timeout=30)
        wait_for_file(out, proc)
        t0 = time.monotonic()
        time.sleep(2.0)
        proc.p.send_signal(signal.SIGKILL)
        elapsed = time.monotonic() - t0
        proc.finish(timeout=30)
    finally:
        proc.finish(timeout=5)
    assert proc.p.returncode == -signal.SIGKILL

    f = read_run(out)
    assert f.status == "running" and f.incomplete
    entries = list(f)
    assert [e.status for e in entries] == ["running"]
    e = entries[0]
    plan, _ = preflight(SWEEP, None)
    check_prefix(e, plan.step(e.name))
    # paced to the clock: about the time it ran, give or take startup and one block
    assert 0.0 < e.duration_s <= elapsed + 0.2  # something flushed, never ahead of the clock


def test_closing_the_terminal_ends_at_0V_with_exit_129(tmp_path):
    """The real SIGHUP: ``labrig run`` on a pseudo-terminal that is its controlling terminal;
    closing the terminal's master side makes the kernel send SIGHUP, and every later write to
    the terminal fails. The run must still ramp to 0 V, record the hangup and exit 129 (a
    failed write of the progress bar or the summary must not turn it into 1 or 120)."""
    out = tmp_path / "run.h5"
    master, slave = pty.openpty()

    def controlling_terminal() -> None:
        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    p = subprocess.Popen(
        [*labrig_cmd(), "run", str(SWEEP), "--realtime", "--out", str(out)],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        cwd=tmp_path,
        start_new_session=True,
        preexec_fn=controlling_terminal,
    )
    os.close(slave)
    seen = b""
    try:
        deadline = time.monotonic() + 30
        while b"step 1/10" not in seen and time.monotonic() < deadline:  # the bar runs
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                seen += os.read(master, 65536)
        assert b"step 1/10" in seen, seen[-2000:]
        end = time.monotonic() + 2.0
        while time.monotonic() < end:  # keep reading: the terminal is alive until closed
            ready, _, _ = select.select([master], [], [], 0.05)
            if ready:
                os.read(master, 65536)
    finally:
        os.close(master)  # the terminal goes away
    try:
        code = p.wait(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(5)
    assert code == 129
    f = read_run(out)
    assert f.status == "aborted" and "SIGHUP" in f.reason and f.exit_code == 129
    with h5py.File(out, "r") as h:
        assert float(h["run/final_amplifier_voltage_V"][()]) == 0.0
        assert h["run/ramp_to_zero/voltage"][-1] == 0.0
