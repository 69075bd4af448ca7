"""Catalogue benchmark: ``labrig runs`` over a folder of many small run files.

Run from the repository root (``--files 10000``: about 10-20 minutes, most of it the first
listing; ``--quick``: 500 files, about a minute):

    .venv/bin/python benchmarks/bench_catalogue.py [--files N] [--dir DIR] [--quick]

Prints a report (stdout); the figures are copied by hand into benchmarks/RESULTS.md and
docs/catalogue.md. What is measured, each as a whole ``labrig runs`` process (interpreter start
and imports included; stdout to /dev/null), wall time and CPU time of the process:

1. The files: ``VARIANTS`` distinct run files written with the store's writer (2 entries of
   200 samples at 1 kHz, the simulated rig's instrument description, protocol, sample, operator,
   amplitudes, frequencies and start date varied; NXsample/NXuser groups in the layout
   docs/catalogue.md describes, sealed as the writer seals), each copied to reach ``N`` files
   (distinct files, not links).
2. The first listing, which reads every file (the index is built).
3. The listing again (everything from the index), unfiltered: ``N`` lines printed.
4. A filtered query, the issue's example: ``--where sample=P-888#3 --where protocol~sweep
   --where since=2026-03-01 --where amplitude_V=100 --where frequency_hz<=20`` (median and
   worst of 5). Goal: under 2 s.
5. A query on an instrument key (``--where identity~DH3840``: the index's second part is read).
6. ``--json`` of everything.
7. After 10 files changed (their modification time moved): the listing reads 10 files.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labrig.store import RunWriter
from labrig.store.writer import seal_all

VARIANTS = 40
PROTOCOLS = ("paper sine sweep", "sweep", "creep hold", "vanishing check")
SAMPLES = ("P-888 #1", "P-888 #2", "P-888 #3", "P-888 #4")
OPERATORS = ("alice", "bob", "carol")
FREQUENCIES = (1.0, 5.0, 10.0, 20.0, 40.0)
EXAMPLE_QUERY = [
    "sample=P-888#3",
    "protocol~sweep",
    "since=2026-03-01",
    "amplitude_V=100",
    "frequency_hz<=20",
]
#: a simulated-rig instrument description, as ``labrig run`` records it (shortened: the
#: virtual bench's physics settings left out)
INSTRUMENT = {
    "name": "sim",
    "simulated": True,
    "limits": {"v_min_V": -20.0, "v_max_V": 100.0, "capacitance_F": 6e-6, "i_peak_A": 0.18},
    "daq": {"driver": "sim_daq", "identity": "labrig simulated DAQ", "rate_hz": 1000.0},
    "amplifier": {"driver": "pi_e503", "identity": "E-503 (simulated)", "gain_V_per_V": 10.0},
    "conditioner": {
        "driver": "strain_modbus",
        "identity": "DH3840-SIM, SN 3840001, firmware 1.00",
        "sensitivity_mV_per_ue": 1.085,
    },
}


def write_variant(path: Path, k: int) -> None:
    """Variant ``k``: two sine entries of 200 samples, metadata varied with ``k``."""
    protocol = PROTOCOLS[k % len(PROTOCOLS)]
    amplitude = (50.0, 100.0)[(k // 4) % 2]
    f1, f2 = FREQUENCIES[k % 5], FREQUENCIES[(k + 2) % 5]
    with RunWriter(path, f"name: {protocol}\n", "", INSTRUMENT, k, protocol_name=protocol) as w:
        for f in (f1, f2):
            step = {"kind": "sine", "amplitude_V": amplitude, "frequency_hz": f, "cycles": 1.0}
            e = w.begin_entry(
                f"sine_{amplitude:g}V_{f:g}Hz", step, 1000.0, ["command_voltage", "strain"]
            )
            t = np.arange(200) / 1000.0
            v = amplitude / 2 * (1 - np.cos(2 * np.pi * f * t))
            e.append({"command_voltage": v, "strain": 11.5 * v})
            e.finish()
    with h5py.File(path, "a") as h:
        h["run/start_time"][()] = f"2026-{1 + k % 12:02d}-{1 + k % 28:02d}T10:00:00.000+01:00"
        for name in list(h):
            if name == "run":
                continue
            for group, nx_class, value in (
                ("sample", "NXsample", SAMPLES[(k // 3) % len(SAMPLES)]),
                ("user", "NXuser", OPERATORS[k % len(OPERATORS)]),
            ):
                g = h[name].create_group(group)
                g.attrs["NX_class"] = nx_class
                g["name"] = value
        seal_all(h)


def make_folder(folder: Path, n: int) -> int:
    """``n`` run files in ``folder``; returns the size of one in bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    variants = [folder / f"variant{k:02d}.h5" for k in range(VARIANTS)]
    for k, p in enumerate(variants):
        write_variant(p, k)
    for i in range(VARIANTS, n):
        shutil.copyfile(variants[i % VARIANTS], folder / f"run{i:05d}.h5")
    return variants[0].stat().st_size


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one ``labrig runs`` process (stdout discarded)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        [str(Path(sys.executable).parent / "labrig"), "runs", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=True,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def where(*exprs: str) -> list[str]:
    return [x for e in exprs for x in ("--where", e)]


def measure(folder: Path) -> dict[str, Any]:
    out: dict[str, Any] = {"load_before": os.getloadavg()}
    out["first"] = timed([str(folder)])
    out["again"] = timed([str(folder)])
    query = [timed([str(folder), *where(*EXAMPLE_QUERY)]) for _ in range(5)]
    out["query"] = query
    out["instrument"] = timed([str(folder), *where("identity~DH3840")])
    out["json"] = timed([str(folder), "--json"])
    for p in sorted(folder.glob("run*.h5"))[:10]:
        st = p.stat()
        os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    out["changed"] = timed([str(folder), *where(*EXAMPLE_QUERY)])
    out["load_after"] = os.getloadavg()
    return out


def report(n: int, size: int, m: dict[str, Any], index_bytes: int) -> str:
    q_wall = [w for w, _ in m["query"]]

    def row(what: str, wc: tuple[float, float]) -> str:
        return f"| {what} | {wc[0]:.2f} s | {wc[1]:.2f} s |"

    first = m["first"]
    return "\n".join(
        [
            f"labrig runs over {n} run files of {size / 1024:.0f} kB "
            f"({datetime.now():%Y-%m-%d %H:%M}, {platform.processor() or platform.machine()}, "
            f"{os.cpu_count()} cores, Python {platform.python_version()}; load average "
            f"{m['load_before'][0]:.1f} before, {m['load_after'][0]:.1f} after)",
            "",
            "| what | wall | CPU |",
            "|---|---|---|",
            row(
                f"first listing (reads every file, builds the index: {first[0] / n * 1e3:.1f} "
                "ms per file)",
                first,
            ),
            row("listing again, unfiltered (all from the index)", m["again"]),
            f"| filtered query (the issue's example), median / worst of 5 | "
            f"{statistics.median(q_wall):.2f} / {max(q_wall):.2f} s | "
            f"{statistics.median(c for _, c in m['query']):.2f} s |",
            row("query on an instrument key (`identity~DH3840`)", m["instrument"]),
            row("`--json` of every run", m["json"]),
            row("filtered query after 10 files changed (reads those 10)", m["changed"]),
            "",
            f"index file: {index_bytes / 1e6:.1f} MB",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=10_000)
    ap.add_argument("--dir", type=Path, default=None, help="Folder for the files (kept).")
    ap.add_argument("--quick", action="store_true", help="500 files.")
    args = ap.parse_args()
    n = 500 if args.quick else args.files
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.dir or Path(tmp) / "runs"
        t0 = time.perf_counter()
        size = make_folder(folder, n)
        print(f"wrote {n} files in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        m = measure(folder)
        index = folder / ".labrig-index.sqlite"
        print(report(n, size, m, index.stat().st_size))


if __name__ == "__main__":
    main()
