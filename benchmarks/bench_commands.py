"""Whole-command CPU time of the analysis loop, beside the previous implementation.

Run from the repository root (a few minutes on a loaded 2-core machine)::

    .venv/bin/python benchmarks/bench_commands.py --previous /path/to/previous/.venv/bin/labrig

Each command runs as its own process (imports included), ``--repeats`` times (default 3), for this
checkout's ``labrig`` and, with ``--previous``, for another installation of labrig (the previous
implementation: for instance a ``git worktree`` of the previous commit with its own virtual
environment), the two interleaved so a drift of the machine's speed hits both alike. Reported:
user + system CPU seconds of the process and its children (``resource.getrusage``), median and
minimum, the ratio previous / this, and a yardstick timed in the same run (``numpy.sort`` of 1e6
floats, CPU seconds in this process) so figures from different days compare. Wall time is not
reported: the machine is shared.

The datasets: ``experiments/paper.yaml`` run on the simulated rig with seed 1 (11 entries), the
real micromanipulator record ``tests/data/real/yan9a-micromanipulator/Model_Vi_Do.dat`` imported as
the README says, and 20 short captures imported as one file (:func:`short_entries`, timed with
``fit`` only). Commands: ``labrig --help``, ``fit --json``, ``report --json`` (every peer),
``diagnose --json``, on the run side ``check experiments/paper.yaml`` and ``run
experiments/sweep.yaml`` (seed 1, 10 entries, 42 s of samples at 1 kHz, on the simulated rig), and
``model figures`` (the paper's section-2 figures, from the model alone). The
JSON documents of both implementations are compared: the largest relative difference of every NRMSE,
the effects added and the verdict's class.

``--floor`` measures instead what a command cannot go below in a fresh process: the CPU of a
bare interpreter, then of importing what ``labrig fit`` must use (numpy, scipy.optimize, h5py,
numba, the command line's typer, rich and pydantic), numba's start at the first call of a cached
kernel, the run file's checked read (:func:`labrig.store.read_run`, in a child process as every
command reads it), and for ``labrig report`` with every peer the further libraries it must
import (scipy.signal for SINDy's derivative, pysindy with scikit-learn and pandas, matplotlib's
figure and Agg canvas, Pillow, jinja2). Each row is its own fresh process, ``--repeats`` times,
interleaved; the rows are cumulative (each process does what the rows above did, then its own
step) and the table gives each step's increment (median) and the cumulative median.

Prints markdown on stdout (copied into ``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import yardstick

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "tests" / "data" / "real" / "yan9a-micromanipulator" / "Model_Vi_Do.dat"


def yardstick_s(repeats: int = 5) -> float:
    """CPU seconds of ``np.sort`` of 1e6 uniform floats (median of ``repeats``)."""
    return yardstick.yardstick_s(repeats, statistics.median)


def cpu_of(cmd: list[str], cwd: Path, timeout: float = 1800) -> tuple[float, str]:
    """User + system CPU seconds of a child process (and its own children) and its stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode not in (0,):
        raise RuntimeError(f"{' '.join(cmd)} exited {res.returncode}: {res.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, res.stdout


def make_data(labrig: str, work: Path) -> dict[str, Path]:
    work.mkdir(parents=True, exist_ok=True)
    paper = work / "paper1.h5"
    real = work / "real_model.h5"
    if not paper.exists():
        subprocess.run(
            [labrig, "run", str(ROOT / "experiments" / "paper.yaml"), "--seed", "1", "--out",
             str(paper)], check=True, capture_output=True,
        )  # fmt: skip
    if not real.exists():
        subprocess.run(
            [labrig, "import", str(REAL), "--out", str(real), "--voltage", "1", "--strain", "5",
             "--rate-hz", "200", "--strain-units", "raw"], check=True, capture_output=True,
        )  # fmt: skip
    short = work / "short20.h5"
    if not short.exists():
        csvs = short_entries(work / "short20")
        subprocess.run(
            [labrig, "import", *map(str, csvs), "--out", str(short)], check=True,
            capture_output=True,
        )  # fmt: skip
    return {
        "paper campaign (seed 1)": paper,
        "real record Model_Vi_Do": real,
        SHORT: short,
    }


#: the dataset of many short entries (:func:`short_entries`), timed with ``fit`` only
SHORT = "20 short entries (60 samples each)"


def short_entries(folder: Path, n: int = 20, samples: int = 60) -> list[Path]:
    """``n`` CSV captures of ``samples`` samples at 1 kHz: unipolar sines of 60-70 V at 25-35
    Hz on a linear stack (8.9 ue/V) with 2 ue of gauge noise, no hysteresis (the shape of a
    tester's file whose leave-one-out took minutes: many folds, each fitting every entry, and
    a model whose operator the data do not determine)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    t = np.arange(samples) / 1000.0
    paths = []
    for k in range(n):
        f, a = 25 + 0.5 * k, 60 + 0.5 * k
        v = a / 2 * (1 - np.cos(2 * np.pi * f * t))
        s = 8.9 * v + rng.normal(0.0, 2.0, samples)
        path = folder / f"m{k:02d}.csv"
        cols = zip(t.tolist(), v.tolist(), s.tolist(), strict=True)
        rows = "".join(f"{x!r},{y!r},{z!r}\n" for x, y, z in cols)
        path.write_text("time_s,voltage_V,strain_ue\n" + rows)
        paths.append(path)
    return paths


def nrmse_values(doc, prefix: str = "") -> dict[str, float]:
    """Every number under a key that names an NRMSE, by its path in the document."""
    out: dict[str, float] = {}
    if isinstance(doc, dict):
        for k, v in doc.items():
            path = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and "nrmse" in path:
                out[path] = float(v)
            else:
                out.update(nrmse_values(v, path))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.update(nrmse_values(v, f"{prefix}[{i}]"))
    return out


def compare(a: str, b: str) -> str:
    """How two JSON documents of one command differ: NRMSE (largest relative difference),
    effects added, verdict class."""
    try:
        da, db = json.loads(a), json.loads(b)
    except json.JSONDecodeError:
        return "-"
    na, nb = nrmse_values(da), nrmse_values(db)
    common = set(na) & set(nb)
    rel = max(
        (abs(na[k] - nb[k]) / max(abs(nb[k]), 1e-300) for k in common if np.isfinite(nb[k])),
        default=0.0,
    )
    parts = [f"NRMSE max rel diff {rel:.1e} ({len(common)} values)"]
    if isinstance(da, dict) and "effects_added" in da:
        ea = [e["effect"] for e in da["effects_added"]]
        eb = [e["effect"] for e in db["effects_added"]]
        parts.append("same effects" if ea == eb else f"effects {ea} vs {eb}")
        va, vb = da.get("verdict", ""), db.get("verdict", "")
        parts.append("same verdict" if va == vb else "verdict text differs")
    return "; ".join(parts)


#: ``--floor``'s steps: (label, the statements a fresh process runs after the previous
#: steps'); ``RUN`` is replaced by the run file's path
FLOOR_STEPS: tuple[tuple[str, str], ...] = (
    ("interpreter start (`python -c pass`)", "pass"),
    ("import numpy, scipy.optimize", "import numpy, scipy.optimize"),
    ("import h5py", "import h5py"),
    ("import the command line's libraries", "import typer, rich.progress, pydantic"),
    ("import numba", "import numba"),
    (
        "numba's start: the first call of a cached kernel (the operator's)",
        "from labrig.model.accel import kernels; import numpy as np; "
        "kernels().operator_pass(np.zeros(4), np.zeros(1), np.zeros(1), 0.0, 0.0, 2, 0, 1.0, "
        "1.0, 1.0, False, np.empty((4, 0)))",
    ),
    (
        "read the run file (checked, in a child process)",
        "from labrig.store import read_run; read_run(RUN)",
    ),
    ("`labrig fit`'s floor", ""),
    ("import scipy.signal (SINDy's Savitzky-Golay derivative)", "import scipy.signal"),
    ("import pysindy (scikit-learn, pandas)", "import pysindy"),
    (
        "import matplotlib's figure and Agg canvas, Pillow, jinja2",
        "import matplotlib.figure, matplotlib.backends.backend_agg, PIL.Image, jinja2",
    ),
    ("`labrig report`'s floor (every peer, the page)", ""),
)  # fmt: skip


def floor(run: Path, repeats: int) -> list[tuple[str, float | None, float]]:
    """``--floor``: (label, the step's increment, the cumulative CPU seconds) of each of
    :data:`FLOOR_STEPS` (a total row: increment ``None``), medians of ``repeats`` fresh
    processes per step, interleaved."""
    steps = [(label, code.replace("RUN", repr(str(run)))) for label, code in FLOOR_STEPS]
    cumul: dict[int, list[float]] = {i: [] for i, (_, c) in enumerate(steps) if c}
    for _ in range(repeats):
        done: list[str] = []
        for i, (_, code) in enumerate(steps):
            if not code:
                continue
            done.append(code)
            cpu, _ = cpu_of([sys.executable, "-c", "; ".join(done)], ROOT)
            cumul[i].append(cpu)
    rows: list[tuple[str, float | None, float]] = []
    prev = 0.0
    last = 0.0
    for i, (label, code) in enumerate(steps):
        if not code:
            rows.append((label, None, last))
            continue
        med = statistics.median(cumul[i])
        rows.append((label, med - prev, med))
        prev = last = med
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--previous", help="the previous implementation's labrig executable")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--work", default="/tmp/labrig-bench-commands")
    ap.add_argument("--only", default="", help="comma-separated commands (help,fit,report,...)")
    ap.add_argument("--floor", action="store_true", help="the floor of fit and report (above)")
    args = ap.parse_args()
    this = shutil.which("labrig", path=str(Path(sys.executable).parent)) or "labrig"
    work = Path(args.work)
    data = make_data(this, work)
    if args.floor:
        load0, y0 = os.getloadavg(), yardstick_s()
        rows = floor(data["paper campaign (seed 1)"], args.repeats)
        load1, y1 = os.getloadavg(), yardstick_s()
        cpu = platform.processor() or platform.machine()
        print(
            f"Floor, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu}, {os.cpu_count()} cores; "
            f"load {load0[0]:.2f} -> {load1[0]:.2f}; yardstick {1e3 * y0:.1f} / "
            f"{1e3 * y1:.1f} ms CPU; medians of {args.repeats} fresh processes per step\n"
        )
        print("| step | CPU s (this step) | CPU s (cumulative) |")
        print("|---|---|---|")
        for label, inc, cum in rows:
            if inc is None:
                print(f"| **{label}** | | **{cum:.2f}** |")
            else:
                print(f"| {label} | {inc:.2f} | {cum:.2f} |")
        return 0
    load0 = os.getloadavg()
    y0 = yardstick_s()
    commands = {
        "help": lambda f: ["--help"],
        "fit": lambda f: ["fit", str(f), "--json"],
        "report": lambda f: [
            "report",
            str(f),
            "--json",
            "--out",
            str(work / "r.html"),
            "--overwrite",
        ],
        "diagnose": lambda f: ["diagnose", str(f), "--json"],
        # the run side: a preflight and the rig's drivers, and a whole simulated run
        "check": lambda f: ["check", str(ROOT / "experiments" / "paper.yaml")],
        "run": lambda f: [
            "run",
            str(ROOT / "experiments" / "sweep.yaml"),
            "--seed",
            "1",
            "--out",
            str(work / "sweep.h5"),
            "--overwrite",
        ],
        # the paper's section-2 figures, drawn from the model alone
        "figures": lambda f: ["model", "figures", "--out", str(work / "figures"), "--overwrite"],
    }
    only = [c for c in args.only.split(",") if c] or list(commands)
    rows = []
    for cname in only:
        files = {"-": None} if cname in ("help", "check", "run", "figures") else dict(data)
        if cname != "fit":  # the short entries: a case of the fit's leave-one-out
            files.pop(SHORT, None)
        for dname, f in files.items():
            times: dict[str, list[float]] = {"this": [], "previous": []}
            outs: dict[str, str] = {}
            for _ in range(args.repeats):
                for who, exe in (("this", this), ("previous", args.previous)):
                    if exe is None:
                        continue
                    cpu, out = cpu_of([exe, *commands[cname](f)], work)
                    times[who].append(cpu)
                    outs[who] = out
            med = {k: statistics.median(v) for k, v in times.items() if v}
            ratio = med["previous"] / med["this"] if "previous" in med else None
            rows.append(
                (
                    cname,
                    dname,
                    med["this"],
                    min(times["this"]),
                    med.get("previous"),
                    ratio,
                    compare(outs["this"], outs["previous"]) if "previous" in outs else "",
                )
            )
            print(f"  {cname} {dname}: {med}", file=sys.stderr)
    y1 = yardstick_s()
    load1 = os.getloadavg()
    cpu = platform.processor() or platform.machine()
    print(
        f"Run {datetime.now(UTC):%Y-%m-%d %H:%M} UTC on {cpu}, {os.cpu_count()} cores; load "
        f"average {load0[0]:.2f} at the start, {load1[0]:.2f} at the end; yardstick (np.sort of "
        f"1e6 floats) {1e3 * y0:.1f} / {1e3 * y1:.1f} ms CPU.\n"
    )
    print("| command | data | CPU s (median / min) | previous CPU s | previous / this | "
          "results against the previous |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for c, d, m, lo, p, r, cmp in rows:
        prev = f"{p:.2f}" if p is not None else "-"
        rat = f"{r:.1f}x" if r is not None else "-"
        print(f"| `{c}` | {d} | {m:.2f} / {lo:.2f} | {prev} | {rat} | {cmp} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
