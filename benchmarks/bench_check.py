"""``labrig check`` of long repeating entries at the highest rate, in CPU seconds.

Run from the repository root (about 10 s; ``--full`` adds the scan of every fine-grid point,
the preflight as it was before the shortcut over repeating pieces, and compares the figures:
about 3 minutes per protocol on a shared 2-core machine):

    .venv/bin/python benchmarks/bench_check.py [--full] [--repeats N]

Prints a report (stdout); nothing is written to benchmarks/RESULTS.md. Every figure is CPU time
(``time.process_time`` in-process, ``getrusage`` of the children for the command), each with the
yardstick timed right after it (``numpy.sort`` of 1e6 floats, benchmarks/yardstick.py) and its
ratio to it. The protocols, written to a temporary folder:

1. **sweep**: the defect's case, a ``kind: sweep`` of 3 amplitudes (20, 50, 80 V) x 5
   frequencies (1, 5, 10, 20, 40 Hz), ``min_duration_s: 499``, ``rate_hz: 100000``: 15 sines
   of 499 s, each ``2e8`` points on the preflight's grid 4 times finer than the output; their
   grids repeat every period (whole fine points a period);
2. **sweep, two decimals**: the same with 1.37, 5.13, 12.71, 23.49, 41.07 Hz: grids that repeat
   only every 100 s, measured by the runs of points whose phases leave no gap wider than the
   sinusoid's allowance;
3. **mixed**: 400 s each of an offset sine at 23.49 Hz, triangles at 20 Hz and 37.77 Hz (a grid
   that repeats every 4e7 points, a fifth of the entry: the triangle takes no shortcut but
   exact repeats), a hold, and a sine of 1500.5 cycles at 3.3 Hz (a partial last cycle).

For each: ``check_protocol`` in-process (validation, expansion, preflight), and a whole
``labrig check`` process (interpreter start and imports included); with ``--full``, the sum of
``measure(step, limits, full=True)`` over the entries, and the largest relative difference of
each figure between the two (the voltages relative to the amplitude): the shortcut allows itself
1e-10; the whole scan's own rounding of late times moves its peak current by up to about 2e-8
and its window means by up to about 1e-9 on 499 s entries.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from yardstick import yardstick_s

from labrig.protocol.check import check_protocol, load_plan
from labrig.protocol.preflight import measure
from labrig.rig.limits import RigLimits


def long_sweep(name: str, frequencies_hz: str) -> str:
    """A protocol of 15 sines of 499 s at 100 kHz: 20, 50, 80 V at ``frequencies_hz``."""
    return f"""name: {name}
rate_hz: 100000
steps:
  - kind: sweep
    amplitudes_V: [20, 50, 80]
    frequencies_hz: [{frequencies_hz}]
    cycles: 1
    min_duration_s: 499
"""


PROTOCOLS = {
    "sweep": long_sweep("long sweep", "1, 5, 10, 20, 40"),
    "sweep, two decimals": long_sweep(
        "long sweep, two decimals", "1.37, 5.13, 12.71, 23.49, 41.07"
    ),
    "mixed": """name: long mixed
rate_hz: 100000
steps:
  - {kind: offset_sine, offset_V: 30, amplitude_V: 40, frequency_hz: 23.49, duration_s: 400}
  - {kind: triangle, offset_V: 30, amplitude_V: 40, frequency_hz: 20, duration_s: 400}
  - {kind: triangle, offset_V: 30, amplitude_V: 40, frequency_hz: 37.77, duration_s: 400}
  - {kind: hold, voltage_V: 30, duration_s: 400}
  - {kind: sine, amplitude_V: 60, frequency_hz: 3.3, cycles: 1500.5}
""",
}


def cpu_of(work: Callable[[], object]) -> float:
    """CPU seconds of ``work()`` in this process."""
    t0 = time.process_time()
    work()
    return time.process_time() - t0


def children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def command_cpu(path: Path) -> float:
    """CPU seconds of a whole ``labrig check PATH`` process."""
    exe = Path(sys.executable).parent / "labrig"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]
    before = children_cpu()
    proc = subprocess.run([*cmd, "check", str(path)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return children_cpu() - before


def timed(cpu_s: Callable[[], float], repeats: int) -> tuple[float, float]:
    """``(median CPU s, median CPU / yardstick)`` of ``cpu_s()`` (the CPU seconds of one run)
    over ``repeats``, a yardstick timed after each."""
    cpus, ratios = [], []
    for _ in range(repeats):
        cpu = cpu_s()
        y = yardstick_s()
        cpus.append(cpu)
        ratios.append(cpu / y)
    return statistics.median(cpus), statistics.median(ratios)


def differences(path: Path, limits: RigLimits) -> tuple[float, dict[str, float]]:
    """CPU of the full scans of every entry, and the largest relative difference of each figure
    between the shortcut and them."""
    plan = load_plan(path)
    worst = {"v_min_V": 0.0, "v_max_V": 0.0, "peak_current_A": 0.0, "mean_current_A": 0.0}
    cpu = 0.0
    for s in plan.steps:
        t0 = time.process_time()
        full = measure(s, limits, full=True)
        cpu += time.process_time() - t0
        short = measure(s, limits)
        for key in worst:
            scale = (s.amplitude_V or 1.0) if key.startswith("v_") else abs(getattr(full, key))
            d = abs(getattr(short, key) - getattr(full, key)) / (scale or 1.0)
            worst[key] = max(worst[key], d)
    return cpu, worst


def report_case(name: str, path: Path, repeats: int, full: bool) -> None:
    lim = RigLimits()
    plan = load_plan(path)
    points = sum((s.n_samples - 1) * 4 + 1 for s in plan.steps)
    print(f"\n## {name}: {len(plan.steps)} entries, {plan.recorded_duration_s:.0f} s recorded, "
          f"{points:.3g} fine-grid points\n")  # fmt: skip
    cpu, ratio = timed(lambda: cpu_of(lambda: check_protocol(path, lim)), repeats)
    print(f"- check_protocol in-process: {cpu:.2f} s CPU, {ratio:.0f} x yardstick")
    cpu, ratio = timed(lambda: command_cpu(path), repeats)
    print(f"- `labrig check` process: {cpu:.2f} s CPU, {ratio:.0f} x yardstick")
    if full:
        y0 = yardstick_s()
        cpu, worst = differences(path, lim)
        y = statistics.median([y0, yardstick_s()])
        print(f"- full scan of every point (before): {cpu:.1f} s CPU, {cpu / y:.0f} x yardstick")
        print("- largest relative difference, shortcut vs full scan: " + ", ".join(
            f"{k} {v:.1e}" for k, v in worst.items()))  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--full", action="store_true", help="also scan every point (minutes)")
    ap.add_argument("--repeats", type=int, default=3, help="timings per figure (median)")
    args = ap.parse_args(argv)
    print("# labrig check of long repeating entries\n")
    print(f"- load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"- yardstick: {yardstick_s() * 1e3:.2f} ms CPU (numpy.sort of 1e6 floats)")
    with tempfile.TemporaryDirectory(prefix="bench_check_") as d:
        for i, (name, text) in enumerate(PROTOCOLS.items()):
            path = Path(d) / f"p{i}.yaml"
            path.write_text(text)
            report_case(name, path, args.repeats, args.full)
    return 0


if __name__ == "__main__":
    sys.exit(main())
