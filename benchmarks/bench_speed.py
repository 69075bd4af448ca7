"""Where the CPU of ``labrig fit`` and ``labrig diagnose`` goes, and what a larger library costs.

Run from the repository root (a few minutes on a loaded 2-core machine)::

    .venv/bin/python benchmarks/bench_speed.py phases RUN.h5        # fit and diagnose, by step
    .venv/bin/python benchmarks/bench_speed.py library RUN.h5       # 4 more candidates
    .venv/bin/python benchmarks/bench_speed.py fleet-task RUN.h5    # batch diagnose's base fit
    .venv/bin/python benchmarks/bench_speed.py documents A.h5 B.h5 --reference PYTHON  # pages
    .venv/bin/python benchmarks/bench_speed.py reads A.h5 B.h5 C.h5   # files read again
    git worktree add /tmp/before COMMIT    # the tree to compare with, then:
    .venv/bin/python benchmarks/bench_speed.py checked-read A.h5 B.h5 --tree /tmp/before
    .venv/bin/python benchmarks/bench_speed.py static-stage A.h5 B.h5 --tree /tmp/before

``phases``: one fresh process each for ``fit`` and for ``diagnose`` (one worker), CPU seconds
(``getrusage`` of the process and its children: the store reads a run file in a child process)
at each step: the imports (numpy and scipy.optimize; labrig's command modules; numba and the
compiled kernels), reading the run file, the fit or the diagnosis' steps (from its progress
messages), and the whole.

``library``: ``diagnose`` in this process (one worker) with the effect library as it is and with
four more candidates registered for the benchmark only (``library`` is replaced in
:mod:`labrig.analysis.diagnose.procedure` for the run): four copies of library effects under new
names (they rank as their originals do, so they can displace others from the refitted top
``top_k``), and four dummy gains the base model absorbs (ranked last: their cost is the
ranking's). The variants interleaved, ``--repeats`` times each (default 2); CPU seconds
(``time.process_time``), the ratio to the library as it is, the candidates ranked and refitted,
the effects added and the held-out NRMSE, and a yardstick (``numpy.sort`` of 1e6 floats) timed
in the same process.

``fleet-task``: what a ``batch diagnose`` task saves by giving its fit to the diagnosis
(``diagnose(base_fit=...)``): one fresh process per variant, interleaved ``--repeats`` times
each, both reading the file once and running the task's ``fit_part`` (``labrig fit`` with
leave-one-entry-out), then the diagnosis with the fit (``reuse``) or fitting its own base as
before (``refit``); CPU seconds (``getrusage``, children included) of the fit, of the diagnosis
and of both, medians and ranges, and whether the two ``diagnosis.json`` documents are equal.

``documents``: what a ``batch diagnose`` task's documents cost (``diagnosis.json`` and
``diagnosis.html`` with its figures) in a worker that has made some before: one fresh process
per installation (this checkout's interpreter, and ``--reference PYTHON``, another
installation's, interleaved ``--repeats`` times), each diagnosing the run files given (the
task's fit, then the diagnosis), then making their documents three times over, one run after
the other, with a task's large temporaries allocated and freed between pages; CPU seconds of
the first (matplotlib's import, the first figure) and the median of the others, and whether
every ``diagnosis.json`` and every figure's pixels are the same across the installations.

``reads``: what keeping the recent reads saves a session that reads files again after others
(a notebook, a test suite, ``validate`` over several files): the files given read in turn, three
times over, in this process, with the store keeping the last eight files (today) and the last
one only (before; ``RECENT_FILES = 1``), interleaved ``--repeats`` times; CPU seconds of the
process and its children (each read is made in a forked child), the number of reads made, and
the yardstick.

``checked-read``: one checked read of each file (``labrig.store.parse.read_run_here``: the
seals, the types and shapes, every sample; what a command's forked reader does) with this
tree's code and with ``--tree``'s (another checkout, imported ahead of the installed labrig),
one fresh process per tree, interleaved ``--repeats`` times (default 2); each process reads
every file 9 times and gives the median CPU seconds (``time.process_time``) of a read, and a
yardstick (``numpy.sort`` of 1e6 floats) timed beside it; the ratio of the medians per file, and
whether the two trees read the same (every field and every sample equal).

``static-stage``: the staged fit's static stage (``labrig.analysis.staged._fit_static``) in the
fit ``labrig fit`` makes (no leave-one-out), five fits of each file in one fresh process per
tree (this one and ``--tree``'s), interleaved ``--repeats`` times; the median CPU seconds of the
stage in the four warm fits (the first pays numba's start), the ratio of the medians per file,
whether both trees' stages return the same parameters (to the last digit), and the yardstick.

Prints markdown on stdout (copied into ``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from bench_commands import yardstick_s

#: what the child process of ``phases`` runs: prints one JSON line of (step, CPU s) pairs
PHASES = r"""
import json, resource, sys, time
def cpu():
    a = resource.getrusage(resource.RUSAGE_SELF); b = resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime
out = [("interpreter start", cpu())]
import numpy, scipy.optimize
out.append(("import numpy, scipy.optimize", cpu()))
from pathlib import Path
what, path = sys.argv[1], Path(sys.argv[2])
if what == "fit":
    from labrig.commands.fit import fit_run_file
else:
    from labrig.commands.diagnose import diagnose_run_file
out.append(("import labrig's command modules", cpu()))
import labrig.model.compiled
from labrig.model.accel import kernels
kernels()
out.append(("import numba, load the operator's compiled kernels", cpu()))
from labrig.store import read_run
run = read_run(path)
out.append(("read the run file (checked, in a child process)", cpu()))
if what == "fit":
    fit_run_file(path, run=run)
    out.append(("fit with leave-one-entry-out", cpu()))
else:
    last = [None]
    def say(msg):
        if last[0] is not None:
            out.append((last[0], cpu()))
        last[0] = msg
    diagnose_run_file(path, progress=say, workers=1, snapshot=run)
    out.append((last[0] + " ... to the end", cpu()))
print(json.dumps(out))
"""

#: what the child process of ``fleet-task`` runs: one JSON line (fit CPU s, diagnosis CPU s, doc)
FLEET_TASK = r"""
import json, resource, sys
from pathlib import Path
def cpu():
    a = resource.getrusage(resource.RUSAGE_SELF); b = resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime
from labrig.commands.diagnose import diagnose_run_file
from labrig.fleet.tasks import TaskOptions, TaskResult, fit_part, read_snapshot, task_base_fit
path, reuse = Path(sys.argv[1]), sys.argv[2] == "reuse"
snap = read_snapshot(path)
t = cpu()
fit_part(snap, TaskOptions(), TaskResult("diagnose", str(path), "bench", False))
t_fit = cpu() - t
t = cpu()
res = diagnose_run_file(path, snapshot=snap.run, base_fit=task_base_fit(snap) if reuse else None)
print(json.dumps([t_fit, cpu() - t, res.document]))
"""

#: what the child process of ``documents`` runs: one JSON line (CPU s of the first documents,
#: of each later one, the diagnosis.json documents, SHA-256 of each figure's pixels)
DOCUMENTS = r"""
import base64, hashlib, io, json, re, sys, time
from pathlib import Path
import numpy as np
from PIL import Image
from labrig.commands.diagnose import diagnose_run_file
from labrig.fleet.tasks import TaskOptions, TaskResult, fit_part, read_snapshot, task_base_fit
results = []
for p in sys.argv[1:]:
    path = Path(p)
    snap = read_snapshot(path)
    fit_part(snap, TaskOptions(), TaskResult("diagnose", str(path), "bench", False))
    results.append(diagnose_run_file(path, snapshot=snap.run, base_fit=task_base_fit(snap)))
times, out = [], {}
for rnd in range(3):
    for res in results:
        junk = [np.ones((87_500, 8)) for _ in range(20)]  # a task's temporaries between pages
        del junk
        t = time.process_time()
        docs = res.documents()
        times.append(time.process_time() - t)
        pngs = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", docs["diagnosis.html"])
        pixels = [hashlib.sha256(np.asarray(Image.open(io.BytesIO(base64.b64decode(b))))
                  .tobytes()).hexdigest() for b in pngs]
        out[res.path.name] = [docs["diagnosis.json"], pixels]
print(json.dumps([times[0], times[1:], out]))
"""

#: the start of a child script of :func:`compare_trees`: labrig imported from the tree its first
#: argument names (``from_tree`` checks where a module came from), and the yardstick
#: (``numpy.sort`` of 1e6 floats, CPU s)
IN_TREE = r"""
import hashlib, json, statistics, sys, time
from pathlib import Path
import numpy as np
import importlib
tree = sys.argv[1]
sys.path.insert(0, tree)
def from_tree(name):
    module = importlib.import_module(name)
    assert module.__file__.startswith(tree), module.__file__
    return module
def yardstick():
    x = np.random.default_rng(0).random(1_000_000)
    t = time.process_time()
    np.sort(x)
    return time.process_time() - t
"""

#: what the child process of ``checked-read`` runs: one JSON line (median CPU s of a read per
#: file, the yardstick's median, a digest of what each file read to)
CHECKED_READ = (
    IN_TREE
    + r"""
parse = from_tree("labrig.store.parse")
out, sticks = {}, []
for p in map(Path, sys.argv[2:]):
    run, shapes = parse.read_run_here(p)
    ts = []
    for _ in range(9):
        t = time.process_time()
        run, shapes = parse.read_run_here(p)
        ts.append(time.process_time() - t)
        sticks.append(yardstick())
    def canon(x):
        if hasattr(x, "__dataclass_fields__"):
            return canon(vars(x))
        if isinstance(x, dict):
            return [[repr(k), canon(v)] for k, v in sorted(x.items(), key=lambda kv: repr(kv[0]))]
        if isinstance(x, list | tuple):
            return [canon(v) for v in x]
        if isinstance(x, np.ndarray):
            return [x.dtype.str, x.shape, hashlib.sha256(x.tobytes()).hexdigest()]
        return repr(x)
    run.path = None
    digest = hashlib.sha256(repr(canon([run, shapes])).encode()).hexdigest()
    out[p.name] = [statistics.median(ts), digest]
print(json.dumps([out, statistics.median(sticks)]))
"""
)

#: what the child process of ``static-stage`` runs: ``labrig fit``'s fit (no leave-one-out) of
#: each file five times; one JSON line (median CPU s of the static stage in the warm fits, the
#: stage's result; the yardstick's median)
STATIC_STAGE = (
    IN_TREE
    + r"""
staged = from_tree("labrig.analysis.staged")
from labrig.commands.fit import fit_dynamic
from labrig.commands.prepare import prepare
out, sticks = {}, []
for p in map(Path, sys.argv[2:]):
    setup = prepare(p)
    calls, results = [], []
    stage = staged._fit_static
    def timed(*a, **k):
        t = time.process_time()
        results.append(stage(*a, **k))
        calls.append(time.process_time() - t)
        return results[-1]
    staged._fit_static = timed
    for _ in range(5):
        fit_dynamic(setup, "global", heldout=False, progress=None)
        sticks.append(yardstick())
    staged._fit_static = stage
    # the first fit pays numba's start; the stage's result in full precision
    out[p.name] = [statistics.median(calls[1:]), repr(sorted(results[-1].items()))]
print(json.dumps([out, statistics.median(sticks)]))
"""
)

ROOT = Path(__file__).resolve().parents[1]


def header() -> str:
    load = os.getloadavg()
    return (
        f"Run {datetime.now(UTC):%Y-%m-%d %H:%M} UTC on "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; load average "
        f"{load[0]:.2f}; yardstick (np.sort of 1e6 floats) {1e3 * yardstick_s():.1f} ms CPU."
    )


def phases(path: Path, repeats: int) -> None:
    print(header() + "\n")
    for what in ("fit", "diagnose"):
        runs = []
        for _ in range(repeats):
            res = subprocess.run(
                [sys.executable, "-c", PHASES, what, str(path)],
                capture_output=True,
                text=True,
                check=True,
                cwd=ROOT,
            )
            runs.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print(f"`{what}` of {path.name}, CPU s per step (median of {repeats} processes):\n")
        print("| step | CPU s |")
        print("|---|---|")
        steps = [name for name, _ in runs[0]]
        prev = [0.0] * len(runs)
        for i, name in enumerate(steps):
            d = [r[i][1] - p for r, p in zip(runs, prev, strict=True)]
            prev = [r[i][1] for r in runs]
            print(f"| {name} | {statistics.median(d):.2f} |")
        total = statistics.median(r[-1][1] for r in runs)
        print(f"| **whole process** | **{total:.2f}** |\n")


#: the library effects copied under new names for ``library`` (the copies variant)
COPIED = ("offset_drift", "sensor_lowpass", "quadratic_term", "time_delay")


def _gain_dummy(k: int):
    """A cheap dummy candidate: an output gain ``(1 + g) S``, which the base model absorbs
    entirely (its alpha0 and gamma), so the ranking puts it last and it is never refitted."""
    from labrig.model.effects import Effect
    from labrig.model.effects.base import Param

    class Gain(Effect):
        name = f"dummy_gain_{k}"
        where = "output"
        params = (Param("g", "", 0.0, -0.1, 0.1, 0.001),)

        def apply(self, x, ctx, p):
            return (1.0 + p.get("g", 0.0)) * x

    return Gain()


def library(path: Path, repeats: int) -> None:
    from labrig.analysis.diagnose import procedure
    from labrig.commands.prepare import prepare_diagnosis

    setup = prepare_diagnosis(path, say=lambda _m: None)
    real_library = procedure.library

    def copies(**context):
        lib = real_library(**context)
        more = {}
        for name in COPIED:
            e = copy.copy(lib[name])
            e.name = f"copy_of_{name}"
            more[e.name] = e
        return {**lib, **more}

    def dummies(**context):
        more = [_gain_dummy(k) for k in range(4)]
        return {**real_library(**context), **{e.name: e for e in more}}

    def one(lib) -> tuple[float, list[str], float, int, list[str]]:
        procedure.library = lib
        try:
            names = None
            if lib is not real_library:
                names = [*procedure.EFFECT_NAMES, *(n for n in lib() if n not in real_library())]
            t = time.process_time()
            d = procedure.diagnose(
                setup.records, setup.start, offset=setup.offset, effects=names, workers=1
            )
            cpu = time.process_time() - t
        finally:
            procedure.library = real_library
        ranked = sum(len(r) for r in d.rounds)
        tried = [c.effect for r in d.rounds for c in r if c.tried]
        added = [e["effect"] for e in d.effects_added]
        return cpu, added, d.after["heldout_nrmse_pct"], ranked, tried

    print(header() + "\n")
    one(real_library)  # warm: imports, compiled kernels
    variants = {
        "as it is": real_library,
        "+ 4 copies of library effects (" + ", ".join(COPIED) + ")": copies,
        "+ 4 dummy gains (absorbed by the base, ranked last)": dummies,
    }
    rows: dict[str, list] = {k: [] for k in variants}
    for _ in range(repeats):
        for k, lib in variants.items():
            rows[k].append(one(lib))
    print(f"`diagnose` of {path.name} in-process (one worker), CPU s:\n")
    print(
        "| library | CPU s (median / min) | ratio | candidates ranked | refitted (all rounds) "
        "| effects added | held-out NRMSE % |"
    )
    print("|---|---|---|---|---|---|---|")
    ref = statistics.median(c for c, *_ in rows["as it is"])
    for k, v in rows.items():
        cpus = [c for c, *_ in v]
        med = statistics.median(cpus)
        _, added, ho, ranked, tried = v[-1]
        print(
            f"| {k} | {med:.2f} / {min(cpus):.2f} | {med / ref:.2f}x | {ranked} "
            f"| {', '.join(tried)} | {', '.join(added) or '-'} | {ho:.6g} |"
        )


def fleet_task(path: Path, repeats: int) -> None:
    """``fleet-task`` (module docstring)."""
    print(header() + "\n")
    got: dict[str, list] = {"refit": [], "reuse": []}
    for _ in range(repeats):
        for variant in got:
            res = subprocess.run(
                [sys.executable, "-c", FLEET_TASK, str(path), variant],
                capture_output=True,
                text=True,
                check=True,
                cwd=ROOT,
            )
            got[variant].append(json.loads(res.stdout.strip().splitlines()[-1]))
    same = all(r[2] == got["refit"][0][2] for rs in got.values() for r in rs)
    print(f"`batch diagnose` task of {path.name}: `fit_part`, then the diagnosis, CPU s "
          f"(median and range of {repeats} fresh processes each, interleaved):\n")  # fmt: skip
    print("| diagnosis | fit (with leave-one-out) | the diagnosis | both |")
    print("|---|---|---|---|")
    for variant, label in (("refit", "fits its own base"), ("reuse", "takes the task's fit")):
        rows = got[variant]
        cells = []
        for vals in ([r[0] for r in rows], [r[1] for r in rows], [r[0] + r[1] for r in rows]):
            cells.append(f"{statistics.median(vals):.2f} ({min(vals):.2f}-{max(vals):.2f})")
        print(f"| {label} | " + " | ".join(cells) + " |")
    print(f"\n`diagnosis.json` of every process equal: {same}; load average now "
          f"{os.getloadavg()[0]:.2f}")  # fmt: skip


def documents(paths: list[Path], repeats: int, reference: str | None) -> None:
    """``documents`` (module docstring)."""
    print(header() + "\n")
    pythons = {"this checkout": sys.executable}
    if reference:
        pythons = {"reference": reference, **pythons}
    got: dict[str, list] = {k: [] for k in pythons}
    for _ in range(repeats):
        for label, python in pythons.items():
            res = subprocess.run(
                [python, "-c", DOCUMENTS, *map(str, paths)],
                capture_output=True,
                text=True,
                check=True,
                cwd=ROOT,
            )
            got[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
    first = next(iter(got.values()))[0]
    same = all(r[2] == first[2] for rs in got.values() for r in rs)
    names = ", ".join(p.name for p in paths)
    print(f"`diagnosis.json` + `diagnosis.html` of {names}, three times over, CPU s "
          f"({repeats} fresh processes each, interleaved):\n")  # fmt: skip
    print("| installation | first in the process (range) | later: median (range) |")
    print("|---|---|---|")
    for label, rows in got.items():
        firsts = [r[0] for r in rows]
        later = [t for r in rows for t in r[1]]
        cells = [f"{statistics.median(v):.2f} ({min(v):.2f}-{max(v):.2f})" for v in (firsts, later)]
        print(f"| {label} | " + " | ".join(cells) + " |")
    print(f"\nevery `diagnosis.json` and every figure's pixels the same in every process: {same}; "
          f"load average now {os.getloadavg()[0]:.2f}")  # fmt: skip


def reads(paths: list[Path], repeats: int) -> None:
    """The ``reads`` comparison (module docstring)."""
    import resource

    from labrig.store import reader

    def cpu() -> float:
        a, b = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
        return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime

    made: list[int] = []
    real = reader.call_isolated

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        made.append(1)
        return real(*args, **kwargs)

    reader.call_isolated = counting  # type: ignore[assignment]
    kept = reader.RECENT_FILES
    times: dict[int, list[float]] = {kept: [], 1: []}
    counts: dict[int, int] = {}
    for _ in range(repeats):
        for files in (kept, 1):
            reader.RECENT_FILES = files
            reader._recent.clear()
            made.clear()
            t = cpu()
            for _round in range(3):
                for p in paths:
                    reader.read_run(p)
            times[files].append(cpu() - t)
            counts[files] = len(made)
    reader.RECENT_FILES = kept
    print(header())
    print()
    print("| files kept | reads made | CPU s (median; range) |")
    print("|---|---|---|")
    for files, ts in times.items():
        print(
            f"| {files} | {counts[files]} of {3 * len(paths)} | {statistics.median(ts):.3f}; "
            f"{min(ts):.3f}-{max(ts):.3f} |"
        )
    ratio = statistics.median(times[1]) / statistics.median(times[kept])
    print(f"\nlast one only / last {kept}: {ratio:.2f}x the CPU")


def compare_trees(code: str, paths: list[Path], repeats: int, tree: Path, what: str) -> None:
    """Run ``code`` (a child's script: ``argv`` the tree, then the files; its last line JSON
    ``[{file: [median CPU s, digest]}, yardstick s]``) with this tree's labrig and with
    ``tree``'s, one fresh process per tree, interleaved ``repeats`` times; print the medians
    per file, their ratio and whether every digest agrees. ``what``: the table's caption."""
    trees = {"this tree": ROOT, f"`--tree` ({tree.name})": tree}
    got: dict[str, list] = {k: [] for k in trees}
    for _ in range(repeats):
        for label, root in trees.items():
            res = subprocess.run(
                [sys.executable, "-c", code, str(root), *map(str, paths)],
                capture_output=True,
                text=True,
                check=True,
                cwd="/",
            )
            got[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
    print(header() + "\n")
    print(f"{what}; median and range over {repeats} processes per tree, interleaved:\n")
    print("| file | " + " | ".join(trees) + " | ratio |")
    print("|---|" + "---|" * (len(trees) + 1))
    this, other = (got[k] for k in trees)
    for p in paths:
        cells, meds = [], []
        for rows in (this, other):
            v = [r[0][p.name][0] for r in rows]
            meds.append(statistics.median(v))
            cells.append(f"{meds[-1]:.3f} ({min(v):.3f}-{max(v):.3f})")
        print(f"| {p.name} | " + " | ".join(cells) + f" | {meds[0] / meds[1]:.2f} |")
    same = {r[0][p.name][1] for rows in got.values() for r in rows for p in paths} == {
        this[0][0][p.name][1] for p in paths
    }
    sticks = [r[1] for rows in got.values() for r in rows]
    print(f"\nyardstick {1e3 * statistics.median(sticks):.1f} ms (median of the processes'); "
          f"the same result in both trees: {same}; load average now "
          f"{os.getloadavg()[0]:.2f}")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    modes = ("phases", "library", "fleet-task", "documents", "reads", "checked-read")
    modes += ("static-stage",)
    ap.add_argument("what", choices=modes)
    ap.add_argument("run", type=Path, nargs="+", help="run file(s); documents: several")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--reference", help="documents: another installation's Python")
    ap.add_argument(
        "--tree", type=Path, help="checked-read, static-stage: another checkout to compare with"
    )
    a = ap.parse_args()
    if a.what in ("checked-read", "static-stage"):
        if a.tree is None:
            ap.error(f"{a.what} needs --tree (another checkout)")
        code, what = {
            "checked-read": (CHECKED_READ, "One checked read, CPU s (median of 9 reads)"),
            "static-stage": (STATIC_STAGE, "The staged fit's static stage, CPU s (median of 4)"),
        }[a.what]
        compare_trees(code, [r.resolve() for r in a.run], a.repeats, a.tree.resolve(), what)
        return 0
    if a.what == "documents":
        documents([r.resolve() for r in a.run], a.repeats, a.reference)
        return 0
    if a.what == "reads":
        reads([r.resolve() for r in a.run], a.repeats)
        return 0
    run = {"phases": phases, "library": library, "fleet-task": fleet_task}[a.what]
    run(a.run[0].resolve(), a.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
