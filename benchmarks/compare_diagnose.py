"""Does a faster diagnosis give the same result? ``diagnose --json`` of two installations, diffed.

Run from the repository root::

    .venv/bin/python benchmarks/compare_diagnose.py --reference /path/to/other/.venv/bin/labrig \\
        --work /tmp/compare RUN.h5 [RUN.h5 ...]

For each run file, ``labrig diagnose RUN --json --workers 1`` runs with this checkout's
``labrig`` and with the reference installation (its document is kept in ``--work`` as
``NAME.reference.json`` and reused by later runs unless ``--fresh``), and the two documents are
compared field by field: the same keys, the same list lengths, every string identical, every
number within ``--rtol`` relative (default 1e-6; ``|a - b| <= rtol * max(|a|, |b|)``, or both
below ``--atol`` = 1e-12 in absolute value). The CPU seconds of each process (user + system of
the process and its children, ``resource.getrusage``) are printed beside a yardstick timed in
this process (``numpy.sort`` of 1e6 floats) and the load average.

Exit status: 0 when every document matches, 1 otherwise (each difference printed with its path
in the document).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from bench_commands import yardstick_s


def run_json(labrig: str, path: Path, extra: list[str]) -> tuple[float, Any]:
    """CPU seconds (process and children) and the parsed ``--json`` document of one diagnosis."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = [labrig, "diagnose", str(path), "--json", "--workers", "1", *extra]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {res.returncode}: {res.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, json.loads(res.stdout)


def differences(a: Any, b: Any, rtol: float, atol: float, path: str = "$") -> list[str]:
    """Every place where documents ``a`` and ``b`` differ (numbers beyond the tolerances)."""
    num = (int, float)
    if isinstance(a, bool) or isinstance(b, bool):
        return [] if a == b else [f"{path}: {a!r} != {b!r}"]
    if isinstance(a, num) and isinstance(b, num):
        fa, fb = float(a), float(b)
        if fa == fb or (abs(fa) <= atol and abs(fb) <= atol):
            return []
        if np.isfinite(fa) and np.isfinite(fb) and abs(fa - fb) <= rtol * max(abs(fa), abs(fb)):
            return []
        rel = abs(fa - fb) / max(abs(fa), abs(fb), 1e-300)
        return [f"{path}: {a!r} != {b!r} (relative {rel:.2e})"]
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}: key {k!r} only in one" for k in sorted(set(a) ^ set(b))]
        for k in a:
            if k in b:
                out += differences(a[k], b[k], rtol, atol, f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} items != {len(b)}"]
        out = []
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            out += differences(x, y, rtol, atol, f"{path}[{i}]")
        return out
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run files to diagnose")
    ap.add_argument("--reference", required=True, help="the reference installation's labrig")
    ap.add_argument("--work", type=Path, default=Path("/tmp/labrig-compare-diagnose"))
    ap.add_argument("--rtol", type=float, default=1e-6)
    ap.add_argument("--atol", type=float, default=1e-12)
    ap.add_argument("--fresh", action="store_true", help="rerun the reference even if kept")
    ap.add_argument("--extra", default="", help="more diagnose arguments, space-separated")
    args = ap.parse_args()
    this = shutil.which("labrig", path=str(Path(sys.executable).parent)) or "labrig"
    extra = args.extra.split()
    args.work.mkdir(parents=True, exist_ok=True)
    load0, y0 = os.getloadavg(), yardstick_s()
    rows, bad = [], 0
    for run in args.runs:
        tag = "_".join([run.stem, *[e.strip("-") for e in extra]])
        kept = args.work / f"{tag}.reference.json"
        if kept.exists() and not args.fresh:
            ref_cpu, ref = None, json.loads(kept.read_text())
        else:
            ref_cpu, ref = run_json(args.reference, run, extra)
            kept.write_text(json.dumps(ref, indent=1))
        cpu, doc = run_json(this, run, extra)
        (args.work / f"{tag}.this.json").write_text(json.dumps(doc, indent=1))
        diff = differences(doc, ref, args.rtol, args.atol)
        bad += bool(diff)
        for d in diff:
            print(f"  {run.name}: {d}", file=sys.stderr)
        same = "identical" if doc == ref else "identical to the tolerance"
        rows.append((run.name, cpu, ref_cpu, same if not diff else f"{len(diff)} differences"))
        print(f"  {run.name}: {cpu:.2f} s, {rows[-1][3]}", file=sys.stderr, flush=True)
    load1, y1 = os.getloadavg(), yardstick_s()
    print(
        f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores; load {load0[0]:.2f} -> {load1[0]:.2f}; yardstick "
        f"{1e3 * y0:.1f} / {1e3 * y1:.1f} ms CPU; tolerance {args.rtol:g} relative\n"
    )
    print("| run | this CPU s | reference CPU s | against the reference |")
    print("|---|---|---|---|")
    for name, cpu, ref_cpu, verdict in rows:
        ref_s = f"{ref_cpu:.2f}" if ref_cpu is not None else "(kept)"
        print(f"| {name} | {cpu:.2f} | {ref_s} | {verdict} |")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
