"""Diagnosis on the drives and effects other labs' data show, beside the data-driven peers
(issue "close the loop on measured data from other labs").

Writes a markdown report on stdout (``python benchmarks/study_real_drives.py [table|nulls|
effects|timing|smart|contraction|readings|all] [--margins]``); the figures are copied into
docs/diagnose.md and the README.

- ``table``: held-out NRMSE per dataset: ours before and after diagnose's effects (diagnose's
  scoring: each left-out entry's second half, in % of its span), Prandtl-Ishlinskii, Bouc-Wen and
  SINDy (leave-one-entry-out over whole entries), and the noise floor; the real micromanipulator
  records (each cut into 4 parts, as ``labrig diagnose`` does with one entry) and every simulated
  campaign of the study.
- ``nulls``: no effect on the bench, 10 seeds on each drive (short sines, bipolar, biased growing
  envelopes): how often diagnose adds something.
- ``effects``: each bench effect on its drives, seeds 1-3: the first effect named, the held-out
  ratio, the fitted size against the bench's.
- ``timing``: diagnose on the real 14 155-sample record and on a 50 000-sample simulated record.
- ``smart``: the sparse ODE's rate robustness: ``diagnose`` of the real SmartHysteresis record
  (2 periods kept at 1 kHz) at 1 kHz and decimated (every 2nd, 4th, 5th row: 500, 250,
  200 Hz), and of the simulated whole-file stand-in (:mod:`labrig.studies.smart_standin`: 10 s,
  7.36 s idle then 2.64 periods, seed 1) at 5 kHz, 10 kHz and 1 kHz, with the stand-in truth's
  own held-out score (the noise floor's reference); CPU seconds of each diagnosis
  (``time.process_time``) and their ratio to the yardstick (``numpy.sort`` of 1e6 floats).
- ``contraction``: the sparse ODE alone (its five identifications and their scoring, as
  ``sparse_ode_trial`` runs them, offset the only nuisance term) on the real SmartHysteresis,
  ``Model_Vi_Do`` and ``Test_Vi_Do_Di`` records and the 5 kHz stand-in: held-out NRMSE, the
  identified ODE's growth rate under the records' drive (``growth_rate``), the stroke of its
  free run over the 1st, 2nd and 20th period of the records' own drive repeated (the
  SmartHysteresis drive, ``150 sin(2 pi t)``; for the micromanipulator records their own
  record played 5 times), the separation after 20 periods of two free runs started 1 ue apart,
  and CPU seconds (``time.process_time``; ratio to the yardstick). ``--margins`` also scans
  the contraction margin (``contraction.MARGIN_PER_PERIOD``) on SmartHysteresis.
- ``readings``: the sparse ODE alone (as ``contraction``) on the SmartHysteresis record read
  the ways an independent review found the selection fragile (the rate to its last digits,
  samples dropped, resampled to 500 Hz, 2 kHz and 5 kHz, the voltage jittered by 1e-9), and on
  a whole-file-like record built from it (7.36 s at rest, 2.64 periods, 5 kHz).
"""

from __future__ import annotations

import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from labrig.analysis.baselines import fit_baseline  # noqa: E402
from labrig.analysis.diagnose import diagnose, split_entries  # noqa: E402
from labrig.analysis.records import Record  # noqa: E402
from labrig.studies.campaign import study_campaign  # noqa: E402

REAL = ROOT / "tests" / "data" / "real" / "yan9a-micromanipulator"

#: the simulated datasets of the table: (label, study case, drive)
SIMULATED = (
    ("paper truth, no effect, short sines", "none", "short"),
    ("paper truth, no effect, bipolar +-150 V", "none", "bipolar"),
    ("paper truth, no effect, biased envelopes", "none", "biased"),
    ("field saturation, bipolar", "field_saturation", "bipolar"),
    ("field saturation, biased envelopes", "field_saturation", "biased"),
    ("slow viscoelastic mode, short sines", "viscoelastic_creep", "short"),
    ("gain rising with field (cubic, outside the library), bipolar", "cubic_term", "bipolar"),
)


def real_records(name: str) -> list[Record]:
    """A real record as ``labrig import FILE --voltage 1 --strain 5 --rate-hz 200 --strain-units
    raw`` reads it, cut into 4 chained parts (what diagnose does with one entry)."""
    data = np.loadtxt(REAL / name)
    rec = Record.from_arrays(name.split(".")[0], 200.0, data[:, 0], data[:, 4], hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


SMART = ROOT / "tests" / "data" / "real" / "chandratue-SmartHysteresis"


def smart_records() -> list[Record]:
    """The SmartHysteresis record (2 periods of +-150 V at 1 Hz, 1 kHz; displacement in um kept
    raw) as ``labrig import FILE --time 2 --voltage 4 --strain 3 --strain-units raw`` reads it,
    cut into 4 chained parts (what diagnose does with one entry)."""
    rows = np.loadtxt(
        SMART / "hysteresis_v_150_1hz_2cycles_1khz.csv", delimiter=",", usecols=(1, 2, 3)
    )
    rec = Record.from_arrays("smart", 1000.0, rows[:, 2], rows[:, 1], hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def peers(records: list[Record], offset: bool) -> dict[str, float | None]:
    out = {}
    for kind in ("prandtl_ishlinskii", "bouc_wen", "sindy"):
        try:
            res = fit_baseline(records, kind, heldout=True, chain=True, offset=offset)
            out[kind] = res.heldout_nrmse_pct
        except Exception as exc:  # a peer that fails is reported, not fatal
            print(f"    ({kind} failed: {exc})", file=sys.stderr)
            out[kind] = None
    return out


def row(label: str, records: list[Record], offset: bool) -> str:
    t0 = time.perf_counter()
    d = diagnose(records, offset=offset)
    dt = time.perf_counter() - t0
    p = peers(records, offset)
    added = ", ".join(e["effect"] for e in d.effects_added) or "none"

    def f(x: float | None) -> str:
        return "-" if x is None else f"{x:.3g}"

    return (
        f"| {label} | {f(d.before['heldout_nrmse_pct'])} | {f(d.after['heldout_nrmse_pct'])} "
        f"({added}) | {f(p['prandtl_ishlinskii'])} | {f(p['bouc_wen'])} | {f(p['sindy'])} | "
        f"{f(d.evidence_before.floor_pct)} | {d.classification} | {dt:.0f} s |"
    )


def table() -> None:
    print("## Held-out NRMSE (%) per dataset\n")
    print(
        "| dataset | ours | ours + effects found | PI | Bouc-Wen | SINDy | noise floor | verdict "
        "| diagnose time |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("Model_Vi_Do.dat", "Test_Vi_Do_Di.dat"):
        print(row(f"real: {name} (4 parts)", real_records(name), offset=True), flush=True)
    print(row("real: SmartHysteresis +-150 V 1 Hz (4 parts)", smart_records(), True), flush=True)
    for label, case, drive in SIMULATED:
        print(row(label + " (seed 1)", study_campaign(case, 1, drive=drive), False), flush=True)


def nulls(seeds: range = range(1, 11)) -> None:
    print("\n## Nulls: no effect on the bench\n")
    print("| drive | seeds | something added | what | time per seed |")
    print("|---|---|---|---|---|")
    for drive in ("short", "bipolar", "biased"):
        added, t0 = [], time.perf_counter()
        for s in seeds:
            d = diagnose(study_campaign("none", s, drive=drive))
            if d.effects_added:
                added.append(f"seed {s}: " + ", ".join(e["effect"] for e in d.effects_added))
        per = (time.perf_counter() - t0) / len(seeds)
        what = "; ".join(added) or "-"
        print(f"| {drive} | {len(seeds)} | {len(added)} | {what} | {per:.0f} s |", flush=True)


#: bench size of each case, and the fitted parameter that measures it
SIZES = {
    "field_saturation": ("s", 0.0500, "gain loss at full scale"),
    "viscoelastic_creep": ("c", 0.06, "fraction c"),
}


def effects(seeds: range = range(1, 4)) -> None:
    print("\n## Effects: named first, held-out, size\n")
    print("| case | drive | seed | first added | held-out before -> after | fitted (bench) |")
    print("|---|---|---|---|---|---|")
    for case in ("field_saturation", "viscoelastic_creep", "cubic_term"):
        drives = {"field_saturation": ("bipolar", "biased"), "cubic_term": ("bipolar",)}
        for drive in drives.get(case, ("short",)):
            for s in seeds:
                d = diagnose(study_campaign(case, s, drive=drive))
                first = d.effects_added[0] if d.effects_added else None
                size = "-"
                if first and case in SIZES and first["effect"] == case:
                    key, bench, _what = SIZES[case]
                    size = f"{first['params'][key]:.4g} ({bench:g})"
                if first and case == "cubic_term":
                    size = f"V^3 {first['params'].get('c_V3', float('nan')):.3g} ue"
                print(
                    f"| {case} | {drive} | {s} | {first['effect'] if first else 'none'} | "
                    f"{d.before['heldout_nrmse_pct']:.3g} -> {d.after['heldout_nrmse_pct']:.3g} | "
                    f"{size} |",
                    flush=True,
                )


def timing() -> None:
    print("\n## Diagnose time on long records\n")
    data = np.loadtxt(REAL / "Test_Vi_Do_Di.dat")
    rec = Record.from_arrays("Test_Vi_Do_Di", 200.0, data[:, 0], data[:, 4], hold="linear")
    rec.meta["kind"] = "import"
    t0 = time.perf_counter()
    diagnose(split_entries([rec], 4), offset=True)
    print(f"- real record, {rec.n} samples: {time.perf_counter() - t0:.0f} s")
    recs = study_campaign("none", 1, drive="biased")
    v = np.concatenate([r.voltage_V for r in recs])
    s = np.concatenate([r.strain_ue for r in recs])
    n = 50_000
    reps = -(-n // v.size)
    long = Record.from_arrays("long", recs[0].rate_hz, np.tile(v, reps)[:n], np.tile(s, reps)[:n])
    t0 = time.perf_counter()
    diagnose(split_entries([long], 4))
    print(f"- simulated single record, {n} samples: {time.perf_counter() - t0:.0f} s")


def _smart_row(label: str, records: list[Record], truth: str = "-") -> str:
    t0 = time.process_time()
    d = diagnose(records, offset=True)
    cpu = time.process_time() - t0
    ode = next((c for c in d.candidates if c["effect"] == "sparse_ode"), None)
    held = (
        "-"
        if ode is None or ode["heldout_nrmse_pct"] is None
        else f"{ode['heldout_nrmse_pct']:.3g}"
    )
    adopted = bool(d.effects_added) and d.effects_added[-1]["effect"] == "sparse_ode"
    added = ", ".join(e["effect"] for e in d.effects_added) or "none"
    return (
        f"| {label} | {records[0].n * len(records)} | {d.before['heldout_nrmse_pct']:.3g} | "
        f"{held} ({'adopted' if adopted else 'not adopted'}) | {d.after['heldout_nrmse_pct']:.3g}"
        f" ({added}) | {d.evidence_before.floor_pct:.3g} | {truth} | {cpu:.1f} s | "
        f"{cpu / YARD[0]:.0f} |"
    )


#: the yardstick's CPU seconds in this run (set by :func:`smart`)
YARD = [float("nan")]


def _standin(rate_hz: float) -> list[Record]:
    from labrig.studies.smart_standin import standin_rows

    rows = standin_rows(1, rate_hz)
    rec = Record.from_arrays("standin", rate_hz, rows[:, 2], rows[:, 1], hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def _truth_heldout(records: list[Record]) -> float:
    """The stand-in truth's own held-out NRMSE (%) by the sparse-ODE scoring (offset fitted on
    the first half of each part, scored on the second): the noise floor's reference."""
    from labrig.analysis.diagnose.sparse_ode import entry_score
    from labrig.analysis.simulate import scored_sequences
    from labrig.analysis.sindy import SindyBaseline
    from labrig.studies.smart_standin import TRUTH_XI

    scored = scored_sequences(records, [r.name for r in records], 0.0, True)
    model = SindyBaseline(TRUTH_XI, records[0].rate_hz, 0.0)
    ones = lambda t, _rate: np.ones((t.size, 1))  # noqa: E731
    return float(np.mean([entry_score(scored, model, r.name, ones, True)[0] for r in records]))


def smart() -> None:
    from yardstick import yardstick_s

    YARD[0] = yardstick_s()
    print("\n## The sparse ODE across sample rates (SmartHysteresis)\n")
    print(f"yardstick (numpy.sort of 1e6 floats, best of 5): {YARD[0] * 1e3:.1f} ms CPU\n")
    print(
        "| record | samples | base held-out | sparse ODE held-out | final (added) | floor | "
        "truth's held-out | CPU | CPU / yardstick |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    rows = np.loadtxt(
        SMART / "hysteresis_v_150_1hz_2cycles_1khz.csv", delimiter=",", usecols=(1, 2, 3)
    )
    for step in (1, 2, 4, 5):
        rec = Record.from_arrays(
            "smart", 1000.0 / step, rows[::step, 2], rows[::step, 1], hold="linear"
        )
        rec.meta["kind"] = "import"
        nth = {2: "2nd", 4: "4th", 5: "5th"}.get(step)
        label = f"real, 2 periods at {1000 / step:.0f} Hz" + (f" (every {nth} row)" if nth else "")
        print(_smart_row(label, split_entries([rec], 4)), flush=True)
    for rate in (5000.0, 10000.0, 1000.0):
        recs = _standin(rate)
        truth = f"{_truth_heldout(recs):.3g}"
        print(
            _smart_row(f"SIMULATED stand-in, whole file at {rate:.0f} Hz", recs, truth), flush=True
        )


def _sparse_ode_alone(records: list[Record]) -> dict[str, float | str]:
    """The sparse ODE's five identifications on ``records`` and their held-out score (as
    ``sparse_ode_trial``, offset the only nuisance term), its growth rate, the stroke (max -
    min) of its free run over periods 1, 2 and 20 of the drive repeated, the separation of two
    free runs 1 ue apart after them, and the CPU seconds of the identifications and scoring."""
    from labrig.analysis.baseline_kernels import sindy_free_run
    from labrig.analysis.diagnose.sparse_ode import cross_validate, growth_rate
    from labrig.analysis.sindy import equilibrium

    t0 = time.process_time()
    cv = cross_validate(records, [r.name for r in records], 0.0, True, True)
    cpu = time.process_time() - t0
    model, held = cv.model, list(cv.heldout.values())
    seq = cv.work[0][0]
    rate = records[0].rate_hz
    if records[0].name.startswith("smart") or records[0].name.startswith("standin"):
        per = round(rate)  # one period of the 1 Hz drive
        one = 150.0 * np.sin(2 * np.pi * np.arange(per) / rate)
    else:  # the record's own voltage as one "period"
        one = np.asarray(seq.voltage_V, dtype=float)
        per = one.size
    reps = 20 if per <= 20_000 else 5
    v = np.concatenate(([float(one[0])], np.tile(one, reps)))
    xi = np.asarray(model.coefficients, dtype=float)
    s0 = equilibrium(xi, float(v[0]))
    a = sindy_free_run(xi, v, rate, s0, np.inf)
    b = sindy_free_run(xi, v, rate, s0 + 1.0, np.inf)
    stroke = [float(np.ptp(a[1 + k * per : 1 + (k + 1) * per])) for k in (0, 1, reps - 1)]
    return {
        "heldout": float(np.mean(held)),
        "folds": " / ".join(f"{h:.3g}" for h in held),
        "growth": growth_rate(model, cv.work),
        "stroke": " / ".join(f"{x:.4g}" for x in stroke) + f" ({reps} periods)",
        "separation": float(abs(b[-1] - a[-1])),
        "cpu": cpu,
        "equation": model.equation(),
    }


def _readings() -> list[tuple[str, list[Record]]]:
    """The SmartHysteresis record read the ways an independent review tried (2026-11-27): the
    rate from the time column or stated, samples dropped at either end, resampled (``resample
    _poly``, line padding), the voltage jittered by 1e-9 relative; and a whole-file-like
    record built from it (the file's 7.36 s at rest, then the drive from its start: the 0.41 s
    before the kept rows and the 0.23 s after them taken one period away, the whole at 5 kHz)."""
    from scipy.signal import resample_poly

    rows = np.loadtxt(
        SMART / "hysteresis_v_150_1hz_2cycles_1khz.csv", delimiter=",", usecols=(1, 2, 3)
    )
    t, s, v = rows[:, 0], rows[:, 1], rows[:, 2]

    def cut(rate: float, volts: np.ndarray, strain: np.ndarray) -> list[Record]:
        rec = Record.from_arrays("smart", rate, volts, strain, hold="linear")
        rec.meta["kind"] = "import"
        return split_entries([rec], 4)

    def up(x: np.ndarray, k: int) -> np.ndarray:
        return resample_poly(x, k, 1, padtype="line")

    def down(x: np.ndarray) -> np.ndarray:
        return resample_poly(x, 1, 2, padtype="line")

    k = t.size // 100
    out = [
        ("as `labrig import --time 2` reads it (1000.01 Hz)", cut(1000.0100000996063, v, s)),
        ("first to last time stamp (1000.000005 Hz)", cut((t.size - 1) / (t[-1] - t[0]), v, s)),
        ("1000.0000000005542 Hz", cut(1000.0000000005542, v, s)),
        ("exactly 1000 Hz", cut(1000.0, v, s)),
        ("first 1 % of samples dropped", cut(1000.0, v[k:], s[k:])),
        ("last 1 % dropped", cut(1000.0, v[:-k], s[:-k])),
        ("resampled to 500 Hz", cut(500.0, down(v), down(s))),
        ("resampled to 2 kHz", cut(2000.0, up(v, 2), up(s, 2))),
        ("resampled to 5 kHz", cut(5000.0, up(v, 5), up(s, 5))),
    ]
    for seed in (1, 2, 3, 4):
        jitter = 1e-9 * np.random.default_rng(seed).normal(size=v.size)
        out.append((f"voltage jittered by 1e-9, seed {seed}", cut(1000.0, v * (1 + jitter), s)))
    # the drive 150 sin(2 pi t - 46.2178545458) V starts at 7.3558 s, the kept rows at 7.769 s
    # and the file ends at 10 s: the 413 samples before and the 231 after them, one period away
    on_s = 46.2178545458 / (2 * np.pi)
    lead = round((t[0] - on_s) * 1000.0)
    tail = round((10.0 - t[-1]) * 1000.0) - 1
    sv = np.concatenate((np.zeros(round(on_s * 1000.0)), v[1000 - lead : 1000], v, v[:tail]))
    ss = np.concatenate((s[1000 - lead : 1000], s, s[:tail]))
    ss = np.concatenate((np.full(sv.size - ss.size, ss[0]), ss))
    whole = cut(5000.0, up(sv, 5), up(ss, 5))
    out.append(("whole-file-like at 5 kHz (7.36 s at rest, then 2.64 periods)", whole))
    return out


def readings() -> None:
    """The ``readings`` report (module docstring)."""
    from yardstick import yardstick_s

    YARD[0] = yardstick_s()
    print("\n## The sparse ODE on the SmartHysteresis record read several ways\n")
    print(f"yardstick (numpy.sort of 1e6 floats, best of 5): {YARD[0] * 1e3:.1f} ms CPU\n")
    print("| the record as | held-out % (folds) | CPU s | CPU / yardstick | equation |")
    print("|---|---|---|---|---|")
    for label, recs in _readings():
        r = _sparse_ode_alone(recs)
        print(
            f"| {label} | {r['heldout']:.4g} ({r['folds']}) | {r['cpu']:.1f} | "
            f"{r['cpu'] / YARD[0]:.0f} | `{r['equation']}` |",
            flush=True,
        )


def contraction(margins: bool = False) -> None:
    """The ``contraction`` report (module docstring)."""
    from yardstick import yardstick_s

    YARD[0] = yardstick_s()
    print("\n## The sparse ODE alone: held-out, growth and a long drive\n")
    print(f"yardstick (numpy.sort of 1e6 floats, best of 5): {YARD[0] * 1e3:.1f} ms CPU\n")
    print(
        "| record | held-out % (folds) | growth 1/s | stroke: period 1 / 2 / last | separation "
        "after the last (from 1) | CPU s | CPU / yardstick | equation |"
    )
    print("|---|---|---|---|---|---|---|---|")
    recs = (
        ("real SmartHysteresis, 2 periods at 1 kHz", smart_records),
        ("real Model_Vi_Do", lambda: real_records("Model_Vi_Do.dat")),
        ("real Test_Vi_Do_Di", lambda: real_records("Test_Vi_Do_Di.dat")),
        ("SIMULATED stand-in at 5 kHz", lambda: _standin(5000.0)),
    )
    for label, make in recs:
        r = _sparse_ode_alone(make())
        print(
            f"| {label} | {r['heldout']:.4g} ({r['folds']}) | {r['growth']:+.3g} | {r['stroke']} "
            f"| {r['separation']:.3g} | {r['cpu']:.1f} | {r['cpu'] / YARD[0]:.0f} | "
            f"`{r['equation']}` |",
            flush=True,
        )
    if margins:
        import labrig.analysis.diagnose.contraction as contr

        keep = contr.MARGIN_PER_PERIOD
        print("\nMargin scan on SmartHysteresis (fraction per drive period):\n")
        print("| margin | held-out % (folds) | growth 1/s | stroke | CPU s |")
        print("|---|---|---|---|---|")
        for m in (0.01, 0.05, 0.1, 0.3, 1.0):
            contr.MARGIN_PER_PERIOD = m
            r = _sparse_ode_alone(smart_records())
            print(
                f"| {m} | {r['heldout']:.4g} ({r['folds']}) | {r['growth']:+.3g} | "
                f"{r['stroke']} | {r['cpu']:.1f} |",
                flush=True,
            )
        contr.MARGIN_PER_PERIOD = keep


def main() -> None:
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    load = os.getloadavg()
    print(
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; {datetime.now(UTC):%Y-%m-%d %H:%M} UTC; "
        f"load average at start {load[0]:.1f}\n"
    )
    jobs = (("table", table), ("nulls", nulls), ("effects", effects), ("timing", timing))
    scan = "--margins" in sys.argv[2:]
    more = (("smart", smart), ("contraction", lambda: contraction(scan)), ("readings", readings))
    for name, fn in (*jobs, *more):
        if what in (name, "all"):
            fn()
    print(f"\nload average at end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
