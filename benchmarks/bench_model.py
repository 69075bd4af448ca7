"""Measured performance of :mod:`labrig.model` (benchmarks, not timed tests).

Run from the repository root (about 6-10 minutes on a loaded 2-core machine; ~1.5 GB peak
memory at N = 1e7 with the exact method):

    .venv/bin/python benchmarks/bench_model.py            # full run, rewrites benchmarks/RESULTS.md
    .venv/bin/python benchmarks/bench_model.py --quick    # smoke run (small N), stdout only
    .venv/bin/python -m benchmarks                         # same as the full run
    benchmarks/run.sh                                      # same as the full run

Every time is CPU time of this process (``time.process_time``, one BLAS thread) unless said
otherwise, and every predict timing is paired with a **yardstick** timed right after it in the
same loop: ``numpy.sort`` of 1e6 random floats. On a shared machine the CPU time still moves
with the load (cache and memory bandwidth, a busy sibling hyperthread); the ratio to the
yardstick moves much less, and is what to compare across runs and machines.

What is measured (each section of RESULTS.md is produced here, nothing is typed by hand):

1. ``DynamicHysteresisModel(PAPER_TABLE1).predict`` with ``method="fast"`` (the compiled model
   in one pass), the same through ``ModelStream`` blocks, the **previous fast path** (the
   Gauss-Legendre banks of ``previous_quadrature.py``, 242 + 285 modes, run by the numpy block
   realisation, and the numpy operator) and ``method="exact"``, at N = 1e4, 1e6, 1e7 samples of
   a 0-100 V unipolar sine sweep (1 -> 40 Hz, linear chirp repeated every 10 s) at 1 kHz;
   agreement of fast with the numpy stages, with exact and with the previous banks; the cost of
   each stage alone; the banks' recursion compiled against the numpy (BLAS) blocks at the new
   and the previous bank sizes.
2. The relaxor banks: mode counts and max error against ``exact`` (unit step, 1e5 samples;
   zero-order and linear hold) for lam in {0.1, 0.15, 0.3, 0.5, 0.8, 0.95, 1.05, 1.2, 1.5,
   1.8} at 1 kHz and 10 kHz, new quadrature and previous.
3. Compilation: numba's cold compile and cached load in fresh processes (a temporary
   ``NUMBA_CACHE_DIR``), where the cache goes by default, and ``labrig --help``'s start.
4. The Grunwald-Letnikov scheme FOMCON's ``lsim`` uses (full memory, implicit, first order),
   written plainly below (:func:`gl_relaxor`), against our ``exact`` and ``fast`` filters on
   the paper's G_t and G_d at 1 kHz (time and error), after a convergence check of the GL code.
5. Per-sample cost of the steppers, the operator and ``ModelStream.process`` on one-sample
   blocks, against the 100 us budget of a 10 kHz loop.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import gc
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

# One BLAS thread unless --blas-default: the numpy block realisation's matrix products are
# small and gain little from threads, while on a shared 2-core machine OpenBLAS threads that
# compete with another process slow it down by up to 3x. Must be set before numpy is imported.
BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
if "--blas-default" not in sys.argv and "numpy" not in sys.modules:
    for _var in BLAS_VARS:
        os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import scipy  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))
if str(ROOT / "benchmarks") not in sys.path:
    sys.path.insert(0, str(ROOT / "benchmarks"))

from previous_quadrature import previous_modes  # noqa: E402

from labrig.model import (  # noqa: E402
    PAPER_TABLE1,
    DynamicHysteresisModel,
    HysteresisState,
    Relaxor,
)
from labrig.model.modal import compact_form, run_bank  # noqa: E402

RATE_HZ = 1000.0
G_T = Relaxor(PAPER_TABLE1.tau_t_s, PAPER_TABLE1.lam_t)  # 15.5e-5 s, 0.15
G_D = Relaxor(PAPER_TABLE1.tau_d_s, PAPER_TABLE1.lam_d)  # 2e-3 s, 1.35
GOAL_FAST = 2e7  # samples/s at N = 1e6 and 1e7 (labrig issue 25)
GOAL_EXACT = 2e6
YARDSTICK_N = 1_000_000
FULL_SCALE_V = 100.0


# -- helpers -------------------------------------------------------------------------------------


@dataclass
class Timing:
    times: list[float]  # wall clock (perf_counter)
    cpu: list[float]  # CPU time of this process (process_time): robust to time-slicing

    @property
    def cpu_best(self) -> float:
        return min(self.cpu)

    @property
    def best(self) -> float:
        return min(self.times)

    @property
    def median(self) -> float:
        return statistics.median(self.times)


def timeit(fn: Callable[[], object], repeats: int) -> Timing:
    times, cpu = [], []
    for _ in range(repeats):
        gc.collect()
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return Timing(times, cpu)


def sweep_input(n: int, rate_hz: float = RATE_HZ, period_s: float = 10.0) -> np.ndarray:
    """0-100 V unipolar sine, frequency a linear chirp 1 -> 40 Hz repeated every ``period_s``."""
    t = np.arange(n) / rate_hz
    f = 1.0 + 39.0 * (t % period_s) / period_s
    phase = 2 * np.pi * np.cumsum(f) / rate_hz
    phase -= phase[0]
    return 50.0 * (1.0 - np.cos(phase))


def fmt_rate(x: float) -> str:
    return f"{x:.2e}"


def fmt_time(s: float) -> str:
    if s < 1e-3:
        return f"{s * 1e6:.0f} us"
    if s < 1:
        return f"{s * 1e3:.1f} ms"
    return f"{s:.2f} s"


def machine_info() -> dict[str, str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    def git(*args: str) -> str:
        try:
            return subprocess.run(
                ["git", *args], cwd=ROOT, capture_output=True, text=True, check=True
            ).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return "?"

    dirty = git("status", "--porcelain", "--", "labrig/model")
    blas = "?"
    try:
        cfg = np.show_config(mode="dicts")
        b = cfg["Build Dependencies"]["blas"]
        blas = f"{b.get('name', '?')} {b.get('version', '')}".strip()
    except Exception:
        pass
    return {
        "date": _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "blas": blas,
        "os": platform.platform(),
        "commit": git("rev-parse", "--short", "HEAD")
        + (" + uncommitted changes in labrig/model" if dirty else ""),
        "load": " / ".join(f"{x:.2f}" for x in os.getloadavg()),
        "blas threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        "numba": _numba_version(),
    }


def _numba_version() -> str:
    try:
        import numba

        return str(numba.__version__)
    except ImportError:
        return "not installed (numpy fallback)"


# -- 1. predict throughput -----------------------------------------------------------------------

_YARD = np.random.default_rng(0).random(YARDSTICK_N)


def yardstick() -> float:
    """CPU seconds of one ``numpy.sort`` of 1e6 random floats."""
    c0 = time.process_time()
    np.sort(_YARD)
    return time.process_time() - c0


@dataclass
class Paired:
    cpu: list[float]  # CPU seconds of the call
    wall: list[float]
    yard: list[float]  # the yardstick right after each call

    def row(self, n: int) -> dict:
        cb, cm = min(self.cpu), statistics.median(self.cpu)
        yb, ym = min(self.yard), statistics.median(self.yard)
        return {"n": n, "repeats": len(self.cpu), "cpu_best": cb, "cpu_median": cm,
                "wall_best": min(self.wall), "rate_cpu": n / cb, "rate_cpu_median": n / cm,
                "yard_best": yb, "yard_median": ym, "ratio": cm / ym}  # fmt: skip


def paired(fn: Callable[[], object], repeats: int) -> Paired:
    out = Paired([], [], [])
    for _ in range(repeats):
        gc.collect()
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        out.wall.append(time.perf_counter() - t0)
        out.cpu.append(time.process_time() - c0)
        out.yard.append(yardstick())
    return out


CHUNK = 65_536  # block size of the streamed variant
BEFORE_FUSED = "fast before the fused loop (chunks of 4096, full banks; same run)"


def previous_predict(v: np.ndarray, rest: float = 0.0) -> np.ndarray:
    """The previous fast path: the previous banks by numpy blocks, then the numpy operator."""
    bt = previous_modes(G_T.tau_s, G_T.lam, 1 / RATE_HZ).discretise(1 / RATE_HZ, "zoh")
    bd = previous_modes(G_D.tau_s, G_D.lam, 1 / RATE_HZ).discretise(1 / RATE_HZ, "linear")
    op = PREVIOUS_OP
    vt = run_bank(bt, v - rest, engine="numpy")[0]
    vd = run_bank(bd, vt, engine="numpy")[0] + rest
    return op.apply(vd, op.held_state(rest), engine="numpy")


def before_fused(v: np.ndarray) -> np.ndarray:
    """``predict(v, method="fast")`` as it ran before the fused loop (benchmarks/
    previous_fused.py: chunks of 4096 samples through the full banks, then the operator)."""
    from previous_fused import previous_form, previous_model_run

    op = PREVIOUS_OP
    bt, bd = G_T.bank(RATE_HZ, "zoh"), G_D.bank(RATE_HZ, "linear")
    held = op.held_state(0.0)
    return previous_model_run(
        np.ascontiguousarray(v, dtype=np.float64), 0.0, previous_form(bt), previous_form(bd),
        np.zeros(2), np.zeros(1), np.zeros(1), held.u_last, held.direction, op._wipe, op._code,
        float(op.alpha0), float(op.gamma), float(op.vc),
    )[0]  # fmt: skip


PREVIOUS_OP = DynamicHysteresisModel(PAPER_TABLE1).operator
_PREV_BANKS: dict = {}


def bench_predict(sizes: list[int], repeats: dict[int, int]) -> tuple[list[dict], dict]:
    model = DynamicHysteresisModel(PAPER_TABLE1)
    rows = []
    cold = {}
    t0 = time.process_time()
    model.predict(sweep_input(10_000), RATE_HZ)  # builds the banks (kernels already loaded)
    cold["fast"] = time.process_time() - t0

    def chunked(v: np.ndarray) -> np.ndarray:
        stream = model.stream(RATE_HZ)
        return np.concatenate([stream.process(v[i : i + CHUNK]) for i in range(0, v.size, CHUNK)])

    variants: dict[str, Callable[[np.ndarray], np.ndarray]] = {
        "fast": lambda v: model.predict(v, RATE_HZ, method="fast"),
        f"fast, ModelStream in {CHUNK}-sample blocks": chunked,
        BEFORE_FUSED: before_fused,
        "previous fast (numpy blocks, 242 + 285 modes, numpy operator)": previous_predict,
        "exact": lambda v: model.predict(v, RATE_HZ, method="exact"),
    }
    for name, fn in variants.items():
        for n in sizes:
            if name.startswith("fast,") and n <= CHUNK:
                continue
            if name.startswith("previous") and n > 1_000_000:
                continue
            v = sweep_input(n)
            fn(v)  # warm (banks, kernels, block matrices for this size)
            row = paired(lambda fn=fn, v=v: fn(v), repeats[n]).row(n)
            rows.append({"method": name, **row})
            print(f"  predict {name[:30]:30s} N={n:>9d}: CPU best {fmt_time(row['cpu_best'])}, "
                  f"{fmt_rate(row['rate_cpu'])} samples/s, {row['ratio']:.2f} yardsticks",
                  flush=True)  # fmt: skip
    return rows, cold


def agreement(n: int) -> dict[str, float]:
    """Max differences on the benchmark sweep, as fractions of the strain's or voltage's
    full scale."""
    from labrig.model.modal import run_bank as rb

    model = DynamicHysteresisModel(PAPER_TABLE1)
    v = sweep_input(n)
    fast = model.predict(v, RATE_HZ)
    fs_strain = float(np.max(np.abs(fast)))
    vt = rb(model.g_t.bank(RATE_HZ, "zoh"), v, engine="numpy")[0]
    vd = rb(model.g_d.bank(RATE_HZ, "linear"), vt, engine="numpy")[0]
    op = model.operator
    stages = op.apply(vd, engine="numpy")
    exact_vd = model.equivalent_static_voltage(v, RATE_HZ, method="exact")
    prev = previous_predict(v)
    # the arithmetic of the fast path before the fused loop and the compact banks: the full
    # banks by the compiled recursion, then the compiled operator
    cvt = rb(model.g_t.bank(RATE_HZ, "zoh"), v)[0]
    before = op.apply(rb(model.g_d.bank(RATE_HZ, "linear"), cvt)[0])
    return {
        "fast (fused, compact banks) vs the numpy stages (full banks by numpy blocks, numpy "
        "operator)": float(np.max(np.abs(fast - stages))) / fs_strain,
        "fast (fused, compact banks) vs the compiled stages with the full banks": float(
            np.max(np.abs(fast - before))) / fs_strain,
        "fast (fused, compact banks) vs the fast path before the fused loop":
            float(np.max(np.abs(fast - before_fused(v)))) / fs_strain,
        "compiled operator vs numpy operator on the same V*":
            float(np.max(np.abs(op.apply(vd, engine="compiled") - stages))) / fs_strain,
        "V* of the banks vs V* of exact": float(np.max(np.abs(vd - exact_vd))) / FULL_SCALE_V,
        "strain of fast vs strain of exact":
            float(np.max(np.abs(fast - op.apply(exact_vd)))) / fs_strain,
        "strain of fast vs strain of the previous fast path":
            float(np.max(np.abs(fast - prev))) / fs_strain,
    }  # fmt: skip


def compact_sizes(model: DynamicHysteresisModel) -> str:
    """The modes the fused loop runs: real modes with a weight (padded count), complex ones."""
    parts = []
    for name, bank in (("G_t", model.g_t.bank(RATE_HZ, "zoh")),
                       ("G_d", model.g_d.bank(RATE_HZ, "linear"))):  # fmt: skip
        a, cw, _, ca, _ = compact_form(bank)
        parts.append(f"{name} {np.count_nonzero(cw)} real (padded to {a.size}) + {ca.size} "
                     f"complex, of {bank.size}")  # fmt: skip
    return "; ".join(parts)


def split_exact(n: int, repeats: int) -> dict[str, float]:
    """CPU best of the exact method's parts: the two sampled kernels, the FFT products (what
    ``fftconvolve`` does: three real transforms of a length >= 2N - 1 each), the operator."""
    from scipy import fft

    from labrig.model.relaxor import sampled_kernel

    model = DynamicHysteresisModel(PAPER_TABLE1)
    v = sweep_input(n)
    dt = 1.0 / RATE_HZ
    kt = sampled_kernel(G_T.tau_s, G_T.lam, dt, n, "zoh")
    kd = sampled_kernel(G_D.tau_s, G_D.lam, dt, n, "linear")
    size = fft.next_fast_len(2 * n - 1, real=True)
    vd = model.equivalent_static_voltage(v, RATE_HZ, method="exact")
    stages = {
        "the two sampled kernels (closed forms, Chebyshev interpolant)": lambda: (
            sampled_kernel(G_T.tau_s, G_T.lam, dt, n, "zoh"),
            sampled_kernel(G_D.tau_s, G_D.lam, dt, n, "linear"),
        ),
        f"one real FFT of length {size} (the method needs six)": lambda: fft.rfft(v, size),
        "both convolutions (scipy.signal.fftconvolve)": lambda: _two_convolutions(v, kt, kd),
        "operator (compiled)": lambda: model.operator.apply(vd),
        "the whole exact prediction": lambda: model.predict(v, RATE_HZ, method="exact"),
    }
    out = {}
    for k, fn in stages.items():
        fn()
        out[k] = min(paired(fn, repeats).cpu)
    return out


def _two_convolutions(v: np.ndarray, kt: np.ndarray, kd: np.ndarray) -> np.ndarray:
    from scipy.signal import fftconvolve

    return fftconvolve(fftconvolve(v, kt)[: v.size], kd)[: v.size]


def split_fast(n: int, repeats: int) -> dict[str, float]:
    """CPU best of each stage alone (compiled), and of the whole fused prediction."""
    model = DynamicHysteresisModel(PAPER_TABLE1)
    v = sweep_input(n)
    bt, bd = model.g_t.bank(RATE_HZ, "zoh"), model.g_d.bank(RATE_HZ, "linear")
    vt = run_bank(bt, v)[0]
    vd = run_bank(bd, vt)[0]
    op = model.operator
    stages = {
        f"G_t bank alone ({bt.size} modes, zoh)": lambda: run_bank(bt, v),
        f"G_d bank alone ({bd.size} modes, linear)": lambda: run_bank(bd, vt),
        "operator alone (compiled)": lambda: op.apply(vd),
        "operator alone (numpy)": lambda: op.apply(vd, engine="numpy"),
        f"the whole prediction (fused, compact banks: {compact_sizes(model)})":
            lambda: model.predict(v, RATE_HZ),
    }  # fmt: skip
    out = {}
    for k, fn in stages.items():
        fn()
        out[k] = min(paired(fn, repeats).cpu)
    return out


def bench_recursion(n: int, repeats: int) -> list[dict]:
    """run_bank compiled (per sample, all modes) vs numpy blocks (BLAS), new and previous banks."""
    v = sweep_input(n)
    rows = []
    dt = 1 / RATE_HZ
    banks = {
        "G_t, new": G_T.bank(RATE_HZ, "zoh"),
        "G_d, new": G_D.bank(RATE_HZ, "linear"),
        "G_t, previous": previous_modes(G_T.tau_s, G_T.lam, dt).discretise(dt, "zoh"),
        "G_d, previous": previous_modes(G_D.tau_s, G_D.lam, dt).discretise(dt, "linear"),
    }
    for name, bank in banks.items():
        res = {}
        for engine in ("compiled", "numpy"):
            run_bank(bank, v, engine=engine)
            res[engine] = min(paired(lambda b=bank, e=engine: run_bank(b, v, engine=e),
                                     repeats).cpu)  # fmt: skip
        rows.append({"bank": name, "modes": bank.size, **res})
        print(f"  recursion {name}: {bank.size} modes, compiled {fmt_time(res['compiled'])}, "
              f"numpy blocks {fmt_time(res['numpy'])}", flush=True)  # fmt: skip
    return rows


# -- 2. the banks: modes and accuracy ------------------------------------------------------------

BANK_LAMS = (0.1, 0.15, 0.3, 0.5, 0.8, 0.95, 1.05, 1.2, 1.5, 1.8)


def bench_banks(n: int, rates: list[float], tau_s: float = 1e-3) -> list[dict]:
    rows = []
    for rate in rates:
        dt = 1 / rate
        step = np.ones(n)
        for lam in BANK_LAMS:
            r = Relaxor(tau_s, lam)
            row = {"lam": lam, "rate": rate}
            for hold in ("zoh", "linear"):
                exact = r.filter(step, rate, method="exact", hold=hold)
                new = r.bank(rate, hold)
                prev = previous_modes(tau_s, lam, dt).discretise(dt, hold)
                row[f"modes_{hold}"] = new.size
                row[f"modes_prev_{hold}"] = prev.size
                row[f"err_{hold}"] = float(np.max(np.abs(run_bank(new, step)[0] - exact)))
                row[f"err_prev_{hold}"] = float(np.max(np.abs(
                    run_bank(prev, step, engine="numpy")[0] - exact)))  # fmt: skip
            rows.append(row)
            print(f"  banks {rate:g} Hz lam {lam}: {row['modes_zoh']} modes (previous "
                  f"{row['modes_prev_zoh']}), err zoh {row['err_zoh']:.1e} (previous "
                  f"{row['err_prev_zoh']:.1e})", flush=True)  # fmt: skip
    return rows


# -- 3. compilation and start-up -----------------------------------------------------------------

_COLD_SCRIPT = """
import json, time
c0 = time.process_time(); w0 = time.perf_counter()
import numpy as np
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel, Relaxor
c1 = time.process_time()
import numba
c2 = time.process_time()
m = DynamicHysteresisModel(PAPER_TABLE1)
v = 50 * (1 - np.cos(np.arange(2000) / 50.0))
m.predict(v, 1000.0)
c3 = time.process_time()
m.operator.sensitivities(v, 0.0, np.ones((v.size, 2)))
Relaxor(2e-3, 1.35).filter_sensitivities(v, 1000.0, "linear")
m.predict(v, 1000.0, method="exact")
c4 = time.process_time()
print(json.dumps({"import labrig.model": c1 - c0, "import numba": c2 - c1,
                  "first predict (kernels)": c3 - c2,
                  "sensitivities and exact kernels": c4 - c3,
                  "wall": time.perf_counter() - w0}))
"""


def bench_compile() -> dict:
    """Cold compile and cached load of the kernels, in fresh processes with a fresh cache."""
    out: dict = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for label in ("cold (empty cache)", "cached (second process)"):
            res = subprocess.run([sys.executable, "-c", _COLD_SCRIPT], env=env, cwd=ROOT,
                                 capture_output=True, text=True, check=True)  # fmt: skip
            out[label] = json.loads(res.stdout.strip().splitlines()[-1])
            print(f"  compile {label}: {out[label]}", flush=True)
    cli = ROOT / ".venv" / "bin" / "labrig"
    times = []
    if cli.exists():
        for _ in range(5):
            r0 = os.times()
            t0 = time.perf_counter()
            subprocess.run([str(cli), "--help"], capture_output=True, check=True, cwd=ROOT)
            r1 = os.times()
            times.append((time.perf_counter() - t0, (r1.children_user - r0.children_user)
                          + (r1.children_system - r0.children_system)))  # fmt: skip
    probe = subprocess.run(
        [sys.executable, "-c", "import sys, labrig.cli; print('numba' in sys.modules)"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    out["cli"] = {"runs": times, "numba imported": probe.stdout.strip()}
    return out


# -- 2. Grunwald-Letnikov (FOMCON lsim) versus exact and fast --------------------------------------


def gl_weights(lam: float, n: int) -> np.ndarray:
    """``w_j = (-1)^j binom(lam, j)``, ``j = 0..n``, by ``w_j = w_{j-1} (1 - (lam+1)/j)``."""
    w = np.empty(n + 1)
    w[0] = 1.0
    w[1:] = np.cumprod(1.0 - (lam + 1.0) / np.arange(1, n + 1))
    return w


def gl_relaxor(v: np.ndarray, tau_s: float, lam: float, h: float) -> np.ndarray:
    """``(1 + (tau D)^lam) y = v`` by the Grunwald-Letnikov scheme (full memory, implicit).

    ``y_n = (v_n - c sum_{j=1}^{n} w_j y_{n-j}) / (1 + c)`` with ``c = tau^lam h^-lam``: the
    discretisation FOMCON's ``lsim`` applies to a fractional transfer function (first order in
    ``h``, every past sample kept). O(N^2): one dot product of length n per sample.
    """
    v = np.asarray(v, dtype=float)
    n_tot = v.size
    c = (tau_s / h) ** lam
    wr = gl_weights(lam, n_tot)[::-1].copy()  # wr[n_tot - j] = w_j
    y = np.zeros(n_tot)
    inv = 1.0 / (1.0 + c)
    for n in range(n_tot):
        # sum_{j=1}^{n} w_j y_{n-j} = dot(w_n..w_1, y_0..y_{n-1})
        hist = np.dot(wr[n_tot - n : n_tot], y[:n]) if n else 0.0
        y[n] = (v[n] - c * hist) * inv
    return y


def gl_convergence(
    relaxor: Relaxor, t_end_s: float, t_min_s: float, refinements: list[int]
) -> list[dict]:
    """Max error of GL on the unit step over ``[t_min, t_end]`` as ``h = 1 ms / k`` shrinks."""
    rows = []
    for k in refinements:
        h = 1.0 / (RATE_HZ * k)
        n = round(t_end_s / h) + 1
        t = np.arange(n) * h
        y = gl_relaxor(np.ones(n), relaxor.tau_s, relaxor.lam, h)
        ref = relaxor.step_response(t)
        sel = t >= t_min_s - 1e-12
        rows.append(
            {
                "h_s": h,
                "n": n,
                "err_late": float(np.max(np.abs(y[sel] - ref[sel]))),
                "err_end": float(abs(y[-1] - ref[-1])),
            }
        )
    return rows


def sine_reference(relaxor: Relaxor, n: int, f_hz: float, over: int) -> np.ndarray:
    """Exact response (linear hold) at ``over`` x the rate, subsampled: the continuous sine's."""
    t = np.arange((n - 1) * over + 1) / (RATE_HZ * over)
    v = 50.0 * (1.0 - np.cos(2 * np.pi * f_hz * t))
    return relaxor.filter(v, RATE_HZ * over, method="exact", hold="linear")[::over]


def bench_gl(sizes: list[int], repeats: int) -> list[dict]:
    rows = []
    h = 1.0 / RATE_HZ
    n_max = max(sizes)
    f_sine = 5.0
    for name, r in (("G_t", G_T), ("G_d", G_D)):
        t_all = np.arange(n_max) * h
        ref_step = r.step_response(t_all)
        ref_sine = sine_reference(r, n_max, f_sine, over=16)
        v_sine_all = 50.0 * (1.0 - np.cos(2 * np.pi * f_sine * t_all))
        for n in sizes:
            step = np.ones(n)
            sine = v_sine_all[:n]
            res: dict[str, dict] = {}
            for method in ("GL", "exact", "fast"):
                if method == "GL":
                    reps = 1 if n > 20_000 else repeats

                    def run(x, r=r):
                        return gl_relaxor(x, r.tau_s, r.lam, h)

                    def run_lin(x, r=r):
                        return gl_relaxor(x, r.tau_s, r.lam, h)
                else:
                    reps = repeats

                    def run(x, r=r, m=method):
                        return r.filter(x, RATE_HZ, method=m, hold="zoh")

                    def run_lin(x, r=r, m=method):
                        return r.filter(x, RATE_HZ, method=m, hold="linear")

                if method != "GL":  # warm caches (banks, block matrices for this size)
                    run(step)
                    run_lin(sine)
                tm = timeit(lambda run=run, step=step: run(step), reps)
                y_step = run(step)
                y_sine = run_lin(sine)
                err = np.abs(y_step - ref_step[:n])
                late = np.arange(n) >= 10  # t >= 10 ms
                res[method] = {
                    "time": tm.best,
                    "err_step": float(err.max()),
                    "err_step_late": float(err[late].max()),
                    "err_sine": float(np.max(np.abs(y_sine - ref_sine[:n])) / 100.0),
                }
            rows.append({"relaxor": name, "n": n, **res})
            print(
                f"  {name} N={n:>6d}: GL {fmt_time(res['GL']['time'])} "
                f"(err {res['GL']['err_step']:.2e}), exact {fmt_time(res['exact']['time'])} "
                f"({res['exact']['err_step']:.1e}), fast {fmt_time(res['fast']['time'])} "
                f"({res['fast']['err_step']:.1e})",
                flush=True,
            )
    return rows


# -- 3. per-sample cost --------------------------------------------------------------------------


class ScalarExpHysteresis:
    """Benchmark-only sketch: the exponential-shape operator one sample at a time in plain Python.

    The last-reversal memory rule (reversal = change of direction, the extremum is the previous
    sample; rest at 0 V with zero strain), which on the benchmark's periodic signal (no extremum
    passes an earlier turning point) gives what ``QuasiStaticHysteresis.apply`` gives with its
    default return-point memory; checked against it before its cost is reported. It shows what a
    scalar ``step`` costs (the controller's ``_StaticInverseStepper`` is the full, stack-based
    per-sample form).
    """

    def __init__(self, alpha0: float, gamma: float, vc: float):
        self.a0, self.g, self.vc = alpha0, gamma, vc
        self.u_s = self.s_s = self.u_last = self.s_last = 0.0
        self.d = 0.0

    def step(self, u: float) -> float:
        du = u - self.u_last
        d = 1.0 if du > 0 else -1.0 if du < 0 else self.d
        if self.d != 0.0 and d != self.d:
            self.u_s, self.s_s = self.u_last, self.s_last
        self.d = d
        x = abs(u - self.u_s)
        f = self.a0 * x + self.g * (x + self.vc * math.expm1(-x / self.vc))
        s = self.s_s + (f if u >= self.u_s else -f)
        self.u_last, self.s_last = u, s
        return s


def bench_stepper(n_samples: int, rates: list[float]) -> list[dict]:
    rows = []
    x = 50.0 * (1.0 - np.cos(2 * np.pi * 5.0 * np.arange(n_samples) / 1000.0))
    xs = [float(a) for a in x]
    model = DynamicHysteresisModel(PAPER_TABLE1)
    op = model.operator
    arrs = [np.array([a]) for a in xs]

    def per_sample(fn: Callable[[], object]) -> dict[str, float]:
        """ns per sample: CPU time (the verdicts use it) and wall clock, best of 3."""
        tm = timeit(fn, 3)
        return {"ns": tm.cpu_best / n_samples * 1e9, "ns_wall": tm.best / n_samples * 1e9}

    # the hysteresis operator does not depend on the rate: measure it once
    def loop_h() -> None:
        state = HysteresisState()
        for a in arrs:
            op.apply(a, state)

    ns_h = per_sample(loop_h)
    p = PAPER_TABLE1
    ref = op.apply(x)
    sc = ScalarExpHysteresis(p.alpha0_ue_per_V, p.gamma_ue_per_V, p.vc_V)
    same = np.allclose([sc.step(a) for a in xs], ref, rtol=0, atol=1e-9)

    def loop_sc() -> None:
        h = ScalarExpHysteresis(p.alpha0_ue_per_V, p.gamma_ue_per_V, p.vc_V)
        step = h.step
        for a in xs:
            step(a)

    ns_sc = per_sample(loop_sc) if same else {"ns": float("nan"), "ns_wall": float("nan")}
    for rate in rates:
        for name, r, hold in (
            ("G_t stepper (zoh, as in the model)", G_T, "zoh"),
            ("G_d stepper (zoh)", G_D, "zoh"),
            ("G_d stepper (linear, as in the model)", G_D, "linear"),
        ):
            st = r.stepper(rate, hold=hold)

            def loop(st=st) -> None:
                st.reset()
                step = st.step
                for a in xs:
                    step(a)

            rows.append({"what": name, "rate": rate, "modes": st.bank.size, **per_sample(loop)})
        rows.append({"what": "hysteresis `apply` on a 1-sample array", "rate": rate, "modes": 0,
                     **ns_h})  # fmt: skip
        rows.append({"what": "scalar hysteresis step (sketch in this file, same output)",
                     "rate": rate, "modes": 0, **ns_sc})  # fmt: skip
        stream = model.stream(rate)

        def loop_s(stream=stream) -> None:
            stream.reset()
            for a in arrs:
                stream.process(a)

        rows.append({"what": "`ModelStream.process` on 1-sample blocks", "rate": rate,
                     "modes": sum(np.count_nonzero(compact_form(b)[1]) + compact_form(b)[3].size
                                  for b in (stream._bank_t, stream._bank_d)),
                     **per_sample(loop_s)})  # fmt: skip
        print(f"  per-sample costs at {rate:g} Hz measured", flush=True)
    return rows


# -- report --------------------------------------------------------------------------------------


def goal_verdict(rate: float, goal: float) -> str:
    return "met" if rate >= goal else f"**missed** ({rate / goal:.0%} of the goal)"


def summary(a, rows: list[dict], agree: dict, banks: list[dict], comp: dict,
            gl_rows: list[dict], step_rows: list[dict]) -> None:  # fmt: skip
    """The table the README can copy."""
    a("## Summary")
    a("")
    a("| measurement | result | goal | status |")
    a("|---|---|---|---|")
    by = {(r["method"], r["n"]): r for r in rows}
    for method, goal, ns in (("fast", GOAL_FAST, (1_000_000, 10_000_000)),
                             ("exact", GOAL_EXACT, (1_000_000,))):  # fmt: skip
        for n in ns:
            r = by.get((method, n))
            if r is None:
                continue
            a(
                f'| `predict(method="{method}")`, N = {n:.0e}: samples/s, CPU time best '
                f"(median); median time in yardsticks | {fmt_rate(r['rate_cpu'])} "
                f"({fmt_rate(r['rate_cpu_median'])}); {r['ratio']:.2f} | >= {goal:.0e} | "
                f"{goal_verdict(r['rate_cpu'], goal)} on the best run, "
                f"{goal_verdict(r['rate_cpu_median'], goal)} on the median |"
            )
    prev = [r for r in rows if r["method"].startswith("previous") and r["n"] == 1_000_000]
    if prev and ("fast", 1_000_000) in by:
        f, p = by[("fast", 1_000_000)], prev[0]
        a(
            f"| fast vs the previous fast path, N = 1e6, same run: median time in yardsticks | "
            f"{f['ratio']:.2f} vs {p['ratio']:.2f} | - | x{p['ratio'] / f['ratio']:.1f} |"
        )
    for n in (1_000_000, 10_000_000):
        f, b = by.get(("fast", n)), by.get((BEFORE_FUSED, n))
        if f and b:
            a(
                f"| fast vs the fast path before the fused loop (chunks of 4096, full banks), "
                f"N = {n:.0e}, same run: CPU median | {fmt_time(f['cpu_median'])} vs "
                f"{fmt_time(b['cpu_median'])} | - | x{b['cpu_median'] / f['cpu_median']:.2f} |"
            )
    for key, label in (
        ("fast (fused, compact banks) vs the numpy stages (full banks by numpy blocks, numpy "
         "operator)", "fast (compiled) vs the same maths in numpy"),
        ("fast (fused, compact banks) vs the fast path before the fused loop",
         "fast vs the fast path before the fused loop"),
    ):  # fmt: skip
        if key in agree:
            a(
                f"| {label}, max difference / full scale | {agree[key]:.1e} | <= 1e-12 | "
                f"{'met' if agree[key] <= 1e-12 else '**missed**'} |"
            )
    if banks:
        worst = max(max(r["err_zoh"], r["err_linear"]) for r in banks)
        worst_zoh = max(r["err_zoh"] for r in banks)
        modes = sorted({r["modes_zoh"] for r in banks} | {r["modes_linear"] for r in banks})
        prev_modes = sorted({r["modes_prev_zoh"] for r in banks})
        a(
            f"| relaxor banks, lam 0.1..1.8, 1 and 10 kHz: modes (previous) | {modes[0]}-"
            f"{modes[-1]} ({prev_modes[0]}-{prev_modes[-1]}) | as few as the accuracy needs | - |"
        )
        a(
            f"| relaxor banks: max error on a unit step vs exact, zoh (zoh and linear) | "
            f"{worst_zoh:.1e} ({worst:.1e}) | 1e-12 | "
            f"{'met' if worst_zoh <= 1e-12 else '**missed**'} (zoh; the linear hold's exact "
            "kernel is the limit) |"
        )
    if comp:
        cold, warm = comp["cold (empty cache)"], comp["cached (second process)"]
        kc = cold["first predict (kernels)"] + cold["sensitivities and exact kernels"]
        kw = warm["first predict (kernels)"] + warm["sensitivities and exact kernels"]
        a(
            f"| numba kernels: cold compile / cached load (CPU s, fresh processes) | {kc:.1f} / "
            f"{kw:.2f} | no compile after the first run | {'met' if kw < 2 else '**missed**'} |"
        )
        runs = comp["cli"]["runs"]
        if runs:
            a(
                f"| `labrig --help`: wall / CPU, best of {len(runs)} | "
                f"{min(r[0] for r in runs):.2f} s / {min(r[1] for r in runs):.2f} s | <= 0.5 s; "
                f"numba not imported | {'met' if min(r[1] for r in runs) <= 0.5 else '**missed**'}"
                f" (CPU); numba imported: {comp['cli']['numba imported']} |"
            )
    for name in ("G_t", "G_d"):
        rr = [r for r in gl_rows if r["relaxor"] == name]
        if rr:
            r = rr[-1]
            g, e, f = r["GL"], r["exact"], r["fast"]
            a(
                f"| {name} unit step at 1 kHz, N = {r['n']:.0e}: time GL / exact / fast | "
                f"{fmt_time(g['time'])} / {fmt_time(e['time'])} / {fmt_time(f['time'])} | - | "
                f"GL x{g['time'] / e['time']:.2g} the time of exact, x{g['time'] / f['time']:.2g}"
                " that of fast |"
            )
    rr = {r["what"]: r["ns"] for r in step_rows if r["rate"] == 10000.0}
    if rr:
        ns = rr["`ModelStream.process` on 1-sample blocks"]
        a(
            f"| 10 kHz loop, `ModelStream.process` per sample | {ns / 1e3:.0f} us | <= 100 us | "
            + ("fits" if ns < 50e3 else "only just" if ns < 100e3 else "**does not fit**")
            + " |"
        )
    a("")


def render(info: dict, rows: list[dict], cold: dict, agree: dict, split: dict, split_n: int,
           recursion: list[dict], banks: list[dict], bank_n: int, comp: dict, conv: dict,
           gl_rows: list[dict], step_rows: list[dict], elapsed: float) -> str:  # fmt: skip
    L: list[str] = []
    a = L.append
    a("# labrig model benchmarks")
    a("")
    a("Reproduce (from the repository root; 6-10 minutes on a loaded 2-core machine, rewrites")
    a("this file):")
    a("")
    a("    .venv/bin/python benchmarks/bench_model.py        # or: .venv/bin/python -m benchmarks")
    a("")
    a("Every number below is produced by `benchmarks/bench_model.py` in one run; the prose that")
    a("states goals met or missed is generated from the same numbers. Times are CPU time of the")
    a("process (`time.process_time`; `gc.collect()` before each repeat, one BLAS thread) unless")
    a("said otherwise. Each predict timing is followed, in the same loop, by the **yardstick**:")
    a("`numpy.sort` of 1e6 random floats; *yardsticks* = median time / median yardstick.")
    a("")
    a("## Machine")
    a("")
    a("| item | value |")
    a("|---|---|")
    labels = {"load": "load average at start (1/5/15 min)", "load_end": "load average at end",
              "commit": "labrig commit"}  # fmt: skip
    for k in ("date", "cpu", "cores", "os", "python", "numpy", "scipy", "numba", "blas",
              "blas threads", "commit", "load", "load_end"):  # fmt: skip
        a(f"| {labels.get(k, k)} | {info[k]} |")
    a(f"| total benchmark run time | {elapsed:.0f} s |")
    a("")
    a("The machine is shared: with the load average above ~2 on these 2 cores, CPU times move")
    a("by 20-50 % between repeats (a busy sibling hyperthread, cache and memory bandwidth);")
    a("the yardstick moves with them, and the ratios to it are what to compare across runs.")
    a("")
    summary(a, rows, agree, banks, comp, gl_rows, step_rows)
    a("## 1. `DynamicHysteresisModel(PAPER_TABLE1).predict` throughput")
    a("")
    a("Input: 0-100 V unipolar sine whose frequency sweeps linearly 1 -> 40 Hz every 10 s,")
    a("sampled at 1 kHz (N = 1e7 is 2.8 h of signal). Kernels loaded and banks built first (the")
    a(f"first call at N = 1e4 in this process: {fmt_time(cold['fast'])} CPU; compilation is in")
    a("section 3). *fast* runs the compiled model in one pass (`compiled.model_run`: both banks")
    a("and the operator fused in one loop over blocks of eight samples, no intermediate arrays,")
    a("on the compact banks of `modal.compact_form`); the *ModelStream* row feeds the same")
    a(f"computation in {CHUNK}-sample blocks; *fast before the fused loop* is the compiled loop")
    a("it replaced (`benchmarks/previous_fused.py`: chunks of 4096 samples through the full")
    a("banks into arrays, then the operator), timed in this run; the *previous fast path* is")
    a("what `fast` was before the compiled kernels and the new quadrature, timed in this run:")
    a("the Gauss-Legendre banks (`benchmarks/previous_quadrature.py`, 242 + 285 modes) run by")
    a("the numpy block realisation, then the numpy operator.")
    a("")
    a("| method | N | repeats | CPU best | CPU median | samples/s (CPU best) | samples/s "
      "(CPU median) | yardstick best / median | yardsticks |")  # fmt: skip
    a("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        a(f"| {r['method']} | {r['n']:.0e} | {r['repeats']} | {fmt_time(r['cpu_best'])} | "
          f"{fmt_time(r['cpu_median'])} | {fmt_rate(r['rate_cpu'])} | "
          f"{fmt_rate(r['rate_cpu_median'])} | {fmt_time(r['yard_best'])} / "
          f"{fmt_time(r['yard_median'])} | {r['ratio']:.2f} |")  # fmt: skip
    a("")
    by = {(r["method"], r["n"]): r for r in rows}
    for method, goal, ns in (("fast", GOAL_FAST, (1_000_000, 10_000_000)),
                             ("exact", GOAL_EXACT, (1_000_000,))):  # fmt: skip
        for n in ns:
            r = by.get((method, n))
            if r:
                a(
                    f"- **{method}**, N = {n:.0e}, goal >= {goal:.0e} samples/s: "
                    f"{goal_verdict(r['rate_cpu'], goal)} on the best run "
                    f"({fmt_rate(r['rate_cpu'])}), "
                    f"{goal_verdict(r['rate_cpu_median'], goal)} on the median "
                    f"({fmt_rate(r['rate_cpu_median'])}); {r['ratio']:.2f} yardsticks."
                )
    a("")
    a(f"Agreement on the same sweep (N = {split_n:.0e}; strain full scale = its maximum, V* "
      "full scale 100 V):")  # fmt: skip
    a("")
    a("| comparison | max difference / full scale |")
    a("|---|---:|")
    for k, x in agree.items():
        a(f"| {k} | {x:.1e} |")
    a("")
    a(f"Each stage alone at N = {split_n:.0e} (compiled unless said; CPU best of 5):")
    a("")
    a("| stage | CPU | samples/s |")
    a("|---|---:|---:|")
    for k, x in split.items():
        if k != "exact":
            a(f"| {k} | {fmt_time(x)} | {fmt_rate(split_n / x)} |")
    a("")
    ex = split.get("exact")
    if ex:
        a(f"The exact method's parts at N = {split_n:.0e}, each timed alone (CPU best of 3, so")
        a("the shares need not add up to 100 %): the two sampled kernels, the two convolutions")
        a("(`scipy.signal.fftconvolve`: six real transforms of a length >= 2N - 1, pocketfft)")
        a("and the operator.")
        a("")
        a("| part | CPU | share of the whole |")
        a("|---|---:|---:|")
        whole = ex["the whole exact prediction"]
        for k, x in ex.items():
            a(f"| {k} | {fmt_time(x)} | {x / whole:.0%} |")
        a("")
    a(f"The banks' recursion, N = {split_n:.0e}: compiled (one sample at a time over all modes,")
    a("eight samples per sweep) against the numpy block realisation (blocks of 256 samples,")
    a("BLAS matrix products), at the new and the previous bank sizes; CPU best of 3:")
    a("")
    a("| bank | modes | compiled | numpy blocks | blocks / compiled |")
    a("|---|---:|---:|---:|---:|")
    for r in recursion:
        a(
            f"| {r['bank']} | {r['modes']} | {fmt_time(r['compiled'])} | {fmt_time(r['numpy'])} "
            f"| {r['numpy'] / r['compiled']:.1f} |"
        )
    a("")
    a("## 2. The relaxor banks: modes and accuracy")
    a("")
    a(f"`Relaxor(1e-3 s, lam)`, unit-step record of {bank_n:.0e} samples, max |fast - exact|")
    a("(full scale 1). *New*: the pole-corrected trapezoidal rule of `labrig/model/diffusive.py`")
    a("(node positions fixed for the rate; same count for every lam); *previous*: the")
    a("Gauss-Legendre panels. The exact linear-hold kernel (differences of interval means) is")
    a("itself good to a few 1e-12, which bounds the linear columns.")
    a("")
    a("| rate | lam | modes zoh / linear | previous | error zoh | previous | error linear | "
      "previous |")  # fmt: skip
    a("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in banks:
        a(
            f"| {r['rate']:g} Hz | {r['lam']} | {r['modes_zoh']} / {r['modes_linear']} | "
            f"{r['modes_prev_zoh']} / {r['modes_prev_linear']} | {r['err_zoh']:.1e} | "
            f"{r['err_prev_zoh']:.1e} | {r['err_linear']:.1e} | {r['err_prev_linear']:.1e} |"
        )
    a("")
    a("## 3. Compilation, the cache and start-up")
    a("")
    if comp:
        a("Fresh Python processes with an empty `NUMBA_CACHE_DIR` (cold) and then the same one")
        a("again (cached), CPU seconds of each step (`wall` is the whole script's wall time):")
        a("")
        keys = list(comp["cold (empty cache)"])
        a("| run | " + " | ".join(keys) + " |")
        a("|---|" + "---:|" * len(keys))
        for label in ("cold (empty cache)", "cached (second process)"):
            a(f"| {label} | " + " | ".join(f"{comp[label][k]:.2f}" for k in keys) + " |")
        a("")
        a("Without `NUMBA_CACHE_DIR`, numba writes the cache to `labrig/model/__pycache__` when")
        a("that folder is writable, else to its user-wide folder (`~/.cache/numba` on Linux);")
        a("with no writable folder at all it refuses `cache=True` kernels, and labrig falls back")
        a("to its numpy code with a warning naming `NUMBA_CACHE_DIR` (docs/model.md).")
        a("")
        runs = comp["cli"]["runs"]
        if runs:
            a(
                f"`labrig --help`, {len(runs)} runs (wall s, CPU s): "
                + ", ".join(f"{w:.2f}/{c:.2f}" for w, c in runs)
                + f"; `import labrig.cli` imports numba: {comp['cli']['numba imported']}."
            )
            a("")
    a("## 4. Grunwald-Letnikov (FOMCON `lsim`) versus `exact` and `fast`")
    a("")
    a("The GL scheme, as FOMCON's `lsim` discretises `(1 + (tau D)^lam) y = v` (full memory,")
    a("implicit, first order): `y_n = (v_n - c sum_{j=1..n} w_j y_{n-j}) / (1 + c)`,")
    a("`c = (tau/h)^lam`, `w_0 = 1`, `w_j = w_{j-1} (1 - (lam+1)/j)`; written in numpy in")
    a("`bench_model.py::gl_relaxor` (one BLAS dot product per sample, O(N^2)).")
    a("")
    a("**Check that the GL code converges** to the closed-form step response `1 - E_lam(-(t/tau)")
    a("^lam)` (max error over the stated window, h = 1 ms / k):")
    a("")
    a("| relaxor | window | h | N | max error in window | error at window end |")
    a("|---|---|---:|---:|---:|---:|")
    for name, (win, rows) in conv.items():
        for r in rows:
            a(
                f"| {name} | {win} | {r['h_s'] * 1e6:.1f} us | {r['n']} | {r['err_late']:.2e} | "
                f"{r['err_end']:.2e} |"
            )
    a("")
    a("The error falls roughly in proportion to h (first order), as it should; at the rig's")
    a("h = 1 ms it is what the table below reports.")
    a("")
    a("**Side by side at 1 kHz** (paper's G_t: tau = 15.5e-5 s, lam = 0.15; G_d: tau = 2e-3 s,")
    a("lam = 1.35). Time: unit-step record, best of repeats (GL: 1 run above N = 2e4). Errors")
    a("(full scale 1): *step* = max over all samples against `Relaxor.step_response` at `t_n`")
    a("(GL's first samples carry most of its error: it sees the step at t = 0 as a value, not")
    a("a held sample); *step, t >= 10 ms* = the same from the 10th sample on; *sine* = a 0-100 V")
    a("unipolar 5 Hz sine, max error / 100 V against the exact linear-hold response computed at")
    a("16 kHz: the continuous sine's response to ~1e-7. GL takes the samples as point values;")
    a("exact and fast use the linear hold (the smooth-input convention). At 1 kHz the linear")
    a("hold's own interpolation error (~h^2) is what exact and fast share here: it belongs to")
    a("sampling the sine at 1 kHz, not to either method.")
    a("")
    a(
        "| relaxor | N | GL time | exact time | fast time | GL/exact | GL/fast | "
        "GL err step | exact err step | fast err step | GL err step t>=10ms | "
        "GL err sine | exact err sine | fast err sine |"
    )
    a("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in gl_rows:
        g, e, f = r["GL"], r["exact"], r["fast"]
        a(
            f"| {r['relaxor']} | {r['n']:.0e} | {fmt_time(g['time'])} | {fmt_time(e['time'])} | "
            f"{fmt_time(f['time'])} | {g['time'] / e['time']:.2g}x | {g['time'] / f['time']:.2g}x |"
            f" {g['err_step']:.1e} | {e['err_step']:.1e} | {f['err_step']:.1e} | "
            f"{g['err_step_late']:.1e} | {g['err_sine']:.1e} | {e['err_sine']:.1e} | "
            f"{f['err_sine']:.1e} |"
        )
    a("")
    # extrapolation of GL to 1e6
    for name in ("G_t", "G_d"):
        rr = [r for r in gl_rows if r["relaxor"] == name]
        if not rr:
            continue
        big = rr[-1]
        scale = (1e6 / big["n"]) ** 2
        a(
            f"- {name}: GL at N = 1e6 (16.7 min of 1 kHz data) would take about "
            f"{big['GL']['time'] * scale / 60:.0f} min (extrapolated as t(N={big['n']:.0e}) x "
            f"{scale:.0f}, O(N^2); not run), against {fmt_time(big['exact']['time'])} (exact) and "
            f"{fmt_time(big['fast']['time'])} (fast) at N = {big['n']:.0e}."
        )
    a("")
    a("## 5. Per-sample cost (control loop)")
    a("")
    a("A Python loop calling `step(x)` (or the named call) once per sample (5 Hz 0-100 V sine,")
    a("2e4 samples, best of 3). `modes` is the size of the modal bank (the same at every rate:")
    a("the nodes span the same e-folds below 40/dt). The budget of a 10 kHz loop is 100 us per")
    a("sample for everything (two relaxors, hysteresis, control law, I/O); a 1 kHz loop has")
    a("1000 us. Verdicts use the CPU time (on an idle core it equals the wall time; under load")
    a("the wall time of these loops moved by up to 2x between runs).")
    a("")
    a("| what | rate | modes | ns per sample (CPU) | ns per sample (wall) |")
    a("|---|---:|---:|---:|---:|")
    for r in step_rows:
        a(
            f"| {r['what']} | {r['rate']:g} Hz | {r['modes'] or '-'} | {r['ns']:.0f} | "
            f"{r['ns_wall']:.0f} |"
        )
    a("")
    for rate in sorted({r["rate"] for r in step_rows}):
        rr = {r["what"]: r["ns"] for r in step_rows if r["rate"] == rate}
        steppers = (
            rr["G_t stepper (zoh, as in the model)"] + rr["G_d stepper (linear, as in the model)"]
        )
        chain = steppers + rr["hysteresis `apply` on a 1-sample array"]
        chain_sc = steppers + rr["scalar hysteresis step (sketch in this file, same output)"]
        stream = rr["`ModelStream.process` on 1-sample blocks"]

        budget = 1e9 / rate  # ns per sample at this loop rate

        def verdict(ns: float, budget: float = budget) -> str:
            share = ns / budget
            word = (
                "fits"
                if share < 0.5
                else "fits only just (little room for control law and I/O)"
                if share < 1
                else "does **not** fit"
            )
            return f"{ns / 1e3:.0f} us = {share:.0%} of the budget, {word}"

        a(
            f"- {rate:g} Hz loop (budget {budget / 1e3:.0f} us per sample, banks built for this "
            f"rate): two steppers + hysteresis `apply`: {verdict(chain)}; two steppers + a "
            f"scalar hysteresis step: {verdict(chain_sc)}; `ModelStream.process` per sample: "
            f"{verdict(stream)}."
        )
    a("")
    return "\n".join(L)


#: RESULTS.md below this line holds the runner, fit and control benchmarks; kept on rewrite
OTHER_MARKER = "<!-- other benchmarks: kept by bench_model.py -->"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small sizes; print, do not write")
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("RESULTS.md"))
    ap.add_argument("--blas-default", action="store_true", help="keep the default BLAS threads")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    info = machine_info()
    print(f"machine: {info['cpu']}, {info['cores']} cores, load {info['load']}", flush=True)
    if args.quick:
        sizes, reps = [10_000, 100_000], {10_000: 3, 100_000: 3}
        gl_sizes, split_n, conv_k, step_n, bank_n = (
            [2_000, 5_000],
            100_000,
            [1, 2, 4],
            2_000,
            20_000,
        )
    else:
        sizes = [10_000, 1_000_000, 10_000_000]
        reps = {10_000: 21, 1_000_000: 11, 10_000_000: 3}
        gl_sizes, split_n, conv_k, step_n, bank_n = (
            [10_000, 20_000, 50_000], 1_000_000, [1, 2, 4, 8, 16], 20_000, 100_000)  # fmt: skip

    print("1. predict throughput", flush=True)
    rows, cold = bench_predict(sizes, reps)
    agree = agreement(split_n)
    split = split_fast(split_n, 5)
    split["exact"] = split_exact(split_n, 3)
    recursion = bench_recursion(split_n, 3)
    print("2. banks", flush=True)
    banks = bench_banks(bank_n, [1000.0, 10000.0])
    print("3. compilation", flush=True)
    comp = {} if args.quick else bench_compile()
    print("4. GL convergence and comparison", flush=True)
    conv = {
        "G_t": ("10 ms <= t <= 1 s", gl_convergence(G_T, 1.0, 0.01, conv_k)),
        "G_d": ("10 ms <= t <= 0.2 s", gl_convergence(G_D, 0.2, 0.01, conv_k)),
    }
    gl_rows = bench_gl(gl_sizes, 5)
    print("5. per-sample cost", flush=True)
    step_rows = bench_stepper(step_n, [1000.0, 10000.0])

    elapsed = time.perf_counter() - t_start
    info["load_end"] = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    text = render(info, rows, cold, agree, split, split_n, recursion, banks, bank_n, comp, conv,
                  gl_rows, step_rows, elapsed)  # fmt: skip
    if args.quick:
        print(text)
    else:
        old = args.out.read_text() if args.out.exists() else ""
        if OTHER_MARKER in old:
            text = text.rstrip("\n") + "\n\n" + old[old.index(OTHER_MARKER) :]
        tmp = args.out.with_suffix(".md.tmp")
        tmp.write_text(text)
        tmp.replace(args.out)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
