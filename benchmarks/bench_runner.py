# Measured (two full runs, 2026-11-22, 05:39 and 06:01 UTC) on a shared 2-core AMD EPYC VM
# (24 GB, Python 3.11.7, numpy 2.4.6, h5py 3.16.0 / HDF5 2.0.0), load average 2.6 and 4.2 from
# other people's work at the start, so expect tens of per cent of spread:
#
#   1. paper.yaml (11 entries, 57.5 s recorded, 87.5 s with rests, 1 kHz), simulated, unpaced:
#      execute() in-process best 2.77-2.95 s, median 2.99-3.09 s -> 28-32x real time;
#      a whole `labrig run` process (start-up, imports) 3.6-5.3 s -> 17-24x real time.
#      Per block (0.1 s) the cost is mostly the HDF5 append+flush (about half), then the
#      virtual bench's physics, then the health checks (about 7 %).
#   2. simulated rig at its highest rate, 100 kHz, one 30 s sine entry:
#      unpaced 1.0-1.7 MS/s (10-17x real time); with --realtime every sample logged
#      (3,000,001 of 3,000,001, contiguous), block lag at most 8-9 ms and not growing:
#      sustained 2 AI channels x 100 kS/s = 200 kS/s acquired, 5 columns logged (4 MB/s).
#   3. runner + run file alone (DAQ blocks handed over at once), 60 s entry at 100 kHz:
#      3.3-3.4 MS/s per channel = 6.6-6.8 MS/s for 2 AI channels, 16.6-17.0 M values/s
#      written (133-136 MB/s), lossless: about 33x the rig's highest rate.
#
"""Runner benchmarks: how fast the simulated campaign runs, and how much the runner can log.

Run from the repository root (about 1 minute; ``--quick``: about 20 s, shorter records):

    .venv/bin/python benchmarks/bench_runner.py [--quick]

Prints a report (stdout); nothing is written to benchmarks/RESULTS.md (owned by the model
benchmarks). What is measured:

1. **The paper's campaign** (``experiments/paper.yaml``: 11 entries, 57.5 s recorded, 87.5 s
   with the 3 s rests, 1 kHz) on the simulated rig, not paced: wall time of
   :func:`labrig.runner.execute` in-process (best and median of repeats; the rig is opened
   each time) and of a whole ``labrig run`` process (interpreter start and imports included),
   and the ratio to real time = protocol duration (with rests) / wall time.
2. **Sustained logging on the simulated rig at the rig's highest rate** (``rate_max_hz``,
   100 kHz): a single long sine entry run with ``--realtime`` pacing. Every block's lag
   (wall clock minus the protocol time of its last sample) is recorded through the progress
   callback: the rate is sustained when the lag stays bounded (it does not grow with time),
   and nothing is lost when the file holds every planned sample with a contiguous time axis.
   Also the unpaced throughput of the same entry (samples/s), which bounds what the simulated
   rig can sustain: here the virtual bench's physics, not the runner, is the limit.
3. **The runner's own logging ceiling**: the same entry with the DAQ's ``play`` replaced by
   one that hands over precomputed blocks at once (no physics). What is left is the runner
   (unit conversion, health checks every second) and the run file (HDF5 append + flush per
   0.1 s block): the rate it can log, i.e. what it could sustain from a real DAQ without the
   DAQ's buffer overflowing. Counted as AI channels x samples/s (the DAQ's AI channels:
   ``gauge`` and ``amp_monitor``) and as values/s written (5 columns: time, command voltage,
   raw gauge, strain, amplifier voltage).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "experiments" / "paper.yaml"


def machine_info() -> dict[str, str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        load = "?"
    try:
        mem = next(
            line.split(":", 1)[1].strip()
            for line in Path("/proc/meminfo").read_text().splitlines()
            if line.startswith("MemTotal")
        )
    except (OSError, StopIteration):
        mem = "?"
    return {
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "memory": mem,
        "load average (1/5/15 min) at start": load,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "h5py / HDF5": f"{h5py.version.version} / {h5py.version.hdf5_version}",
    }


def _labrig_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "labrig"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]


# -- 1. the campaign ------------------------------------------------------------------------------


def bench_campaign(tmp: Path, repeats: int) -> dict:
    from labrig.runner.execute import execute, preflight
    from labrig.store import read_run

    plan, rig_path = preflight(PAPER, None)
    walls = []
    for i in range(repeats):
        out = tmp / f"paper{i}.h5"
        t0 = time.perf_counter()
        o = execute(plan, rig_path, out, seed=1)
        walls.append(time.perf_counter() - t0)
        run = read_run(out, load_data=False)
        assert o.status == "complete" and len(run) == 11, (o.status, o.reason)
    out = tmp / "paper_cli.h5"
    t0 = time.perf_counter()
    proc = subprocess.run(
        [*_labrig_cmd(), "run", str(PAPER), "--out", str(out), "--seed", "1"],
        capture_output=True,
        text=True,
        cwd=tmp,
    )
    cli_wall = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr
    return {
        "entries": len(plan.steps),
        "recorded_s": plan.recorded_duration_s,
        "total_s": plan.total_duration_s,
        "samples": plan.total_samples,
        "walls": walls,
        "cli_wall": cli_wall,
    }


# -- 2. sustained on the simulated rig ------------------------------------------------------------


def _long_protocol(tmp: Path, rate_hz: float, duration_s: float) -> Path:
    p = tmp / f"long_{rate_hz:g}.yaml"
    p.write_text(
        f"name: sustained logging\nrate_hz: {rate_hz:g}\nsteps:\n"
        "  - kind: sine\n    amplitude_V: 50\n    frequency_hz: 20\n"
        f"    duration_s: {duration_s:g}\n"
    )
    return p


def _check_lossless(out: Path, n_expected: int, rate_hz: float) -> dict:
    from labrig.store import read_run

    run = read_run(out)
    (e,) = list(run)
    t = e["time"]
    contiguous = bool(np.allclose(np.diff(t), 1.0 / rate_hz, rtol=0, atol=1e-9))
    finite = all(bool(np.all(np.isfinite(e[c]))) for c in e.channels)
    return {
        "status": run.status,
        "samples": e.n_samples,
        "expected": n_expected,
        "lossless": e.n_samples == n_expected and contiguous and finite,
        "columns": len(e.channels),
        "file_MB": out.stat().st_size / 1e6,
    }


def bench_sustained_sim(tmp: Path, duration_s: float, repeats: int) -> dict:
    from labrig.runner.execute import execute, preflight
    from labrig.runner.rigfile import load_rig

    rate = load_rig(None).limits.rate_max_hz
    proto = _long_protocol(tmp, rate, duration_s)
    plan, rig_path = preflight(proto, None)
    n = plan.steps[0].n_samples

    # unpaced: what the simulated rig can deliver
    walls = []
    for i in range(repeats):
        out = tmp / f"sim_unpaced{i}.h5"
        t0 = time.perf_counter()
        o = execute(plan, rig_path, out, seed=1)
        walls.append(time.perf_counter() - t0)
        assert o.status == "complete", o.reason
        unpaced_check = _check_lossless(out, n, rate)
        out.unlink()

    # paced to the clock: the lag of every block
    lags: list[tuple[float, float]] = []
    start: list[float] = []

    def progress(k, n_steps, name, frac, left):
        now = time.perf_counter()
        if not start:  # the first block's end is due at BLOCK_S
            start.append(now - frac * plan.steps[0].duration_s)
        t_proto = frac * plan.steps[0].duration_s
        lags.append((t_proto, now - start[0] - t_proto))

    out = tmp / "sim_realtime.h5"
    t0 = time.perf_counter()
    o = execute(plan, rig_path, out, seed=1, realtime=True, progress=progress)
    paced = time.perf_counter() - t0
    assert o.status == "complete", o.reason
    lag = np.array([x[1] for x in lags])
    tp = np.array([x[0] for x in lags])
    half = tp >= tp[-1] / 2
    slope = float(np.polyfit(tp[half], lag[half], 1)[0]) if half.sum() > 2 else float("nan")
    return {
        "rate_hz": rate,
        "duration_s": duration_s,
        "unpaced_walls": walls,
        "unpaced_check": unpaced_check,
        "paced_wall": paced,
        "lag_max": float(lag.max()),
        "lag_final": float(lag[-1]),
        "lag_slope": slope,
        "paced_check": _check_lossless(out, n, rate),
    }


# -- 3. the runner's own ceiling ------------------------------------------------------------------


def bench_logging_ceiling(tmp: Path, rate_hz: float, duration_s: float, repeats: int) -> dict:
    import labrig.runner.execute as runner
    from labrig.rig.instruments import AcquiredBlock

    real_open = runner.open_rig

    def open_instant(path=None, seed=None):
        rig = real_open(path, seed)
        gain = float(rig.amplifier.gain)
        k = rig.strain_scale_V_per_ue()

        def play(ao, block_size):
            ao = np.asarray(ao, dtype=float)
            mon = ao * gain * rig.monitor_V_per_V
            gauge = ao * gain * 10.0 * k  # 10 ue/V, as a DAQ would read it
            for s in range(0, ao.size, block_size):
                yield AcquiredBlock(
                    s, {"gauge": gauge[s : s + block_size], "amp_monitor": mon[s : s + block_size]}
                )

        rig.daq.play = play
        return rig

    proto = _long_protocol(tmp, rate_hz, duration_s)
    plan, rig_path = runner.preflight(proto, None)
    n = plan.steps[0].n_samples
    walls = []
    runner.open_rig = open_instant
    try:
        for i in range(repeats):
            out = tmp / f"ceiling{i}.h5"
            t0 = time.perf_counter()
            o = runner.execute(plan, rig_path, out, seed=1)
            walls.append(time.perf_counter() - t0)
            assert o.status == "complete", o.reason
            check = _check_lossless(out, n, rate_hz)
            out.unlink()
    finally:
        runner.open_rig = real_open
    return {
        "rate_hz": rate_hz,
        "duration_s": duration_s,
        "walls": walls,
        "check": check,
        "samples_per_s": n / min(walls),
        "samples_per_s_median": n / statistics.median(walls),
    }


# -- report ---------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter records, one repeat")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    info = machine_info()
    repeats = 1 if args.quick else 3
    sim_s = 5.0 if args.quick else 30.0
    ceiling_s = 20.0 if args.quick else 60.0

    with tempfile.TemporaryDirectory(prefix="bench_runner_") as d:
        tmp = Path(d)
        camp = bench_campaign(tmp, repeats)
        sus = bench_sustained_sim(tmp, sim_s, repeats)
        ceil = bench_logging_ceiling(tmp, sus["rate_hz"], ceiling_s, repeats)

    p = print
    p("# labrig runner benchmarks\n")
    for k, v in info.items():
        p(f"- {k}: {v}")
    p("\n## 1. the paper's campaign (experiments/paper.yaml) on the simulated rig, not paced\n")
    best, med = min(camp["walls"]), statistics.median(camp["walls"])
    p(
        f"- {camp['entries']} entries, {camp['samples']:,} samples, {camp['recorded_s']:.1f} s "
        f"recorded, {camp['total_s']:.1f} s with rests"
    )
    p(
        f"- execute() in-process, {len(camp['walls'])} runs: best {best:.2f} s, median "
        f"{med:.2f} s -> {camp['total_s'] / best:.1f}x / {camp['total_s'] / med:.1f}x real time"
    )
    p(
        f"- `labrig run` process (start-up and imports included): {camp['cli_wall']:.2f} s -> "
        f"{camp['total_s'] / camp['cli_wall']:.1f}x real time"
    )
    p(f"\n## 2. sustained logging on the simulated rig at {sus['rate_hz']:,.0f} Hz\n")
    uc, pc = sus["unpaced_check"], sus["paced_check"]
    ub, um = min(sus["unpaced_walls"]), statistics.median(sus["unpaced_walls"])
    p(
        f"- unpaced, {sus['duration_s']:g} s entry, {len(sus['unpaced_walls'])} runs: best "
        f"{ub:.2f} s, median {um:.2f} s wall -> {uc['samples'] / ub:,.0f} / "
        f"{uc['samples'] / um:,.0f} samples/s ({sus['duration_s'] / ub:.1f}x / "
        f"{sus['duration_s'] / um:.1f}x real time); lossless: {uc['lossless']}"
    )
    p(
        f"- --realtime, {sus['duration_s']:g} s entry: {sus['paced_wall']:.2f} s wall; block lag "
        f"max {sus['lag_max'] * 1e3:.0f} ms, at the end {sus['lag_final'] * 1e3:.0f} ms, trend "
        f"over the second half {sus['lag_slope'] * 1e3:+.1f} ms/s; {pc['samples']:,} of "
        f"{pc['expected']:,} samples, contiguous: {pc['lossless']}"
    )
    ai = 2
    p(
        f"- sustained: {ai} AI channels x {sus['rate_hz']:,.0f} S/s = "
        f"{ai * sus['rate_hz']:,.0f} S/s acquired, {pc['columns']} columns logged "
        f"({pc['columns'] * sus['rate_hz'] * 8 / 1e6:.1f} MB/s), file {pc['file_MB']:.0f} MB"
        if pc["lossless"] and sus["lag_final"] < 0.5
        else "- NOT sustained on the simulated rig at this rate (the lag grew)"
    )
    p("\n## 3. the runner's own logging ceiling (DAQ blocks handed over at once, no physics)\n")
    c = ceil["check"]
    p(
        f"- {ceil['duration_s']:g} s entry at {ceil['rate_hz']:,.0f} Hz, {len(ceil['walls'])} "
        f"runs: best {min(ceil['walls']):.2f} s wall (median "
        f"{ceil['samples_per_s_median']:,.0f} samples/s) "
        f"-> {ceil['samples_per_s']:,.0f} samples/s per channel = "
        f"{ai * ceil['samples_per_s']:,.0f} AI S/s ({ai} channels), "
        f"{c['columns'] * ceil['samples_per_s']:,.0f} values/s written "
        f"({c['columns'] * ceil['samples_per_s'] * 8 / 1e6:.0f} MB/s); "
        f"{ceil['samples_per_s'] / ceil['rate_hz']:.1f}x the rig's highest rate; "
        f"lossless: {c['lossless']} ({c['samples']:,} samples)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
