"""The peers' cost: Prandtl-Ishlinskii, Bouc-Wen and SINDy as `labrig report` fits them.

Run from the repository root (about 3 minutes on a loaded 2-core machine):

    .venv/bin/python benchmarks/bench_baselines.py                 # against commit 6fe3c46
    .venv/bin/python benchmarks/bench_baselines.py --before REV    # against another commit
    .venv/bin/python benchmarks/bench_baselines.py --quick         # this tree only, 1 repeat
    .venv/bin/python benchmarks/bench_baselines.py --report-phases RUN.h5  # report, step by step
                                                         # (--repeats N: N + 1 processes)

Prints a report in markdown (stdout); the figures of record are copied into the "Baselines"
section of benchmarks/RESULTS.md by hand. What is measured, and how:

- **Data**: ``experiments/paper.yaml`` run on the simulated rig with ``--seed 1`` (11 entries,
  57 511 scored samples, 87 512 simulated with the rests: a chain, no offset), and the real
  record ``tests/data/real/yan9a-micromanipulator/Model_Vi_Do.dat`` imported with
  ``--voltage 1 --strain 5 --rate-hz 200`` (one entry of 8 027 samples: on its own, a 2 s
  warm-up, one offset; a single entry has no held-out score). Each is prepared as
  ``labrig fit`` and ``labrig report`` prepare it (:func:`labrig.commands.prepare.prepare`).
- **Implementations**: this tree, and the previous one (``--before REV``, default the commit
  before the compiled kernels), its ``labrig/`` extracted with ``git archive`` into a
  temporary folder and imported from there, in the same environment.
- **CPU seconds** (``time.process_time`` in a child process per implementation and dataset;
  one BLAS thread as the fits set it): each peer fitted with leave-one-entry-out
  (:func:`labrig.analysis.baselines.fit_baseline`, the call ``labrig report`` makes), the
  first fit in a fresh process (imports and compiled-kernel loading included: numba for this
  tree, pysindy and scikit-learn for the previous one's SINDy) and the best of the repeats
  after it. The yardstick, timed in the same child: ``numpy.sort`` of 1e6 floats, best of 5;
  costs are also given as multiples of it, which the machine's load moves less than seconds.
- **numba's fixed cost** in a fresh process: ``import numba`` and the first call of a cached
  kernel (shared by every compiled kernel of the process).
- **Whole processes**: ``labrig fit RUN --model KIND --json`` for each peer (interpreter start,
  imports, reading the run file, the fit, held-out included), CPU of the child process
  (user + system, ``resource.getrusage``).
- **Agreement**: for each peer and dataset, the largest relative difference between the two
  implementations of the mean NRMSE, the per-entry NRMSE (in-sample and held-out) and the
  fitted parameters; for SINDy whether the same terms are kept.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from yardstick import yardstick_s

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "tests" / "data" / "real" / "yan9a-micromanipulator" / "Model_Vi_Do.dat"
KINDS = ("prandtl_ishlinskii", "bouc_wen", "sindy")
LABEL = {"prandtl_ishlinskii": "Prandtl-Ishlinskii", "bouc_wen": "Bouc-Wen", "sindy": "SINDy"}
#: the last commit before the compiled kernels of the baselines
DEFAULT_BEFORE = "6fe3c46"


# -- the child: one implementation, one dataset --------------------------------------------------


def child(src: str, run: str, repeats: int) -> dict:
    """Fit every peer on ``run`` with the labrig found in ``src``; CPU seconds and results."""
    sys.path.insert(0, src)

    from labrig.analysis.baselines import fit_baseline
    from labrig.commands.prepare import prepare

    assert Path(sys.modules["labrig"].__file__).is_relative_to(src), "wrong labrig imported"

    s = prepare(Path(run))
    out: dict = {"yardstick_s": yardstick_s(), "kinds": {}}
    for kind in KINDS:
        times, res = [], None
        for _ in range(1 + repeats):
            t0 = time.process_time()
            res = fit_baseline(
                s.records,
                kind,
                heldout=True,
                warmup_s=s.warmup_s,
                chain=s.chain,
                scored=s.scored,
                offset=s.offset,
            )
            times.append(time.process_time() - t0)
        out["kinds"][kind] = {
            "first_s": times[0],
            "best_s": min(times[1:]) if repeats else times[0],
            "nrmse": res.nrmse_pct,
            "per_entry": res.per_entry,
            "heldout": res.heldout_nrmse_pct,
            "heldout_per_entry": res.heldout_per_entry,
            "params": res.params,
        }
    out["yardstick_end_s"] = yardstick_s()
    return out


def numba_child() -> dict:
    """``import numba`` and the first call of a cached kernel, in a fresh process."""
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from labrig.analysis.baseline_kernels import play_operators

    t0 = time.process_time()
    import numba  # noqa: F401

    t1 = time.process_time()
    play_operators(np.array([0.0, 1.0, 0.5]), np.array([0.0, 0.2]))
    return {"import_s": t1 - t0, "first_call_s": time.process_time() - t1}


# -- the parent ----------------------------------------------------------------------------------


def run_child(args: list[str]) -> dict:
    proc = subprocess.run(
        [sys.executable, __file__, *args], capture_output=True, text=True, cwd=ROOT, check=False
    )
    if proc.returncode != 0:
        raise SystemExit(f"child {args} failed:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def cli_cpu(src: Path, *args: str) -> float:
    """CPU seconds (user + system) of a whole ``labrig`` process run from ``src``."""
    code = f"import sys; sys.path.insert(0, {str(src)!r}); from labrig.cli import app; app()"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=ROOT, check=False
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"labrig {' '.join(args)} failed:\n{proc.stderr}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def extract(rev: str, dest: Path) -> Path:
    """``labrig/`` of commit ``rev`` into ``dest`` (git archive)."""
    tar = dest / "src.tar"
    with tar.open("wb") as f:
        subprocess.run(["git", "archive", rev, "labrig"], cwd=ROOT, stdout=f, check=True)
    with tarfile.open(tar) as t:
        t.extractall(dest / "src", filter="data")
    return dest / "src"


def rel(a: float, b: float) -> float:
    return abs(a - b) / max(abs(a), 1e-300)


def agreement(a: dict, b: dict) -> dict:
    """Largest relative differences between two children's results for one peer."""
    out = {
        "nrmse": rel(a["nrmse"], b["nrmse"]),
        "per_entry": max(rel(a["per_entry"][n], b["per_entry"][n]) for n in a["per_entry"]),
    }
    if a["heldout"] is not None:
        out["heldout"] = rel(a["heldout"], b["heldout"])
        ha, hb = a["heldout_per_entry"], b["heldout_per_entry"]
        out["heldout_per_entry"] = max(rel(ha[n], hb[n]) for n in ha)
    worst = 0.0
    for k, x in a["params"].items():
        y = b["params"][k]
        xs, ys = (x, y) if isinstance(x, list) else ([x], [y])
        if xs and all(isinstance(v, int | float) for v in xs):
            if len(xs) != len(ys):
                worst = float("inf")
                continue
            big = max(abs(v) for v in xs) or 1.0
            worst = max(
                worst, *(abs(p - q) / max(abs(p), 1e-12 * big) for p, q in zip(xs, ys, strict=True))
            )
    out["params"] = worst
    if "terms" in a["params"]:
        out["same_terms"] = a["params"]["terms"] == b["params"]["terms"]
    return out


def report_phases(run: str) -> list[tuple[str, float]]:
    """``--report-phases RUN``: the CPU seconds of each step of ``labrig report RUN --out ...``
    in this process (``time.process_time``; the file is read in a child process, not counted),
    as :func:`labrig.commands.report.build_run_report` runs them (with one BLAS thread, as it
    sets): imports, our model's fit with leave-one-entry-out, each peer with its own, the
    metrics, the figures and the page."""
    t0 = time.process_time()
    steps: list[tuple[str, float]] = []

    def lap(name: str) -> None:
        nonlocal t0
        t = time.process_time()
        steps.append((name, t - t0))
        t0 = t

    from labrig.commands.fit import fit_dynamic
    from labrig.commands.prepare import prepare
    from labrig.commands.report import fit_report_models, metrics_table, render_page, report_data
    from labrig.core.blas import single_thread_blas

    lap("import numpy, labrig's report command (scipy.optimize, h5py, numba)")
    setup = prepare(Path(run), None, None, None)
    lap("read the run file (its child's CPU not counted)")
    with single_thread_blas():
        ours = fit_dynamic(setup, "global", True, None)
        lap("our model: fit with leave-one-entry-out")

        def progress(stage: str, done: int, total: int) -> None:
            if stage in KINDS and done == total:  # a peer fitted, with its held-out folds
                lap(f"{LABEL[stage]} with leave-one-entry-out (first in the process: its imports)")

        fitted = fit_report_models(setup, None, None, "global", True, progress, ours)
        data = report_data(setup, fitted, True, False)
        metrics_table(setup, data)
        lap("the metrics (report --json)")
        render_page(setup, data)
        lap("the figures and the page (matplotlib imported here)")
    return steps


def report_phases_table(run: str, repeats: int) -> None:
    """The steps of :func:`report_phases` in ``repeats`` fresh processes: median and range of
    each, with the yardstick (``numpy.sort`` of 1e6 floats, CPU, best of 5 in this process)
    and the load average before and after."""

    load0, y0 = os.getloadavg()[0], yardstick_s()
    runs = [run_child(["--phases-child", run]) for _ in range(repeats)]
    load1, y1 = os.getloadavg()[0], yardstick_s()
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"{when}, {run}: load {load0:.1f} -> {load1:.1f}, yardstick {1e3 * y0:.1f} / "
          f"{1e3 * y1:.1f} ms; {repeats} processes\n")  # fmt: skip
    print("| step | CPU s, median (range) |\n|---|---|")
    names = [n for n, _ in runs[0]]
    for i, name in enumerate(names):
        xs = sorted(r[i][1] for r in runs)
        print(f"| {name} | {xs[len(xs) // 2]:.2f} ({xs[0]:.2f}-{xs[-1]:.2f}) |")
    tot = sorted(sum(dt for _, dt in r) for r in runs)
    print(f"| **in all** | **{tot[len(tot) // 2]:.2f}** ({tot[0]:.2f}-{tot[-1]:.2f}) |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default=DEFAULT_BEFORE, help="commit to compare with")
    ap.add_argument("--repeats", type=int, default=2, help="fits after the first, per peer")
    ap.add_argument("--quick", action="store_true", help="this tree only, one repeat, no CLI")
    ap.add_argument("--report-phases", metavar="RUN", help="the steps of labrig report RUN")
    ap.add_argument("--phases-child", metavar="RUN", help=argparse.SUPPRESS)
    ap.add_argument("--child", nargs=3, metavar=("SRC", "RUN", "REPEATS"), help=argparse.SUPPRESS)
    ap.add_argument("--numba-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.report_phases:
        report_phases_table(args.report_phases, 1 if args.quick else args.repeats + 1)
        return 0
    if args.phases_child:
        print(json.dumps(report_phases(args.phases_child)))
        return 0
    if args.child:
        print(json.dumps(child(args.child[0], args.child[1], int(args.child[2]))))
        return 0
    if args.numba_child:
        print(json.dumps(numba_child()))
        return 0

    repeats = 1 if args.quick else args.repeats
    load0 = os.getloadavg()
    t_start = time.time()
    print("# Baselines benchmark\n")
    print(
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {platform.platform()}, "
        f"Python {platform.python_version()}, {os.cpu_count()} CPUs; load average "
        f"{load0[0]:.1f} / {load0[1]:.1f} / {load0[2]:.1f} at start\n"
    )
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        paper, real = tmp / "paper1.h5", tmp / "real.h5"
        labrig = [sys.executable, "-c", "from labrig.cli import app; app()"]
        subprocess.run([*labrig, "run", "experiments/paper.yaml", "--seed", "1", "--out",
                        str(paper)], cwd=ROOT, check=True, capture_output=True)  # fmt: skip
        subprocess.run([*labrig, "import", str(REAL), "--out", str(real), "--voltage", "1",
                        "--strain", "5", "--rate-hz", "200"], cwd=ROOT, check=True,
                       capture_output=True)  # fmt: skip
        impls = {"after": ROOT}
        if not args.quick:
            impls["before"] = extract(args.before, tmp)
        datasets = {"paper campaign (seed 1)": paper, "real record Model_Vi_Do": real}
        # a first child compiles the kernels if their cache is missing (not measured)
        run_child(["--child", str(ROOT), str(real), "0"])
        res = {
            (impl, ds): run_child(["--child", str(src), str(run), str(repeats)])
            for ds, run in datasets.items()
            for impl, src in impls.items()
        }
        nb = [run_child(["--numba-child"]) for _ in range(3)]
        cli = {}
        if not args.quick:
            for impl, src in impls.items():
                for kind in KINDS:
                    cli[impl, kind] = cli_cpu(src, "fit", str(paper), "--model", kind, "--json")

    print("## CPU seconds of each peer with leave-one-entry-out (`fit_baseline`)\n")
    print("Best of the repeats after the first fit in the process (in parentheses: the first "
          "fit, one-time imports and kernel loading included); x: multiples of the yardstick "
          "(`numpy.sort` of 1e6 floats) timed in the same process.\n")  # fmt: skip
    head = " | ".join(f"{LABEL[k]}" for k in KINDS)
    print(f"| dataset | code | yardstick | {head} | sum of the three |")
    print("|---|---|---|" + "---|" * len(KINDS) + "---|")
    for ds in datasets:
        for impl in impls:
            r = res[impl, ds]
            y = r["yardstick_s"]
            cells = [
                f"{r['kinds'][k]['best_s']:.3f} s = {r['kinds'][k]['best_s'] / y:.0f} x "
                f"({r['kinds'][k]['first_s']:.2f} s)"
                for k in KINDS
            ]
            tot = sum(r["kinds"][k]["best_s"] for k in KINDS)
            tot1 = sum(r["kinds"][k]["first_s"] for k in KINDS)
            print(f"| {ds} | {impl} | {y * 1e3:.1f} ms | {' | '.join(cells)} | "
                  f"{tot:.2f} s = {tot / y:.0f} x ({tot1:.2f} s) |")  # fmt: skip
    if "before" in impls:
        print()
        for ds in datasets:
            ra, rb = res["after", ds], res["before", ds]
            ratio = [
                (rb["kinds"][k]["best_s"] / rb["yardstick_s"])
                / (ra["kinds"][k]["best_s"] / ra["yardstick_s"])
                for k in KINDS
            ]
            print(f"- {ds}: speed-up (in yardsticks) " + ", ".join(
                f"{LABEL[k]} {x:.0f}x" for k, x in zip(KINDS, ratio, strict=True)))  # fmt: skip
    imp = sorted(n["import_s"] for n in nb)
    first = sorted(n["first_call_s"] for n in nb)
    print(f"\nnumba in a fresh process (3 processes, median): `import numba` {imp[1]:.2f} s, "
          f"first call of a cached kernel {first[1]:.2f} s CPU (once per process, shared by "
          "every compiled kernel).\n")  # fmt: skip
    if cli:
        print("## Whole `labrig fit paper1.h5 --model KIND --json` processes (CPU s)\n")
        print("| peer | before | after |")
        print("|---|---|---|")
        for kind in KINDS:
            print(f"| {LABEL[kind]} | {cli['before', kind]:.2f} | {cli['after', kind]:.2f} |")
        print()
    if "before" in impls:
        print("## Agreement with the previous implementation (largest relative difference)\n")
        print("| dataset | peer | mean NRMSE | per-entry NRMSE | held-out mean | held-out per "
              "entry | parameters | same SINDy terms |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|")
        for ds in datasets:
            for kind in KINDS:
                a = res["before", ds]["kinds"][kind]
                g = agreement(a, res["after", ds]["kinds"][kind])
                print(f"| {ds} | {LABEL[kind]} | {g['nrmse']:.1e} | {g['per_entry']:.1e} | "
                      f"{g.get('heldout', float('nan')):.1e} | "
                      f"{g.get('heldout_per_entry', float('nan')):.1e} | {g['params']:.1e} | "
                      f"{g.get('same_terms', '-')} |")  # fmt: skip
        print("\nNRMSE (%), before -> after:\n")
        print("| dataset | peer | in-sample | held-out |")
        print("|---|---|---|---|")
        for ds in datasets:
            for kind in KINDS:
                a, b = res["before", ds]["kinds"][kind], res["after", ds]["kinds"][kind]
                held = ("-" if a["heldout"] is None
                        else f"{a['heldout']:.10g} -> {b['heldout']:.10g}")  # fmt: skip
                print(f"| {ds} | {LABEL[kind]} | {a['nrmse']:.10g} -> {b['nrmse']:.10g} | "
                      f"{held} |")  # fmt: skip
    load1 = os.getloadavg()
    print(f"\nLoad average at the end {load1[0]:.1f} / {load1[1]:.1f} / {load1[2]:.1f}; "
          f"benchmark run time {time.time() - t_start:.0f} s.")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
