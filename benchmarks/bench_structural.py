"""CPU cost of each structural candidate of the base model in ``labrig diagnose``.

Run from the repository root (about 10 minutes on a loaded 2-core machine)::

    .venv/bin/python benchmarks/bench_structural.py

``experiments/paper.yaml`` is run on the simulated rig with seed 1 (11 entries, as in
``bench_commands.py``), then ``labrig diagnose --json`` runs as its own process (imports
included) without ``--also`` and with ``--also NAME`` for each structural candidate
(:data:`NAMES`). Reported: user + system CPU seconds of each process (``resource.getrusage``),
the extra CPU of each ``--also`` against the plain diagnosis, whether the candidate was tried,
added or rejected, and a yardstick timed in the same run (``numpy.sort`` of 1e6 floats), with
the machine, date and load. Prints markdown on stdout (copied into ``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_commands import ROOT, cpu_of, yardstick_s

NAMES = (
    "amplifier_bandwidth",
    "mechanical_resonance",
    "negative_field_asymmetry",
    "rate_hysteresis",
    "sensor_drift",
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/labrig-bench-structural")
    ap.add_argument("--names", nargs="*", default=list(NAMES))
    args = ap.parse_args()
    labrig = shutil.which("labrig", path=str(Path(sys.executable).parent)) or "labrig"
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    paper = work / "paper1.h5"
    if not paper.exists():
        run = [labrig, "run", str(ROOT / "experiments" / "paper.yaml"), "--seed", "1"]
        subprocess.run([*run, "--out", str(paper)], check=True, capture_output=True)
    y0 = yardstick_s()
    load0 = os.getloadavg()[0]
    rows = []
    base_cpu, out = cpu_of([labrig, "diagnose", str(paper), "--json"], work)
    base = json.loads(out)
    rows.append(("(none)", base_cpu, None, base))
    for name in args.names:
        cpu, out = cpu_of([labrig, "diagnose", str(paper), "--json", "--also", name], work)
        rows.append((name, cpu, cpu - base_cpu, json.loads(out)))
    y1 = yardstick_s()
    print(
        f"`labrig diagnose --json` on experiments/paper.yaml (seed 1), "
        f"{platform.machine()} {os.cpu_count()} cores, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, "
        f"load {load0:.1f} -> {os.getloadavg()[0]:.1f}; yardstick (np.sort 1e6) "
        f"{1e3 * y0:.1f} / {1e3 * y1:.1f} ms\n"
    )
    print("| `--also` | CPU s | extra CPU s | extra / yardstick | candidate | added |")
    print("|---|---|---|---|---|---|")
    for name, cpu, extra, doc in rows:
        cands = {c["effect"]: c for c in doc["candidates"]}
        added = [e["effect"] for e in doc["effects_added"]]
        tried = "tried" if name in cands else ("-" if name == "(none)" else "not tried")
        ex = "" if extra is None else f"{extra:+.1f}"
        ratio = "" if extra is None else f"{extra / y0:.0f}"
        print(f"| {name} | {cpu:.1f} | {ex} | {ratio} | {tried} | {', '.join(added) or '-'} |")


if __name__ == "__main__":
    main()
