"""Helpers the tests share: the CLI in-process, a protocol run on the simulated rig, small
protocols. (Fixtures built on them are in ``conftest.py``.)"""

from __future__ import annotations

import contextlib
import os
import resource
import select
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from labrig.drivers.sim.bench import BenchConfig, VirtualBench
from typer.testing import CliRunner

from labrig.cli import app
from labrig.rig.limits import RigLimits

#: the repository and its test data
ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
#: the SmartHysteresis bipolar +-150 V, 1 Hz record kept in tests/data/real (its PROVENANCE.md)
SMART_CSV = DATA / "real" / "chandratue-SmartHysteresis" / "hysteresis_v_150_1hz_2cycles_1khz.csv"

#: the keys of ``labrig fit --model BASELINE --json``
BASELINE_JSON_KEYS = (
    "params",
    "uncertainty",
    "correlation",
    "nrmse_pct",
    "per_entry",
    "heldout_nrmse_pct",
    "method",
    "entries",
)
#: the keys of ``labrig fit --json`` (the contract of the fit output): the baselines', the run
#: files fitted and the parameters' identifiability
FIT_JSON_KEYS = (*BASELINE_JSON_KEYS, "train_files", "identifiability")

#: three short sines at 500 Hz (a run file of a few hundred kB, written in about a second)
TINY = """\
name: small
rate_hz: 500
steps:
  - kind: sine
    amplitude_V: 60
    frequency_hz: 2
    cycles: 2
    rest_s: 0.2
  - kind: sine
    amplitude_V: 80
    frequency_hz: 2
    cycles: 2
    rest_s: 0.2
  - kind: sine
    amplitude_V: 100
    frequency_hz: 2
    cycles: 2
"""

#: a small version of the paper's campaign: the sweep at 50 and 100 V, 1-40 Hz, 2 cycles or 2 s,
#: and the vanishing envelope (about 25 s of protocol)
#: the fleet tests' campaign: three 100 V sines, 2 cycles each (tests/fleet/)
FLEET_CAMPAIGN = """\
name: fleet test campaign
description: three sines
rate_hz: 1000
rest_s: 0.5
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [1, 10, 40]
    cycles: 2
    min_duration_s: 1
"""
SMALL_CAMPAIGN = """\
name: small campaign
rate_hz: 1000
rest_s: 1
steps:
  - kind: sweep
    amplitudes_V: [50, 100]
    frequencies_hz: [1, 5, 20, 40]
    cycles: 2
    min_duration_s: 2
  - kind: vanishing
    amplitude_V: 100
    frequency_hz: 1
    decay_s: 3
    hold_s: 2
"""


def invoke(*args: object, columns: int | None = 160):
    """``labrig ARGS...`` in-process (typer's CliRunner), the terminal ``columns`` wide."""
    env = {"COLUMNS": str(columns)} if columns else None
    return CliRunner().invoke(app, [str(a) for a in args], env=env)


def run_protocol(text: str, tmp: Path, seed: int, rig: Path | None = None) -> Path:
    """``labrig run`` of the protocol ``text`` on the simulated rig (or ``rig``) into
    ``tmp/run{seed}.h5``; asserts it completed."""
    proto = tmp / "protocol.yaml"
    proto.write_text(text)
    out = tmp / f"run{seed}.h5"
    extra = ["--rig", str(rig)] if rig else []
    res = invoke("run", proto, "--seed", seed, "--out", out, *extra)
    assert res.exit_code == 0, res.output
    return out


def merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` merged in, nested mappings merged key by key."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def copied(folder: Path, *files: Path) -> tuple[Path, ...]:
    """Copies of ``files`` in ``folder``, under their names (a test's own, from a module's
    read-only originals)."""
    return tuple(Path(shutil.copyfile(f, folder / f.name)) for f in files)


def rig_path(tmp_path: Path, **over) -> Path:
    """The built-in simulated rig with ``over`` merged in, written to ``tmp_path/rig.yaml``."""
    from labrig.rig.rigspec import DEFAULT_RIG_YAML

    data = merge(yaml.safe_load(DEFAULT_RIG_YAML), over)
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


#: a run file's writer in another process: a block every 0.1 s until a line arrives on stdin
WRITER = """
import select, sys, numpy as np
from labrig.store import RunWriter
with RunWriter(sys.argv[1], "name: w\\n", "", {}, seed=1, protocol_name="being written") as w:
    e = w.begin_entry("first", {"kind": "sine"}, 1000.0, ["command_voltage", "strain"])
    for k in range(600):
        v = np.full(100, float(k))
        e.append({"command_voltage": v, "strain": 9 * v})
        if k == 0:
            print("writing", flush=True)
        if select.select([sys.stdin], [], [], 0.1)[0]:
            break
    e.finish("complete")
"""


def start_writer(path: Path) -> subprocess.Popen:
    """A process writing the run file ``path`` (until :func:`stop_writer`)."""
    p = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert p.stdout is not None and p.stdout.readline() == "writing\n"
    return p


def stop_writer(p: subprocess.Popen) -> None:
    if p.poll() is None:
        assert p.stdin is not None
        p.stdin.write("stop\n")
        p.stdin.flush()
    assert p.wait(timeout=30) == 0


# -- a linear bench: the hybrid plant with its hysteresis off, so what is measured is an effect ---

ALPHA0 = 11.5  # ue/V, the hybrid plant's linear block
LINEAR_TRUTH = {
    "preset": "hybrid",
    "hybrid": {
        "alpha0_ue_per_V": ALPHA0,
        "gamma_ue_per_V": 0.0,
        "bw_A_ue_per_V": 0.0,
        "use_eq11": False,
    },
}
BIPOLAR = RigLimits(v_min_V=-150.0, v_max_V=150.0, capacitance_F=1e-6, large_signal_factor=1.5)


def linear_bench(effects: list[dict], rate_hz: float = 1000.0) -> VirtualBench:
    """The simulated bench with the truth ``S = ALPHA0 u``, no noise or quantisation, and
    ``effects``."""
    cfg = BenchConfig.model_validate(
        {
            "truth": LINEAR_TRUTH,
            "amplifier": {
                "gain_V_per_V": 20.0,
                "out_min_V": -160.0,
                "out_max_V": 160.0,
                "current_limit": False,
                "monitor_noise_V": 0.0,
            },
            "gauge": {"noise_ue": 0.0, "bridge_offset_ue": 0.0},
            "daq": {"ai_bits": None, "ao_bits": None},
            "effects": effects,
        }
    )
    return VirtualBench(cfg, BIPOLAR, seed=0, rate_hz=rate_hz)


def strain(bench: VirtualBench, v_actuator: np.ndarray) -> np.ndarray:
    out = bench.step(v_actuator / bench.config.amplifier.gain_V_per_V)
    return out["gauge"] / bench.sensitivity_V_per_ue()


def planted_records(
    drives: list[tuple[str, np.ndarray]],
    fs: float,
    effect: str,
    params: dict[str, float],
    rng: np.random.Generator,
    offset: bool = False,
) -> list:
    """Chained records (0.05 s rests) of the paper's model with the library's ``effect`` at
    ``params``, one per named drive (V) at ``fs`` Hz, plus 0.5 ue of noise drawn from ``rng``
    record after record."""
    from labrig.analysis.extended import ExtendedProblem
    from labrig.analysis.records import Record
    from labrig.model import PAPER_TABLE1
    from labrig.model.effects import library

    meta = {"rest_after_s": 0.05}
    recs = [
        Record(n, fs, np.arange(v.size) / fs, v, np.arange(v.size, dtype=float), {}, "zoh", meta)
        for n, v in drives
    ]
    prob = ExtendedProblem(recs, [library()[effect]], chain=True, offset=offset)
    pred = prob.predictions(PAPER_TABLE1.model_dump(), {effect: params}, nuisance=False)
    noisy = [pred[r.name] + rng.normal(0, 0.5, r.n) for r in recs]
    return [
        Record(r.name, fs, r.time_s, r.voltage_V, s, {}, "zoh", dict(meta))
        for r, s in zip(recs, noisy, strict=True)
    ]


def contention() -> float:
    """How many times longer than its CPU time a piece of work takes on the wall clock now
    (at least 1): the larger of the machine's load per core (1-minute average) and the
    wall-clock over CPU time of a short numpy sort timed here. On a free core 1; three test
    workers on two cores about 1.5; a machine at load 10 on 2 cores about 5."""
    work = np.random.default_rng(0).random(100_000)
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(4):
        np.sort(work)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    per_core = os.getloadavg()[0] / (os.cpu_count() or 1)
    return max(1.0, per_core, wall / max(cpu, 1e-6))


def slack(seconds: float) -> float:
    """A wall-clock margin of ``seconds`` on a free machine, stretched by :func:`contention`:
    for the bounds of tests on timing (a server answers, stops or gives up within its margin)
    that must hold on a loaded machine without becoming unbounded (a hang still fails)."""
    return seconds * contention()


def children_cpu_s() -> float:
    """CPU seconds (user + system) of this process's children that have been waited for."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def arm(monkeypatch: pytest.MonkeyPatch, after: int, act: Callable[[], None]) -> list:
    """``labrig run`` opens the simulated rig as usual, but ``act`` is called once, when
    ``after`` samples have been played; returns the list the opened rigs are put in."""
    from labrig.runner import execute as runner

    real_open = runner.open_rig
    rigs: list = []

    def open_and_arm(path=None, seed=None):
        rig = real_open(path, seed)
        rigs.append(rig)
        bench, real_step = rig.sim.bench, rig.sim.bench.step
        played = [0]

        def step(ao):
            out = real_step(ao)
            if bench.playing:
                played[0] += len(ao)
                if played[0] >= after and played[0] - len(ao) < after:
                    act()
            return out

        bench.step = step
        return rig

    monkeypatch.setattr(runner, "open_rig", open_and_arm)
    return rigs


def fork_saying(work: Callable[[int], None]) -> tuple[int, int]:
    """``work(fd)`` in a fork of this process (labrig already loaded: a SIGKILL ends it as it
    would any process), saying what it has to say on the pipe ``fd``. Returns ``(pid, the
    pipe's read end)``. The child never returns to the test: it exits 0 after ``work``, 1 if
    ``work`` raised."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            os.close(read_fd)
            work(write_fd)
            code = 0
        finally:
            os._exit(code)
    os.close(write_fd)
    return pid, read_fd


def pipe_lines(fd: int, timeout_s: float) -> Iterator[str]:
    """The lines read from ``fd`` until its end; each within ``timeout_s`` (or fail)."""
    buf = b""
    while True:
        while b"\n" not in buf:
            assert select.select([fd], [], [], timeout_s)[0], "the child stopped answering"
            chunk = os.read(fd, 65536)
            if not chunk:
                return
            buf += chunk
        line, buf = buf.split(b"\n", 1)
        yield line.decode()


def reaped(pid: int) -> int:
    """The wait status of the child ``pid``, SIGKILLed first if it still runs."""
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    return os.waitpid(pid, 0)[1]
