"""Catalogue benchmark: ``labrig runs`` over folders of run files, in CPU seconds.

Run from the repository root (about 15-25 minutes on 2 shared cores; ``--quick``: 400 small and
100 paper-campaign files, a few minutes):

    .venv/bin/python benchmarks/bench_catalogue.py [--files N] [--paper-files M] [--quick]

Prints a report (stdout); the figures are copied by hand into benchmarks/RESULTS.md and
docs/catalogue.md. The machine is shared and noisy, so every figure is CPU time (the process's
and its children's, ``getrusage``), with a yardstick timed in the same run: the CPU time of
``numpy.sort`` of 1e6 random floats (median of 9), and each figure's ratio to it. Wall time is
given beside, for what a person waits.

1. **Per file, in-process** (a paper-campaign file: ``labrig run experiments/paper.yaml --seed
   1``, 11 entries, 2.6 MB): CPU of the record the listing stores, read three ways: from the
   summary the writer leaves (today's listing), in full without the seal check (today's
   fallback: no summary), and as the listing read it before (the store's reader with every
   seal checked, then the generic metadata walk).
2. **Paper-campaign folder**: ``M`` copies of that file (distinct files); one ``labrig runs``
   process for the first listing (reads every file, builds the index) and one again (all from
   the index): the first listing's CPU per file, with and without the again-listing's cost
   (interpreter start, imports, the index) taken off. Goal: <= 10 ms per file.
3. **Many small files**: ``VARIANTS`` distinct run files written with the store's writer (2
   entries of 200 samples at 1 kHz, the simulated rig's instrument description, protocol,
   sample, operator, amplitudes, frequencies and start date varied; NXsample/NXuser groups in
   the layout docs/catalogue.md describes, sealed as the writer seals), copied to reach ``N``
   files (distinct files, not links); each a whole ``labrig runs`` process (stdout to
   /dev/null): the first listing; the listing again, unfiltered; a filtered query, the issue's
   example ``--where sample=P-888#3 --where protocol~sweep --where since=2026-03-01 --where
   amplitude_V=100 --where frequency_hz<=20`` (median and worst of 5; goal under 2 s); a query
   on an instrument key (``--where identity~DH3840``: the index's second part is read);
   ``--json`` of everything; after 10 files changed (their modification time moved): the
   listing reads 10 files.
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
from yardstick import yardstick_s

from labrig.catalogue.read import file_record_here, read_metadata_here
from labrig.store import RunWriter
from labrig.store.parse import read_run_here
from labrig.store.writer import seal_all

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "experiments" / "paper.yaml"

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


def timed(args: list[str], code: Path | None = None) -> tuple[float, float]:
    """Wall and CPU seconds of one ``labrig runs`` process (stdout discarded); ``code``: a
    checkout of labrig to run instead of this one (its ``labrig`` package first on the path)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "PYTHONPATH": str(code)} if code is not None else None
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "labrig.cli", "runs", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=True,
        env=env,
        cwd=code,  # python -m puts the working folder first on the path: the checkout's own
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


def cpu_per_call(fn: Any, repeats: int) -> float:
    """CPU seconds per call of ``fn()`` (after one call that warms the caches)."""
    fn()
    t0 = time.process_time()
    for _ in range(repeats):
        fn()
    return (time.process_time() - t0) / repeats


def paper_file(folder: Path) -> Path:
    """The paper's campaign on the simulated rig, seed 1 (``labrig run``, a process)."""
    out = folder / "paper.h5"
    subprocess.run(
        [str(Path(sys.executable).parent / "labrig"), "run", str(PAPER), "--seed", "1",
         "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, cwd=ROOT,
    )  # fmt: skip
    return out


def per_file(path: Path) -> dict[str, float]:
    """CPU seconds of one file's record, three ways (module docstring, 1.)."""

    def before() -> None:
        read_run_here(path, load_data=False)  # every seal checked
        read_metadata_here(path)

    return {
        "summary": cpu_per_call(lambda: file_record_here(path), 40),
        "full": cpu_per_call(lambda: file_record_here(path, full=True), 5),
        "before": cpu_per_call(before, 3),
    }


def paper_folder(folder: Path, source: Path, m: int, code: Path | None = None) -> dict[str, Any]:
    """The first listing and the listing again of ``m`` copies of ``source`` (``code``: with
    another checkout of labrig, e.g. the one before this change)."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(m):
        shutil.copyfile(source, folder / f"paper{i:05d}.h5")
    out: dict[str, Any] = {"load_before": os.getloadavg(), "m": m}
    out["first"] = timed([str(folder)], code)
    out["again"] = timed([str(folder)], code)
    out["load_after"] = os.getloadavg()
    shutil.rmtree(folder)
    return out


def report(n: int, size: int, m: dict[str, Any], index_bytes: int, paper: dict[str, Any]) -> str:
    q_wall = [w for w, _ in m["query"]]
    y = paper["yardstick_s"]

    def row(what: str, wc: tuple[float, float]) -> str:
        return f"| {what} | {wc[0]:.2f} s | {wc[1]:.2f} s | {wc[1] / y:.0f} |"

    first = m["first"]
    pf, pm = paper["per_file"], paper["m"]
    p_first, p_again = paper["folder"]["first"], paper["folder"]["again"]
    per = p_first[1] / pm
    per_listing = (p_first[1] - p_again[1]) / pm
    before_rows = []
    if "before" in paper:
        b, bm = paper["before"], paper["before"]["m"]
        before_rows = [
            row(
                f"before ({paper['before_code']}, {bm} copies): first listing "
                f"({b['first'][1] / bm * 1e3:.0f} ms CPU per file; "
                f"{(b['first'][1] - b['again'][1]) / bm * 1e3:.0f} ms without the "
                "again-listing's cost)",
                b["first"],
            ),
            row("before: listing again", b["again"]),
        ]
    machine = platform.processor() or platform.machine()
    return "\n".join(
        [
            f"labrig runs ({datetime.now():%Y-%m-%d %H:%M}, {machine}, "
            f"{os.cpu_count()} cores, Python {platform.python_version()}, "
            f"h5py {h5py.version.version} / HDF5 {h5py.version.hdf5_version}); yardstick "
            f"numpy.sort of 1e6 floats: {y * 1e3:.1f} ms CPU",
            "",
            f"One paper-campaign file ({paper['size'] / 1e6:.1f} MB, 11 entries), its record, "
            "CPU per file in-process:",
            "",
            "| read | CPU per file | x yardstick |",
            "|---|---|---|",
            f"| from its summary (the listing now) | {pf['summary'] * 1e3:.2f} ms | "
            f"{pf['summary'] / y:.2f} |",
            f"| in full, seals not checked (the listing now, a file without a summary) | "
            f"{pf['full'] * 1e3:.1f} ms | {pf['full'] / y:.1f} |",
            f"| the store's reader with every seal, then the metadata walk (the listing before) "
            f"| {pf['before'] * 1e3:.1f} ms | {pf['before'] / y:.1f} |",
            "",
            f"{pm} copies of it, whole `labrig runs` processes (load average "
            f"{paper['folder']['load_before'][0]:.1f} before, "
            f"{paper['folder']['load_after'][0]:.1f} after):",
            "",
            "| what | wall | CPU | CPU / yardstick |",
            "|---|---|---|---|",
            row(
                f"first listing ({per * 1e3:.1f} ms CPU per file; {per_listing * 1e3:.1f} ms "
                "without the again-listing's cost)",
                p_first,
            ),
            row("listing again (all from the index)", p_again),
            *before_rows,
            "",
            f"{n} small run files of {size / 1024:.0f} kB (load average "
            f"{m['load_before'][0]:.1f} before, {m['load_after'][0]:.1f} after):",
            "",
            "| what | wall | CPU | CPU / yardstick |",
            "|---|---|---|---|",
            row(
                f"first listing (reads every file, builds the index: {first[1] / n * 1e3:.1f} "
                "ms CPU per file)",
                first,
            ),
            row("listing again, unfiltered (all from the index)", m["again"]),
            f"| filtered query (the issue's example), median / worst of 5 | "
            f"{statistics.median(q_wall):.2f} / {max(q_wall):.2f} s | "
            f"{statistics.median(c for _, c in m['query']):.2f} s | "
            f"{statistics.median(c for _, c in m['query']) / y:.0f} |",
            row("query on an instrument key (`identity~DH3840`)", m["instrument"]),
            row("`--json` of every run", m["json"]),
            row("filtered query after 10 files changed (reads those 10)", m["changed"]),
            "",
            f"index file: {index_bytes / 1e6:.1f} MB",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=10_000, help="small files (3.)")
    ap.add_argument("--paper-files", type=int, default=1000, help="paper-campaign files (2.)")
    ap.add_argument("--dir", type=Path, default=None, help="Folder for the files (kept).")
    ap.add_argument("--quick", action="store_true", help="400 small, 100 paper files.")
    ap.add_argument(
        "--before",
        type=Path,
        default=None,
        metavar="CHECKOUT",
        help="Also list paper-campaign copies with this checkout of labrig (the code before).",
    )
    ap.add_argument("--before-files", type=int, default=100, help="copies for --before")
    args = ap.parse_args()
    n = 400 if args.quick else args.files
    m_paper = 100 if args.quick else args.paper_files
    with tempfile.TemporaryDirectory() as tmp:
        base = args.dir or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        source = paper_file(base)
        paper: dict[str, Any] = {"size": source.stat().st_size, "m": m_paper}
        paper["yardstick_s"] = yardstick_s(9, statistics.median)
        paper["per_file"] = per_file(source)
        paper["folder"] = paper_folder(base / "paper", source, m_paper)
        if args.before is not None:
            head = subprocess.run(
                ["git", "-C", str(args.before), "log", "-1", "--format=%h"],
                capture_output=True, text=True, check=False,
            ).stdout.strip()  # fmt: skip
            paper["before_code"] = f"checkout {head or args.before}"
            paper["before"] = paper_folder(base / "before", source, args.before_files, args.before)
        print(f"paper part: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        folder = base / "runs"
        t0 = time.perf_counter()
        size = make_folder(folder, n)
        print(f"wrote {n} files in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        m = measure(folder)
        index = folder / ".labrig-index.sqlite"
        paper["yardstick_after_s"] = yardstick_s(9, statistics.median)
        print(report(n, size, m, index.stat().st_size, paper))
        print(
            f"\nyardstick again at the end: {paper['yardstick_after_s'] * 1e3:.1f} ms CPU",
        )


if __name__ == "__main__":
    main()
