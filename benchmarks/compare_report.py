"""Does a faster report give the same report? ``labrig report --json --out`` of two installations.

Run from the repository root::

    .venv/bin/python benchmarks/compare_report.py --reference /path/to/other/.venv/bin/labrig \\
        --work /tmp/compare-report [--repeats 2] RUN.h5 [RUN.h5 ...]

For each run file, ``labrig report RUN --json --out NAME.html --overwrite`` runs with this
checkout's ``labrig`` and with the reference installation, interleaved (reference, this,
reference, this ... for ``--repeats`` rounds), and the two outputs of the last round are
compared:

- **the metrics** (``--json``): field by field, every string identical, every number within
  ``--rtol`` relative (default 0: equal; ``|a - b| <= rtol * max(|a|, |b|)``), as
  ``compare_diagnose.py`` compares diagnoses;
- **the page's text**: the HTML with each embedded figure replaced by its index, and the three
  values that change from one run to the next masked (the fit's elapsed time in "fitted now
  (METHOD, T s)" and in "fit time", and "report generated"), compared character for character;
  the first differing lines are printed;
- **the figures**: each embedded PNG decoded (Pillow, which matplotlib installs) to RGBA
  pixels, and compared pixel for pixel (the bytes may differ with the encoder's settings).

The CPU seconds of each process (user + system of the process and its children, the run file's
checked read included; ``resource.getrusage``) are printed per round, with the yardstick
(``numpy.sort`` of 1e6 floats, CPU, timed in this process before and after) and the load
average; the table gives the median of the rounds.

Exit status: 0 when every run's metrics, text and figures match, 1 otherwise.
"""

from __future__ import annotations

import argparse
import base64
import difflib
import io
import json
import os
import platform
import re
import resource
import shutil
import statistics
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from bench_commands import yardstick_s
from compare_diagnose import differences

PNG = re.compile(r"data:image/png;base64,([A-Za-z0-9+/=]+)")
#: what changes from one run of the same report to the next (masked before comparing)
VOLATILE = (
    re.compile(r"(fitted now \([a-z_]+, )[0-9.]+( s\))"),
    re.compile(r"(<dt>fit time</dt><dd>)[0-9.]+( s)"),
    re.compile(r"(<dt>report generated</dt><dd>)[^<]*(<)"),
)


def run_report(labrig: str, path: Path, html: Path) -> tuple[float, Any, str]:
    """CPU seconds (process and children), the ``--json`` document and the page."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = [labrig, "report", str(path), "--json", "--out", str(html), "--overwrite"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=3600, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {res.returncode}: {res.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, json.loads(res.stdout), html.read_text(encoding="utf-8")


def page_text(page: str) -> str:
    """The page with its figures numbered instead of embedded and the volatile values masked,
    one tag per line (for a readable diff)."""
    count = iter(range(10**6))
    text = PNG.sub(lambda _: f"FIGURE-{next(count)}", page)
    for pat in VOLATILE:
        text = pat.sub(r"\1*\2", text)
    return text.replace("><", ">\n<")


def figures(page: str) -> list[np.ndarray]:
    """Every embedded PNG of the page as an RGBA pixel array."""
    from PIL import Image

    out = []
    for b64 in PNG.findall(page):
        with Image.open(io.BytesIO(base64.b64decode(b64))) as im:
            out.append(np.asarray(im.convert("RGBA")))
    return out


def compare_pages(this: str, ref: str) -> list[str]:
    """What differs between two pages: text lines (the first 20) and figures."""
    out = []
    a, b = page_text(this).splitlines(), page_text(ref).splitlines()
    if a != b:
        diff = [d for d in difflib.unified_diff(b, a, "reference", "this", n=0, lineterm="")]
        out += [f"text: {d[:300]}" for d in diff[2:22]]
    fa, fb = figures(this), figures(ref)
    if len(fa) != len(fb):
        out.append(f"figures: {len(fa)} != {len(fb)}")
    for i, (x, y) in enumerate(zip(fa, fb, strict=False)):
        if x.shape != y.shape:
            out.append(f"figure {i}: size {x.shape} != {y.shape}")
        elif not np.array_equal(x, y):
            n = int(np.count_nonzero(np.any(x != y, axis=-1)))
            out.append(f"figure {i}: {n} pixels differ")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run files to report")
    ap.add_argument("--reference", required=True, help="the reference installation's labrig")
    ap.add_argument("--work", type=Path, default=Path("/tmp/labrig-compare-report"))
    ap.add_argument("--repeats", type=int, default=1, help="interleaved rounds per run file")
    ap.add_argument("--rtol", type=float, default=0.0)
    ap.add_argument("--atol", type=float, default=0.0)
    args = ap.parse_args()
    this = shutil.which("labrig", path=str(Path(sys.executable).parent)) or "labrig"
    args.work.mkdir(parents=True, exist_ok=True)
    load0, y0 = os.getloadavg(), yardstick_s()
    rows, bad = [], 0
    for run in args.runs:
        cpu_ref, cpu_this = [], []
        for k in range(args.repeats):
            c, ref, ref_page = run_report(args.reference, run, args.work / f"{run.stem}.ref.html")
            cpu_ref.append(c)
            c, doc, page = run_report(this, run, args.work / f"{run.stem}.this.html")
            cpu_this.append(c)
            print(f"  {run.name} round {k + 1}: reference {cpu_ref[-1]:.2f} s, this "
                  f"{cpu_this[-1]:.2f} s (load {os.getloadavg()[0]:.1f})", file=sys.stderr,
                  flush=True)  # fmt: skip
        diff = differences(doc, ref, args.rtol, args.atol)
        diff += compare_pages(page, ref_page)
        bad += bool(diff)
        for d in diff:
            print(f"  {run.name}: {d}", file=sys.stderr)
        n_fig = len(PNG.findall(page))
        verdict = (
            f"metrics {'equal' if doc == ref else 'within the tolerance'}, text equal, "
            f"{n_fig} figures equal pixel for pixel"
            if not diff
            else f"{len(diff)} differences"
        )
        rows.append((run.name, statistics.median(cpu_this), statistics.median(cpu_ref), verdict))
    load1, y1 = os.getloadavg(), yardstick_s()
    print(
        f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores; load {load0[0]:.2f} -> {load1[0]:.2f}; yardstick "
        f"{1e3 * y0:.1f} / {1e3 * y1:.1f} ms CPU; median of {args.repeats} interleaved rounds\n"
    )
    print("| run | this CPU s | reference CPU s | this / reference | against the reference |")
    print("|---|---|---|---|---|")
    for name, cpu, ref_cpu, verdict in rows:
        print(f"| {name} | {cpu:.2f} | {ref_cpu:.2f} | {cpu / ref_cpu:.2f} | {verdict} |")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
