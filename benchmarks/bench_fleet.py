"""Fleet benchmarks (``labrig batch`` on Dask): scaling, per-task overhead, memory per worker,
and the detection figures on a simulated fleet. Figures: ``benchmarks/RESULTS.md`` ("Fleet")
and ``docs/fleet.md``.

Run from the repository root (needs ``labrig[fleet]``)::

    .venv/bin/python benchmarks/bench_fleet.py scaling --n 8        # ~5-15 min on 2 cores
    .venv/bin/python benchmarks/bench_fleet.py detect --n 200 --out /tmp/fleet200   # hours

``scaling``: a simulated fleet of ``n`` runs of the 3-entry campaign of the tests, ``batch fit``
(with leave-one-out) serially, on a LocalCluster of 1 and of 2 worker processes, and on a
scheduler and two workers started as separate processes on 127.0.0.1 reached by address.
Per run: wall time, the tasks' own time (summed), overhead per task
``(wall * workers - sum of task times) / n`` (scheduling, transfer, writing, start-up spread
over the tasks), speed-up against one worker; the round trip of 200 empty tasks on the
2-worker LocalCluster; peak RSS of each worker after the batch.

``detect``: ``labrig sim fleet N`` (``experiments/paper.yaml``, seed 1, 5 % defects), then
``labrig batch diagnose`` on a LocalCluster of 2 workers, scored against ``truth.json``
(:func:`labrig.fleet.truth.score`); resumable (a rerun skips the runs already done).
``tasks FILES``: where the CPU of a ``batch diagnose`` (or ``--command report``) task goes, per
run file, in this process (the imports made by a first task, not counted): reading the file
(checked, in a child process), ``fit_part`` (``labrig fit`` with leave-one-entry-out), the
diagnosis itself (:func:`labrig.analysis.diagnose.diagnose`), its documents
(``diagnosis.json`` and the figures of ``diagnosis.html``), ``report_part``; then the whole
``labrig batch diagnose FILES --serial`` and ``--workers 2`` as child processes (CPU of the
command and every process it started: the LocalCluster's scheduler, nannies and workers),
per task. Run it with another installation's Python (its ``labrig`` is then the one measured)
for the figures before a change.

``compare DIR_A DIR_B``: are two ``batch diagnose`` (or ``fit``) output folders of the same run
files the same (another installation's batch, or a batch on Dask against ``--serial``)? The
tables (``fleet.parquet``, ``fleet_entries.parquet``, or their CSV) row by row, every column
equal but the task's time and worker (``elapsed_s``, ``diag_elapsed_s``, ``worker``); each
run's ``fit.json`` and ``diagnosis.json`` byte for byte; ``diagnosis.html`` with its figures
replaced by their index and the diagnosis' time masked character for character, and each
embedded figure decoded and compared pixel for pixel. Exit status 1 on any difference.

Every section prints the load average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from yardstick import yardstick_s

from labrig.fleet.batch import run_batch
from labrig.fleet.schedule import Where
from labrig.fleet.simfleet import write_fleet
from labrig.fleet.tasks import TaskOptions

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
SMALL = """\
name: fleet benchmark campaign
rate_hz: 1000
rest_s: 0.5
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [1, 10, 40]
    cycles: 2
    min_duration_s: 1
"""


def load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB); run on each worker."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def cpu_s() -> float:
    """User + system CPU seconds of this process and its reaped children."""
    a = resource.getrusage(resource.RUSAGE_SELF)
    b = resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def noop(x: int) -> int:
    return x


def one_batch(label: str, runs: list[Path], out: Path, where: Where) -> dict:
    quiet = Console(stderr=True, quiet=True)
    o = run_batch("fit", [str(r) for r in runs], out, where, TaskOptions(), console=quiet)
    assert not o.failed, o.failed
    work = sum(r["elapsed_s"] for r in o.rows)
    n, w = len(o.rows), o.schedule.n_workers
    return {
        "setup": label,
        "workers": w,
        "wall_s": o.schedule.wall_s,
        "task_s_sum": work,
        "task_s_mean": work / n,
        "overhead_per_task_s": (o.schedule.wall_s * w - work) / n,
    }


def start_cluster(tmp: Path) -> tuple[str, list[subprocess.Popen]]:
    sched = tmp / "scheduler.json"
    dev = subprocess.DEVNULL
    procs = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--scheduler-file",
                str(sched),
                "--no-dashboard",
            ],
            stdout=dev,
            stderr=dev,
        )
    ]
    while not sched.exists():
        time.sleep(0.2)
    addr = json.loads(sched.read_text())["address"]
    for k in (1, 2):
        procs.append(
            subprocess.Popen(
                [
                    str(BIN / "dask"),
                    "worker",
                    addr,
                    "--nthreads",
                    "1",
                    "--host",
                    "127.0.0.1",
                    "--name",
                    f"w{k}",
                    "--no-dashboard",
                ],
                stdout=dev,
                stderr=dev,
            )
        )
    from distributed import Client

    with Client(addr) as c:
        c.wait_for_workers(2, timeout=120)
    return addr, procs


def overhead_and_memory(addr: str) -> dict:
    """Round trip of 200 empty tasks and each worker's peak RSS, on the cluster at ``addr``."""
    from distributed import Client

    with Client(addr) as c:
        t0 = time.perf_counter()
        c.gather(c.map(noop, range(200), pure=False))
        empty = (time.perf_counter() - t0) / 200
        rss = c.run(peak_rss_mb)
    return {"empty_task_s": empty, "worker_peak_rss_mb": sorted(rss.values())}


def scaling(n: int) -> None:
    print(f"load average before: {load()}")
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as d:
        tmp = Path(d)
        (tmp / "small.yaml").write_text(SMALL)
        runs = write_fleet(n, tmp / "runs", tmp / "small.yaml", seed=3, defect_fraction=0.0)
        results = [
            one_batch("serial (this process)", runs, tmp / "serial", Where("serial")),
            one_batch("LocalCluster, 1 worker", runs, tmp / "l1", Where("local", workers=1)),
            one_batch("LocalCluster, 2 workers", runs, tmp / "l2", Where("local", workers=2)),
        ]
        addr, procs = start_cluster(tmp)
        try:
            where = Where("address", address=addr)
            results.append(one_batch("scheduler + 2 workers by address", runs, tmp / "a", where))
            extra = overhead_and_memory(addr)
        finally:
            for p in procs:
                p.terminate()
                p.wait(timeout=60)
    one = results[1]["wall_s"]
    for r in results:
        r["speedup_vs_1_worker"] = one / r["wall_s"]
    print(json.dumps({"n_runs": n, "results": results, **extra}, indent=2))
    print(f"load average after: {load()}")


def detect(n: int, out: Path, workers: int) -> None:
    from labrig.fleet.truth import read_truth, score

    print(f"load average before: {load()}")
    t0 = time.perf_counter()
    if not (out / "truth.json").exists():
        write_fleet(n, out, ROOT / "experiments" / "paper.yaml", seed=1, defect_fraction=0.05)
    sim_s = time.perf_counter() - t0
    cpu0 = cpu_s()
    o = run_batch("diagnose", [str(out)], out / "batch", Where("local", workers=workers))
    batch_cpu = cpu_s() - cpu0
    s = score(o.rows, read_truth(out / "truth.json"))
    times = sorted(r["elapsed_s"] for r in o.rows if not r["skipped"])
    print(
        json.dumps(
            {
                "n": n,
                "simulation_s": sim_s,
                "batch_wall_s": o.schedule.wall_s,
                "task_s_median": times[len(times) // 2] if times else None,
                "batch_cpu_s": batch_cpu,  # this process and its reaped children (workers)
                "skipped": o.n_skipped,
                "score": s,
            },
            indent=2,
        )
    )
    print(f"load average after: {load()}")


def task_parts(command: str, files: list[Path]) -> list[dict]:
    """CPU seconds of each part of one batch task per run file, in this process (a first task
    made the imports; each part's time includes the children it reaped)."""
    import labrig.analysis.diagnose as dg
    import labrig.commands.diagnose as cd
    import labrig.fleet.tasks as tasks
    from labrig.fleet.tasks import TaskSpec, run_task

    parts: dict[str, float] = {}
    saved = []

    def wrap(owner, name: str, label: str) -> None:
        f = getattr(owner, name)
        saved.append((owner, name, f))

        def timed(*a, **k):
            t = cpu_s()
            try:
                return f(*a, **k)
            finally:
                parts[label] = parts.get(label, 0.0) + cpu_s() - t

        setattr(owner, name, timed)

    wrap(tasks, "read_snapshot", "read the run file")
    wrap(tasks, "fit_part", "fit (with leave-one-out)")
    wrap(dg, "diagnose", "the diagnosis itself")
    wrap(cd.RunDiagnosis, "documents", "diagnosis.json + diagnosis.html")
    wrap(tasks, "report_part", "report (peers, figures, page)")
    saved_parts = dict(tasks.PARTS)
    tasks.PARTS = {k: tuple(getattr(tasks, f.__name__) for f in v) for k, v in saved_parts.items()}
    rows = []
    try:
        for k, f in enumerate([files[0], *files]):
            parts.clear()
            t = cpu_s()
            res = run_task(TaskSpec(command, str(f.resolve()), f.stem, TaskOptions()))
            total = cpu_s() - t
            if k == 0:  # the imports
                continue
            rows.append({"run": f.name, "ok": res.ok, "task_cpu_s": total, **parts})
    finally:
        tasks.PARTS = saved_parts
        for owner, name, f in saved:
            setattr(owner, name, f)
    return rows


def batch_cpu(command: str, files: list[Path], flags: list[str], out: Path) -> float:
    """CPU seconds of ``labrig batch COMMAND FILES --out OUT FLAGS`` and every process it
    started (reaped children: the LocalCluster's processes)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(
        [str(BIN / "labrig"), "batch", command, *map(str, files), "--out", str(out), *flags],
        check=True,
        capture_output=True,
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def task_costs(command: str, files: list[Path]) -> None:
    import labrig

    print(f"labrig {labrig.__file__}; load average before: {load()}; "
          f"yardstick {1e3 * yardstick_s():.1f} ms")  # fmt: skip
    rows = task_parts(command, files)
    for r in rows:
        print(json.dumps(r))
    n = len(rows)
    keys = dict.fromkeys(k for r in rows for k in r if k not in ("run", "ok"))
    mean = {k: sum(r.get(k, 0.0) for r in rows) / n for k in keys}
    print("mean per task:", json.dumps({k: round(v, 2) for k, v in mean.items()}))
    with tempfile.TemporaryDirectory(prefix="bench-tasks-") as d:
        for label, flags in (
            ("serial", ["--serial"]),
            ("LocalCluster 2 workers", ["--workers", "2"]),
        ):
            cpu = batch_cpu(command, files, flags, Path(d) / label.replace(" ", "_"))
            print(f"batch {command} {label}: {cpu:.1f} s CPU in all, {cpu / n:.2f} s per task")
    print(f"load average after: {load()}; yardstick {1e3 * yardstick_s():.1f} ms")


#: columns of the batch tables that change from one run of the same batch to the next
VOLATILE_COLUMNS = ("elapsed_s", "diag_elapsed_s", "worker")


def _table(folder: Path, stem: str):
    import pandas as pd

    pq = folder / f"{stem}.parquet"
    return pd.read_parquet(pq) if pq.exists() else pd.read_csv(folder / f"{stem}.csv")


def _page(path: Path) -> tuple[str, list]:
    """A diagnosis page's text (figures replaced by their index, its time masked) and the
    figures' pixels."""
    import base64
    import io
    import re

    import numpy as np
    from PIL import Image

    html = path.read_text()
    pngs = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", html)
    text = html
    for k, b in enumerate(pngs):
        text = text.replace(b, f"<figure {k}>", 1)
    text = re.sub(r"Diagnosis took [0-9.]+ s", "Diagnosis took T s", text)
    pixels = [np.asarray(Image.open(io.BytesIO(base64.b64decode(b)))) for b in pngs]
    return text, pixels


def compare_outputs(a: Path, b: Path) -> int:
    """``compare`` (module docstring): the differences printed; 0 when there are none."""
    import numpy as np

    diffs: list[str] = []
    for stem in ("fleet", "fleet_entries"):
        ta, tb = _table(a, stem), _table(b, stem)
        cols = [c for c in ta.columns if c not in VOLATILE_COLUMNS]
        if list(ta.columns) != list(tb.columns) or len(ta) != len(tb):
            diffs.append(f"{stem}: columns or row counts differ")
            continue
        for c in cols:
            x, y = ta[c].tolist(), tb[c].tolist()
            for i, (u, v) in enumerate(zip(x, y, strict=True)):
                same = u == v or (u != u and v != v)  # NaN == NaN here
                if not same:
                    diffs.append(f"{stem}[{i}].{c}: {u!r} != {v!r}")
    runs_a = sorted(p.name for p in (a / "runs").iterdir())
    runs_b = sorted(p.name for p in (b / "runs").iterdir())
    if runs_a != runs_b:
        diffs.append(f"runs differ: {runs_a} != {runs_b}")
    pages = 0
    for key in sorted(set(runs_a) & set(runs_b)):
        for name in ("fit.json", "diagnosis.json"):
            fa, fb = a / "runs" / key / name, b / "runs" / key / name
            if fa.exists() != fb.exists() or (fa.exists() and fa.read_bytes() != fb.read_bytes()):
                diffs.append(f"runs/{key}/{name} differs")
        ha, hb = a / "runs" / key / "diagnosis.html", b / "runs" / key / "diagnosis.html"
        if ha.exists() and hb.exists():
            (xa, pa), (xb, pb) = _page(ha), _page(hb)
            pages += 1
            if xa != xb:
                diffs.append(f"runs/{key}/diagnosis.html: text differs")
            if len(pa) != len(pb) or any(
                u.shape != v.shape or not np.array_equal(u, v) for u, v in zip(pa, pb, strict=False)
            ):
                diffs.append(f"runs/{key}/diagnosis.html: figures differ")
    for d in diffs:
        print(d)
    print(f"{len(runs_a)} runs, {pages} diagnosis pages compared: "
          f"{'identical' if not diffs else f'{len(diffs)} differences'}")  # fmt: skip
    return 1 if diffs else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    ta = sub.add_parser("tasks")
    ta.add_argument("files", type=Path, nargs="+")
    ta.add_argument("--command", default="diagnose", choices=("diagnose", "report"))
    sc = sub.add_parser("scaling")
    sc.add_argument("--n", type=int, default=8)
    de = sub.add_parser("detect")
    de.add_argument("--n", type=int, default=200)
    de.add_argument("--out", type=Path, required=True)
    de.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    co = sub.add_parser("compare")
    co.add_argument("dirs", type=Path, nargs=2)
    a = ap.parse_args()
    if a.what == "compare":
        sys.exit(compare_outputs(*a.dirs))
    if a.what == "scaling":
        scaling(a.n)
    elif a.what == "tasks":
        task_costs(a.command, a.files)
    else:
        detect(a.n, a.out, a.workers)


if __name__ == "__main__":
    main()
