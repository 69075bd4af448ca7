# Measured figures (full run of this script on the shared 2-core machine, 2026-11-25, load
# average about 1 from another process, so wall times vary by some tens of per cent):
#
#   experiments/paper.yaml on the simulated rig (paper truth, seed 7; 11 entries, 57.5 s
#   recorded, 87.5 s simulated as one run at 1 kHz):
#     fit_model (staged start + global + uncertainties)   1.68 s (40 model evaluations)
#     + leave-one-entry-out (11 warm-started refits)       5.9 s in all (4.3 s of it LOO)
#     Prandtl-Ishlinskii / Bouc-Wen, with LOO               0.55 s / 3.3 s
#     `labrig fit RUN` process / `--no-heldout`             8.1 s / 5.7 s
#     `labrig report RUN --params P` / `labrig report RUN`  15.5 s / 23.4 s
#     goal (fit under 30 s): met
#   where the fit's time goes (cProfile, cumulative, overlapping): hysteresis operator 46 %,
#     relaxor filtering 36 %, relaxor banks for new parameters 8 %; by phase: staged start
#     50 %, Jacobians 67 % (the staged stages' included), residual evaluations 24 %
#   recovery (same run): alpha0 -0.10 %, gamma -0.02 %, Vc -0.02 %, lam_t +0.0002,
#     tau_t -0.66 %, lam_d +0.0002, tau_d -0.00 %; NRMSE 0.331 % (held-out 0.331 %) against a
#     noise floor of 0.332 % (2.00 ue rms configured): ratio 1.00
#   hybrid truth (seed 7): NRMSE in-sample / held-out (%): ours 0.927 / 1.05,
#     Prandtl-Ishlinskii 5.48 / 6.05, Bouc-Wen 5.11 / 5.73 (noise floor 0.252 %)
#   micromanipulator (real, 2 files): ours 0.650 / 0.742, Prandtl-Ishlinskii 1.07 / 1.63,
#     Bouc-Wen 1.10 / 1.31 (noise floor 0.166 %, from the constant-voltage stretches)
#
"""Identification benchmarks and the "must show" numbers of the fit issue.

Run from the repository root (about 2-3 minutes on a loaded 2-core machine):

    .venv/bin/python benchmarks/bench_fit.py            # everything, markdown on stdout
    .venv/bin/python benchmarks/bench_fit.py --quick    # the timing section only, 1 repeat

Prints a report (stdout); nothing is written to benchmarks/RESULTS.md (owned by the model
benchmarks). Sections:

1. **Fit time of the paper's campaign**: ``experiments/paper.yaml`` (11 entries, 57.5 s recorded,
   90.5 s simulated with the 3 s rests, 1 kHz) run on the simulated rig (``paper`` truth, 2 ue
   gauge noise), then :func:`labrig.analysis.fit.fit_model` as ``labrig fit`` calls it
   (``chain=True``, global): the fit alone (staged start + global least squares + Jacobian for
   the uncertainties; best and median of repeats), the leave-one-entry-out on top, both
   baselines, and whole ``labrig fit`` and ``labrig report`` processes (imports included).
   Goal: the fit under 30 s.
2. **Where the time goes**: cProfile of one fit (no leave-one-out), grouped by what the code
   does (relaxor filtering, relaxor bank construction, hysteresis operator, least squares...),
   and the top functions by own time.
3. **Recovery on the paper truth**: fitted parameters against PAPER_TABLE1, NRMSE against the
   noise floor (the configured gauge noise and ADC quantisation in the run file).
4. **The hybrid truth** (the paper's section 4 reference plant; a copy of
   ``experiments/rigs/sim.yaml`` with ``truth.preset: hybrid``): NRMSE of our model and of
   both baselines, in-sample and held-out (leave-one-entry-out).
5. **Real data** (``tests/data/real/yan9a-micromanipulator``): the two
   files imported with ``--voltage 1 --strain 5 --rate-hz 200 --strain-units raw``; NRMSE of
   ours and of the baselines, in-sample and held-out (each file predicted by a fit on the
   other).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import platform
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "tests" / "data" / "real" / "yan9a-micromanipulator"
sys.path.insert(0, str(ROOT))

from labrig.analysis.baselines import KINDS, fit_baseline  # noqa: E402
from labrig.analysis.fit import PARAM_NAMES, fit_model  # noqa: E402
from labrig.analysis.load import records_from_run  # noqa: E402
from labrig.model import PAPER_TABLE1  # noqa: E402
from labrig.report.data import noise_floor  # noqa: E402
from labrig.store import read_run  # noqa: E402

LABRIG = [sys.executable, "-c", "from labrig.cli import app; app()"]
BASE_LABEL = {"prandtl_ishlinskii": "Prandtl-Ishlinskii", "bouc_wen": "Bouc-Wen"}

#: functions whose cumulative time the profile reports: (file name, function, what it is)
PARTS = (
    ("fit.py", "_staged", "staged start (seed 3.1 stages, each entry from rest)"),
    ("fit.py", "residuals", "model evaluations for the residuals"),
    ("fit.py", "jacobian", "Jacobians (structured: 4 relaxor columns by differences)"),
    ("fit.py", "_uncertainty", "uncertainties from the final Jacobian"),
    ("modal.py", "run_bank", "relaxor filtering (all calls)"),
    ("relaxor.py", "bank", "relaxor banks for new parameters (modes, quadrature)"),
    ("hysteresis.py", "apply", "hysteresis operator (all calls)"),
)


def cli(*args: str) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    proc = subprocess.run([*LABRIG, *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"labrig {' '.join(map(str, args))} failed:\n{proc.stderr}")
    return dt, proc


def run_campaign(tmp: Path, name: str, seed: int, rig: Path | None = None) -> Path:
    out = tmp / f"{name}.h5"
    extra = ["--rig", rig] if rig else []
    cli("run", ROOT / "experiments" / "paper.yaml", "--seed", seed, "--out", out, *extra)
    return out


def hybrid_rig(tmp: Path) -> Path:
    text = (ROOT / "experiments" / "rigs" / "sim.yaml").read_text()
    assert "preset: paper" in text
    rig = tmp / "sim-hybrid.yaml"
    rig.write_text(text.replace("preset: paper", "preset: hybrid", 1))
    return rig


def timed(fn, repeats: int) -> tuple[list[float], object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return times, out


def profile(fn) -> tuple[float, list[tuple[str, float]], list[tuple[str, float, int]]]:
    """Wall time, cumulative time of :data:`PARTS` and the top functions by own time."""
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    fn()
    prof.disable()
    total = time.perf_counter() - t0
    st = pstats.Stats(prof, stream=io.StringIO())
    cum: dict[str, float] = {}
    rows = []
    for (file, _line, func), (_cc, nc, tt, ct, _callers) in st.stats.items():  # type: ignore[attr-defined]
        rows.append((f"{Path(file).name}:{func}", tt, nc))
        for fname, f, label in PARTS:
            if Path(file).name == fname and func == f:
                cum[label] = cum.get(label, 0.0) + ct
    rows.sort(key=lambda x: -x[1])
    return total, [(label, cum.get(label, 0.0)) for _, _, label in PARTS], rows[:12]


def nrmse_row(label: str, res) -> str:
    held = res.heldout_nrmse_pct
    return f"| {label} | {res.nrmse_pct:.3g} | {'—' if held is None else f'{held:.3g}'} |"


def section_timing(tmp: Path, repeats: int) -> Path:
    print("## 1. Fit time of the paper's campaign (experiments/paper.yaml, simulated rig)\n")
    t_run, _ = cli("run", ROOT / "experiments" / "paper.yaml", "--seed", 7, "--out", tmp / "p.h5")
    run = tmp / "p.h5"
    recs = records_from_run(run)
    n = sum(r.n for r in recs)
    sim = n / 1000 + sum(float(r.meta.get("rest_after_s", 0)) for r in recs)
    print(f"{len(recs)} entries, {n} samples recorded, {sim:.1f} s simulated as one run "
          f"(`labrig run`: {t_run:.1f} s)\n")  # fmt: skip
    fit_times, res = timed(
        lambda: fit_model(recs, chain=True, heldout=False), repeats
    )  # fmt: skip
    t_held0 = time.perf_counter()
    full = fit_model(recs, chain=True, heldout=True)
    t_held = time.perf_counter() - t_held0
    base = {}
    for k in KINDS:
        t0 = time.perf_counter()
        fit_baseline(recs, k, heldout=True, chain=True)
        base[k] = time.perf_counter() - t0
    t_cli, _ = cli("fit", run, "--json", "--out", tmp / "params.json")
    t_cli_noho, _ = cli("fit", run, "--json", "--no-heldout")
    t_rep, _ = cli("report", run, "--params", tmp / "params.json", "--out", tmp / "r.html")
    t_rep_fit, _ = cli("report", run, "--out", tmp / "r2.html")
    print("| what | wall time (s) |")
    print("|---|---|")
    print(f"| fit (staged start + global + uncertainties), best of {repeats} | "
          f"{min(fit_times):.2f} (median {statistics.median(fit_times):.2f}, "
          f"{res.nfev} model evaluations) |")  # fmt: skip
    print(f"| fit + leave-one-entry-out (11 refits, warm-started) | {t_held:.2f} "
          f"(of which leave-one-out {full.heldout_elapsed_s:.2f}) |")  # fmt: skip
    for k in KINDS:
        print(f"| {BASE_LABEL[k]} baseline, with leave-one-out | {base[k]:.2f} |")
    print(f"| `labrig fit RUN --no-heldout` (whole process) | {t_cli_noho:.2f} |")
    print(f"| `labrig fit RUN` (whole process, with leave-one-out) | {t_cli:.2f} |")
    print(f"| `labrig report RUN --params P` (baselines, figures, HTML) | {t_rep:.2f} |")
    print(f"| `labrig report RUN` (fits everything first) | {t_rep_fit:.2f} |")
    ok = min(fit_times) < 30.0 and t_held < 30.0
    print(f"\nGoal (fit under 30 s): **{'met' if ok else 'NOT met'}**.\n")

    print("## 2. Where the time goes (cProfile of one fit, no leave-one-out)\n")
    total, parts, top = profile(lambda: fit_model(recs, chain=True, heldout=False))
    print(f"Profiled wall time {total:.2f} s (profiling overhead included). Cumulative times: "
          "the first four are phases of the fit, the last three the numerical kernels they "
          "call (so the rows overlap).\n")  # fmt: skip
    print("| part | cumulative time (s) | share of the fit |")
    print("|---|---|---|")
    for label, t in parts:
        print(f"| {label} | {t:.2f} | {100 * t / total:.0f} % |")
    print("\nTop functions by own time:\n")
    print("| function | own time (s) | calls |")
    print("|---|---|---|")
    for name, tt, nc in top:
        print(f"| `{name}` | {tt:.2f} | {nc} |")
    print()
    return run


def section_recovery(run: Path) -> None:
    print("## 3. Recovery on the paper truth (same run)\n")
    recs = records_from_run(run)
    res = fit_model(recs, chain=True, heldout=True)
    floor = noise_floor(recs, read_run(run, load_data=False).instrument)
    t = PAPER_TABLE1
    print("| parameter | truth | fitted | ± 1σ | error | criterion |")
    print("|---|---|---|---|---|---|")
    for k in PARAM_NAMES:
        a, b, u = getattr(t, k), getattr(res.params, k), res.uncertainty[k]
        if k.startswith("lam"):
            err, crit = f"{b - a:+.4f}", "within 0.03"
        else:
            err = f"{100 * (b / a - 1):+.2f} %"
            crit = "within 25 %" if k.startswith("tau") else "within 2 %"
        print(f"| {k} | {a:.4g} | {b:.4g} | {u:.2g} | {err} | {crit} |")
    print(f"\nNRMSE {res.nrmse_pct:.3f} % in-sample, {res.heldout_nrmse_pct:.3f} % held-out; "
          f"noise floor {floor.nrmse_pct:.3f} % ({floor.noise_ue:.2f} ue rms from "
          f"{floor.source}); ratio {res.nrmse_pct / floor.nrmse_pct:.3f} "
          "(criterion: at most 1.2).\n")  # fmt: skip


def compare_models(recs, **kw) -> list[str]:
    rows = ["| model | NRMSE in-sample (%) | NRMSE held-out (%) |", "|---|---|---|"]
    rows.append(nrmse_row("fractional-order model (ours)", fit_model(recs, heldout=True, **kw)))
    for k in KINDS:
        rows.append(nrmse_row(BASE_LABEL[k], fit_baseline(recs, k, heldout=True, **kw)))
    return rows


def section_hybrid(tmp: Path) -> None:
    print("## 4. Hybrid truth (the paper's section 4 reference plant) on the simulated rig\n")
    run = run_campaign(tmp, "hybrid", seed=7, rig=hybrid_rig(tmp))
    recs = records_from_run(run)
    floor = noise_floor(recs, read_run(run, load_data=False).instrument)
    print(f"`experiments/paper.yaml`, seed 7, 11 entries chained; noise floor "
          f"{floor.nrmse_pct:.3f} %.\n")  # fmt: skip
    print("\n".join(compare_models(recs, chain=True)))
    print()


def section_real(tmp: Path) -> None:
    print("## 5. Real data: piezo micromanipulator (yan9a/DiscreteBacklashOperator)\n")
    files = [REAL / "Model_Vi_Do.dat", REAL / "Test_Vi_Do_Di.dat"]
    if not all(f.is_file() for f in files):
        print(f"skipped: {REAL} not found\n")
        return
    run = tmp / "real.h5"
    cli("import", *files, "--out", run, "--voltage", "1", "--strain", "5", "--rate-hz", "200",
        "--strain-units", "raw")  # fmt: skip
    recs = records_from_run(run)
    floor = noise_floor(recs, {}, warmup_s=2.0)
    print("Imported with `--voltage 1 --strain 5 --rate-hz 200 --strain-units raw` (DAQ-level "
          "volts, raw sensor units); each file on its own, 2 s warm-up, one offset per entry "
          "(as `labrig fit` chooses); held-out = predicted by a fit on the other file. Noise "
          f"floor {floor.nrmse_pct:.3f} % ({floor.source}).\n")  # fmt: skip
    print("\n".join(compare_models(recs, warmup_s=2.0, offset=True)))
    print()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="timing section only, one repeat")
    args = ap.parse_args()
    print("# Fit benchmarks\n")
    print(f"{platform.platform()}, Python {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f} at start\n")  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        run = section_timing(tmp, 1 if args.quick else 3)
        if not args.quick:
            section_recovery(run)
            section_hybrid(tmp)
            section_real(tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
