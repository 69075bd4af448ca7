"""Measured cost of compensation control (:mod:`labrig.control`): benchmarks, not timed tests.

Run from the repository root (about 1 minute on a 2-core machine):

    .venv/bin/python benchmarks/bench_control.py            # full run, prints a Markdown report
    .venv/bin/python benchmarks/bench_control.py --quick    # smoke run (fewer samples)
    .venv/bin/python benchmarks/bench_control.py --out FILE # also write the report to FILE

What is measured (nothing is typed by hand; RESULTS.md is not touched):

1. The per-sample controller (:class:`CompensationController`, what a real-time loop would run):
   wall time of ``step()`` per sample, mean over a whole command and the median / 99th
   percentile / maximum of individually timed steps, at 1 kHz and 10 kHz, against the 100 us
   budget of a 10 kHz loop; the split into the creep inverse, the static inverse (the operator
   alone and with the fitted remanence, which the controller runs) and the two relaxor stages;
   the direct controller for comparison. Parameters: experiments/hybrid-params.json (the fit the
   control example uses, with its viscoelastic creep and remanence). Command: a 0-1000 ue
   unipolar sine at 10 Hz.
2. Its agreement with the offline drive (:func:`compensated_drive`): max |V_step - V_offline|.
3. The offline drive's time for 1e4, 1e5 and 1e6 samples, and how exactly it inverts the model:
   ``predict(compensated_drive(S)) - S`` for 0-1000 ue sines at 1-40 Hz (max over the record,
   max after the first 0.1 s), in % of the command span.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

if "numpy" not in sys.modules:  # one BLAS thread: small products, a shared machine
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import numpy as np

from labrig.control import (
    CompensationController,
    ControlModel,
    DirectController,
    compensated_drive,
    load_control_model,
    model_tracking_error,
)
from labrig.control.static_inverse import StaticInverseStepper

ROOT = Path(__file__).resolve().parents[1]
BUDGET_NS = 100_000  # 10 kHz loop


def sine(f_hz: float, seconds: float, rate_hz: float, amp_ue: float = 1000.0) -> np.ndarray:
    t = np.arange(round(seconds * rate_hz) + 1) / rate_hz
    return 0.5 * amp_ue * (1.0 - np.cos(2 * np.pi * f_hz * t))


def time_steps(ctl, s: np.ndarray) -> dict[str, float]:
    """Per-sample cost of ``ctl.step`` over the command ``s``: loop mean and per-step stats."""
    n, p = s.size, ctl.preview
    ext = np.concatenate((s, np.full(p, s[-1])))
    # whole loop (what a loop costs on average)
    ctl.reset()
    ctl.prime(ext[:p])
    step = ctl.step
    t0 = time.perf_counter_ns()
    for k in range(n):
        step(ext[k + p])
    loop = (time.perf_counter_ns() - t0) / n
    # individually timed steps (jitter)
    ctl.reset()
    ctl.prime(ext[:p])
    clock = time.perf_counter_ns
    d = np.empty(n)
    for k in range(n):
        a = clock()
        step(ext[k + p])
        d[k] = clock() - a
    return {
        "mean_ns": loop,
        "median_ns": float(np.median(d)),
        "p99_ns": float(np.percentile(d, 99)),
        "max_ns": float(np.max(d)),
        "over_budget": float(np.mean(d > BUDGET_NS)),
    }


def stage_split(params: ControlModel, rate_hz: float, s: np.ndarray) -> dict[str, float]:
    """Mean ns per sample of the static inverse and of each relaxor stage alone."""
    ctl = CompensationController(params, rate_hz)
    p = params.params
    t0 = time.perf_counter_ns()
    for x in s:
        ctl.uncreep(float(x))
    t_creep = (time.perf_counter_ns() - t0) / s.size
    op = p.operator()
    st = StaticInverseStepper(op)
    t0 = time.perf_counter_ns()
    u = [st.step(x) for x in s]
    t_static = (time.perf_counter_ns() - t0) / s.size
    st_full = ctl.static_inverse  # with the fitted remanence, if any
    st_full.reset()
    t0 = time.perf_counter_ns()
    u = [st_full.step(x) for x in s]
    t_full = (time.perf_counter_ns() - t0) / s.size
    gd, gt = ctl.gd_inverse, ctl.gt_inverse
    gd.reset()
    t0 = time.perf_counter_ns()
    vt = [gd.push(x) for x in u]
    t_gd = (time.perf_counter_ns() - t0) / s.size
    vt = [x for x in vt if x is not None]
    gt.reset()
    t0 = time.perf_counter_ns()
    for x in vt:
        gt.push(x)
    t_gt = (time.perf_counter_ns() - t0) / max(1, len(vt))
    return {
        "creep": t_creep,
        "static": t_static,
        "static_full": t_full,
        "G_d": t_gd,
        "G_t": t_gt,
        "modes_d": gd.n_modes,
        "modes_t": gt.n_modes,
    }


Say = Callable[..., None]


def per_sample_section(params: ControlModel, seconds: float, say: Say) -> None:
    """1. The per-sample controller's cost at 1 and 10 kHz, its stages, the direct controller."""
    say("## Per-sample controller (`CompensationController.step`), 0-1000 ue sine at 10 Hz")
    say()
    say(
        "| rate | preview (samples) | modes G_d / G_t | mean ns/sample | median | p99 | max | "
        "share > 100 us | keeps up with 10 kHz |"
    )
    say("|---|---|---|---|---|---|---|---|---|")
    split_rows = []
    for rate in (1000.0, 10000.0):
        s = sine(10.0, seconds if rate == 1000.0 else seconds / 4, rate)
        ctl = CompensationController(params, rate)
        r = time_steps(ctl, s)
        sp = stage_split(params, rate, s[: min(s.size, 4000)])
        split_rows.append((rate, sp))
        ok = "yes" if r["mean_ns"] < BUDGET_NS and r["p99_ns"] < BUDGET_NS else "no"
        say(
            f"| {rate / 1000:g} kHz | {ctl.preview} ({ctl.preview / rate * 1e3:.3g} ms) | "
            f"{sp['modes_d']} / {sp['modes_t']} | {r['mean_ns']:,.0f} | {r['median_ns']:,.0f} | "
            f"{r['p99_ns']:,.0f} | {r['max_ns']:,.0f} | {100 * r['over_budget']:.2f} % | {ok} |"
        )
    s = sine(10.0, seconds, 1000.0)
    r = time_steps(DirectController(params, 1000.0), s)
    say(
        f"| direct, 1 kHz | 1 | - | {r['mean_ns']:,.0f} | {r['median_ns']:,.0f} | "
        f"{r['p99_ns']:,.0f} | {r['max_ns']:,.0f} | {100 * r['over_budget']:.2f} % | yes |"
    )
    say()
    say("Split of the compensated step (mean ns per sample, each stage run alone):")
    say()
    say(
        "| rate | creep^-1 | static inverse: operator alone | operator + remanence (used) "
        "| G_d^-1 (linear hold, anti-causal zero) | G_t^-1 (ZOH) |"
    )
    say("|---|---|---|---|---|---|")
    for rate, sp in split_rows:
        say(
            f"| {rate / 1000:g} kHz | {sp['creep']:,.0f} | {sp['static']:,.0f} | "
            f"{sp['static_full']:,.0f} | {sp['G_d']:,.0f} | {sp['G_t']:,.0f} |"
        )
    say()


def agreement_section(params: ControlModel, say: Say) -> None:
    """2. The per-sample drive against the offline one."""
    say("## Per-sample versus offline drive")
    say()
    say("| command | max abs(V_step - V_offline) (V) | drive range (V) |")
    say("|---|---|---|")
    for f in (1.0, 40.0):
        s = sine(f, 5.0 if f == 1.0 else 1.0, 1000.0)
        v_off = compensated_drive(s, params, 1000.0)
        v_ps = CompensationController(params, 1000.0).run(s)
        say(
            f"| 0-1000 ue, {f:g} Hz, 1 kHz | {np.max(np.abs(v_ps - v_off)):.2e} | "
            f"{v_off.min():.2f} to {v_off.max():.2f} |"
        )
    say()


def offline_section(params: ControlModel, quick: bool, say: Say) -> None:
    """3. The offline drive's time and how exactly it inverts the model."""
    say("## Offline drive (`compensated_drive`)")
    say()
    say("| samples | time (s) |")
    say("|---|---|")
    for n in (10_000, 100_000) if quick else (10_000, 100_000, 1_000_000):
        s = sine(10.0, (n - 1) / 1000.0, 1000.0)
        times = []
        for _ in range(3 if n <= 100_000 else 1):
            t0 = time.perf_counter()
            compensated_drive(s, params, 1000.0)
            times.append(time.perf_counter() - t0)
        say(f"| {n:,} | {min(times):.3g} |")
    say()
    say(
        "How exactly the drive inverts the model: `predict(compensated_drive(S)) - S` "
        "(`predict` fast method), 0-1000 ue sine, 1 kHz, % of the command span:"
    )
    say()
    say("| frequency (Hz) | max over the record | at sample | max after 0.1 s | RMS |")
    say("|---|---|---|---|---|")
    for f in (1, 5, 10, 20, 40):
        s = sine(float(f), max(2.0, 5.0 / f), 1000.0)
        e = model_tracking_error(s, params, 1000.0)
        say(
            f"| {f} | {100 * np.max(np.abs(e)) / 1000:.1e} | {int(np.argmax(np.abs(e)))} | "
            f"{100 * np.max(np.abs(e[100:])) / 1000:.1e} | "
            f"{100 * np.sqrt(np.mean(e**2)) / 1000:.1e} |"
        )
    say()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer samples (smoke run)")
    ap.add_argument("--out", type=Path, default=None, help="also write the report here")
    args = ap.parse_args(argv)
    # the model and the creep and remanence fitted with it (labrig fit --effect)
    params = load_control_model(ROOT / "experiments" / "hybrid-params.json")
    lines: list[str] = []

    def say(s: str = "") -> None:
        lines.append(s)
        print(s, flush=True)

    say("# Compensation control: cost and accuracy")
    say()
    say(
        f"{platform.python_implementation()} {platform.python_version()}, numpy "
        f"{np.__version__}, {platform.machine()}, {os.cpu_count()} CPUs, load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at start; one BLAS thread. "
        f"Parameters: experiments/hybrid-params.json."
    )
    say()
    seconds = 1.0 if args.quick else 4.0

    per_sample_section(params, seconds, say)
    agreement_section(params, say)
    offline_section(params, args.quick, say)
    say(f"Load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}.")
    if args.out:
        args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
