"""The four-waveform stand-in through the commands a user types: predicting a waveform the fit
never saw.

Run from the repository root (markdown on stdout, the commands' JSON kept in ``--work``):

    nice -n 10 .venv/bin/python benchmarks/bench_waveforms.py --work /tmp/waveforms   # seed 1
    nice -n 10 .venv/bin/python benchmarks/bench_waveforms.py --work /tmp/w2 --also  # + structural

What it does (:mod:`labrig.studies.waveforms` holds the captures and their truth):

1. ``python -m labrig.studies.waveforms WORK`` writes the four captures as CSV;
2. ``labrig import`` of each (one run file per capture) and of the four together (``all.h5``);
3. ``labrig validate --leave-one-out`` the four ``--diagnose --json``: every model identified on
   three captures predicts the fourth, ours with what diagnose accepts on those three;
4. ``labrig diagnose all.h5 --json`` (with ``--also``: also with the structural candidates and
   ``--max-effects 3``, as the command's hint proposes);
5. ``labrig fit`` of each capture alone and of the four, for the operator's parameters and
   their correlation (does it collapse?), and the resonance the fitted ``G_d`` is by itself
   (:func:`labrig.model.effects.mechanical_resonance.relaxor_resonance`);
6. with ``--resonance``: the PRBS predicted from the other three with effects given to
   ``labrig validate --effects-from`` (``negative_field_asymmetry`` alone, with
   ``mechanical_resonance``, with ``amplifier_bandwidth`` and ``mechanical_resonance``): the
   held-out NRMSE, the fitted resonance and where in frequency the held-out residual's energy
   lies (shares below 5, 50, 150 Hz ... of the residual's spectrum).

Measured: NRMSE (%) of each held-out capture for every model, the noise floor, what diagnose
accepts, the fitted ``gamma``, ``vc`` and their correlation, and the CPU seconds of every
command (user + system of the child, ``resource.getrusage``), with a yardstick (``numpy.sort``
of 1e6 floats, best of 5) timed at the start and the end and the load average.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import resource
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from yardstick import yardstick_s

from labrig.model.effects.mechanical_resonance import relaxor_resonance

ROOT = Path(__file__).resolve().parents[1]
LABRIG = [sys.executable, "-m", "labrig"]
NAMES = ("sine_50Hz", "sine_100Hz", "triangle_100Hz", "prbs")
STRUCTURAL = (
    "remanence",
    "amplifier_bandwidth",
    "mechanical_resonance",
    "negative_field_asymmetry",
    "rate_hysteresis",
    "sensor_drift",
)


def run(args: list[str], out: Path | None = None) -> tuple[float, str]:
    """Run a command (at this process's niceness), its stdout to ``out``; CPU s of the child
    and its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(out, "w") if out else open(os.devnull, "w") as f:
        p = subprocess.run(args, stdout=f, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr}")
    return cpu, p.stderr


def load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


#: the bands (Hz) of the held-out residual's spectrum in the ``--resonance`` section
BANDS = (0.0, 5.0, 50.0, 150.0, 400.0, 900.0, 1600.0, 5001.0)
#: the effects given to ``validate --effects-from`` in the ``--resonance`` section
FORCED = (
    ("negative_field_asymmetry",),
    ("negative_field_asymmetry", "mechanical_resonance"),
    ("negative_field_asymmetry", "amplifier_bandwidth", "mechanical_resonance"),
)


def band_shares(measured: np.ndarray, predicted: np.ndarray, rate_hz: float) -> list[float]:
    """Share of the residual's energy (mean removed) in each of :data:`BANDS` (Hz)."""
    r = measured - predicted
    spec = np.abs(np.fft.rfft(r - r.mean())) ** 2
    f = np.fft.rfftfreq(r.size, 1.0 / rate_hz)
    total = float(np.sum(spec[1:]))
    return [float(np.sum(spec[(f >= a) & (f < b)])) / total for a, b in itertools.pairwise(BANDS)]


def resonance_section(w: Path, h5s: list[Path]) -> list[tuple[str, float, str]]:
    """The PRBS predicted from the other three captures with :data:`FORCED` effects
    (``labrig.commands.validate.validate_runs`` with ``effects_from``, in this process):
    markdown rows on stdout, the CPU row of each."""
    import time

    from labrig.commands.validate import validate_runs

    train, test = h5s[:-1], h5s[-1]
    print("\n## The PRBS predicted from the other three with effects given (--effects-from)\n")
    heads = " | ".join(f"{a:g}-{b:g} Hz" for a, b in itertools.pairwise(BANDS))
    print(f"| effects | PRBS NRMSE % | fitted resonance | residual energy: {heads} | CPU s |")
    print("|---|---|---|" + "---|" * (len(BANDS) - 1) + "---|")
    rows = []
    for fx in FORCED:
        doc = w / f"forced_{'_'.join(fx)}.json"
        doc.write_text(json.dumps({"effects_added": [{"effect": e, "params": {}} for e in fx]}))
        t0 = time.process_time()
        v = validate_runs(train, [test], effects_from=doc)
        cpu = time.process_time() - t0
        m = v.models["dynamic+effects"]
        rec = v.tests[0].scored_records[0]
        i0 = round(max(v.tests[0].warmup_s, 0.0) * rec.rate_hz)
        pred = m.predictions[(str(test), rec.name)]
        shares = band_shares(rec.strain_ue[i0:], pred[i0:], rec.rate_hz)
        res = [e["description"] for e in m.params.get("effects", []) if e["effect"] == fx[-1]]
        print(
            f"| {' + '.join(fx)} | {m.mean('whole_nrmse_pct'):.3g} | "
            f"{res[0] if res and fx[-1] == 'mechanical_resonance' else '-'} | "
            + " | ".join(f"{100 * x:.1f} %" for x in shares)
            + f" | {cpu:.1f} |",
            flush=True,
        )
        rows.append((f"validate prbs --effects-from ({' + '.join(fx)})", cpu, load()))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--truth", default="stack")
    ap.add_argument("--also", action="store_true", help="also diagnose with --also (slow)")
    ap.add_argument("--no-validate", action="store_true", help="skip the leave-one-out")
    ap.add_argument(
        "--resonance", action="store_true", help="also the PRBS with effects given (slow)"
    )
    ap.add_argument("--no-diagnose", action="store_true", help="skip diagnose all.h5")
    a = ap.parse_args()
    w = a.work
    w.mkdir(parents=True, exist_ok=True)
    y0 = yardstick_s()
    print(f"# four-waveform stand-in, seed {a.seed}, truth {a.truth}")
    print(
        f"\n{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, load {load()}, "
        f"yardstick {y0 * 1e3:.1f} ms\n"
    )
    rows: list[tuple[str, float, str]] = []
    cpu, _ = run(
        [
            *LABRIG[:2],
            "labrig.studies.waveforms",
            str(w),
            "--seed",
            str(a.seed),
            "--truth",
            a.truth,
            "--overwrite",
        ]
    )
    rows.append(("write the four captures (simulation)", cpu, load()))
    csvs = [w / f"{n}.csv" for n in NAMES]
    h5s = [w / f"{n}.h5" for n in NAMES]
    for c, h in zip(csvs, h5s, strict=True):
        cpu, _ = run([*LABRIG, "import", str(c), "--out", str(h), "--overwrite"])
    rows.append(("labrig import (one capture, the last)", cpu, load()))
    cpu, _ = run([*LABRIG, "import", *map(str, csvs), "--out", str(w / "all.h5"), "--overwrite"])
    rows.append(("labrig import (the four into all.h5)", cpu, load()))

    fits = {}
    for name, path in [*zip(NAMES, h5s, strict=True), ("all four", w / "all.h5")]:
        out = w / f"fit_{path.stem}.json"
        cpu, _ = run([*LABRIG, "fit", str(path), "--json"], out)
        fits[name] = (json.loads(out.read_text()), cpu)
    print("## Our model fitted on each capture alone and on the four\n")
    print(
        "| fitted on | gamma (ue/V) | vc (V) | corr(gamma, vc) | unidentifiable | NRMSE % "
        "| G_d (order, tau) and its own resonance | CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, (d, cpu) in fits.items():
        p, u, c = d["params"], d["uncertainty"], d["correlation"]
        unid = ", ".join(d.get("identifiability", {}).get("unidentifiable", {})) or "none"
        gd = relaxor_resonance(p["lam_d"], p["tau_d_s"])
        ring = "none" if gd is None else f"{gd[0]:.4g} Hz, zeta {gd[1]:.3f}"
        print(
            f"| {name} | {p['gamma_ue_per_V']:.3g} +- {u['gamma_ue_per_V'] or 0:.2g} | "
            f"{p['vc_V']:.4g} +- {u['vc_V'] or 0:.2g} | "
            f"{c['gamma_ue_per_V']['vc_V']:+.3f} | {unid} | {d['nrmse_pct']:.3g} | "
            f"{p['lam_d']:.3g}, {1e3 * p['tau_d_s']:.3g} ms: {ring} | {cpu:.1f} |"
        )

    if not a.no_validate:
        out = w / "loo.json"
        cpu, _ = run(
            [*LABRIG, "validate", "--leave-one-out", *map(str, h5s), "--diagnose", "--json"], out
        )
        rows.append(("labrig validate --leave-one-out (4 folds, --diagnose)", cpu, load()))
        doc = json.loads(out.read_text())
        print("\n## Leave one record out: NRMSE % of the held-out capture (whole record)\n")
        print("| model | " + " | ".join(NAMES) + " | mean | mean (second half) |")
        print("|---|" + "---|" * (len(NAMES) + 2))
        for m in doc["models"].values():
            cells = [m["per_file"].get(str(h)) for h in h5s]
            print(
                f"| {m['label']} | "
                + " | ".join("-" if x is None else f"{x:.3g}" for x in cells)
                + f" | {m['whole_nrmse_pct']:.3g} | {m['second_half_nrmse_pct']:.3g} |"
            )
        print(f"| noise floor | | | | | {doc['noise_floor_pct']:.3g} | |")
        print("\nWhat diagnose accepted on each fold's three training captures:\n")
        for name, fold in zip(NAMES, doc["folds"], strict=True):
            eff = fold["effects"]
            label = fold["models"].get("dynamic+effects", {}).get("label", "")
            print(f"- {name} held out: {', '.join(eff) if eff else 'nothing'} ({label})")

    if a.resonance:
        rows += resonance_section(w, h5s)

    variants = [] if a.no_diagnose else [("labrig diagnose all.h5", [])]
    if a.also:
        also = [x for n in STRUCTURAL for x in ("--also", n)] + ["--max-effects", "3"]
        variants.append(("labrig diagnose all.h5 --also (6 structural) --max-effects 3", also))
    for k, (label, extra) in enumerate(variants):
        out = w / f"diagnosis{k}.json"
        cpu, _ = run([*LABRIG, "diagnose", str(w / "all.h5"), "--json", *extra], out)
        rows.append((label, cpu, load()))
        d = json.loads(out.read_text())
        print(f"\n## {label}\n\n{d['headline']}\n")
        for e in d["effects_added"]:
            p = {k2: v for k2, v in e["params"].items() if not k2.endswith("_sd")}
            print(f"- added {e['effect']}: {json.dumps(p)[:300]}")
        print(f"\n{d['verdict']}")

    y1 = yardstick_s()
    ys = min(y0, y1)
    print("\n## CPU per command\n")
    print(f"yardstick {y0 * 1e3:.1f} ms at the start, {y1 * 1e3:.1f} ms at the end\n")
    print("| command | CPU s | yardsticks | load after |")
    print("|---|---|---|---|")
    for label, cpu, ld in rows:
        print(f"| {label} | {cpu:.1f} | {cpu / ys:.0f} | {ld} |")


if __name__ == "__main__":
    main()
