"""The structural study: does ``labrig diagnose --also`` find each structural effect, and does
asking for them leave the nulls alone?

Run from the repository root (markdown on stdout; each finished diagnosis is also appended as
one JSON line to ``--log``, with every candidate of every round: its ranking score, its
held-out NRMSE and why it was refused; so a cut-short run keeps what it measured):

    .venv/bin/python benchmarks/bench_structural_study.py                 # seeds 1-3, 30 nulls
    .venv/bin/python benchmarks/bench_structural_study.py --seeds 1 --nulls 1   # a quick look

What is measured (:mod:`labrig.studies.structural` holds the campaigns and truths):

- **Effects**: each structural library effect has a bench truth of another form on the bench
  (``amplifier_output_rc`` for ``amplifier_bandwidth``, ``stack_resonance`` for
  ``mechanical_resonance``, ``depoling`` for ``negative_field_asymmetry``, ``viscous_slip`` for
  ``rate_hysteresis``, ``gauge_warmup`` for ``sensor_drift``) and a campaign mixing sines,
  triangles, PRBS, multisines, bipolar and biased drives. For seeds 1-3, diagnose runs as
  ``labrig diagnose --also NAME...`` does (``effects = EFFECT_NAMES + structural``, ``always =
  structural``, every structural name asked for): the first effect added, all added, the verdict,
  the held-out NRMSE before and after (%) and its ratio to the noise floor (goal: after <= 1.2 x
  floor).
- **Nulls**: no structural truth (the paper truth, gauge noise only) on each campaign, seeds
  1..N per campaign (3 x 10 = 30 by default): diagnose without and with ``--also`` the
  structural names; a null's verdict changed when the classification or the effects added
  differ (goal: 0 of 30).
- CPU seconds of every diagnosis (``time.process_time``: this process and its threads), with a
  yardstick (``numpy.sort`` of 1e6 floats, best of 5) timed at the start and the end; machine,
  date and load average are printed in the header.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from yardstick import yardstick_s  # noqa: E402

from labrig.analysis.diagnose import diagnose  # noqa: E402
from labrig.model.effects import EFFECT_NAMES  # noqa: E402
from labrig.studies.structural import (  # noqa: E402
    CASES,
    NULL_DRIVES,
    STRUCTURAL_NAMES,
    structural_campaign,
)

#: the held-out goal: at most this many times the noise floor after diagnose
GOAL_FLOOR_RATIO = 1.2


def run_diagnose(records, also: tuple[str, ...], max_effects: int) -> dict:
    """One diagnosis as ``labrig diagnose --also ...`` runs it; the row's numbers."""
    t0 = time.process_time()
    try:
        d = diagnose(
            records,
            effects=EFFECT_NAMES + also,
            always=also,
            max_effects=max_effects,
        )
    except Exception as exc:  # a diagnosis that fails is a row of the study, not its end
        where = exc.__traceback__
        while where is not None and where.tb_next is not None:
            if "labrig/model/effects/" in where.tb_frame.f_code.co_filename:
                break
            where = where.tb_next
        at = "" if where is None else f" in {Path(where.tb_frame.f_code.co_filename).name}"
        print(f"    diagnose failed: {type(exc).__name__}: {exc}{at}", file=sys.stderr)
        return {
            "first": "-",
            "added": [],
            "class": f"failed: {type(exc).__name__}{at}",
            "before": float("nan"),
            "after": float("nan"),
            "floor": float("nan"),
            "ratio": None,
            "cpu_s": time.process_time() - t0,
        }
    cpu = time.process_time() - t0
    added = [e["effect"] for e in d.effects_added]
    floor = d.evidence_before.floor_pct
    after = d.after["heldout_nrmse_pct"]
    tried = [
        {
            "round": c.round + 1,
            "effect": c.effect,
            "score": round(float(c.score), 4),
            "heldout_pct": c.heldout_nrmse_pct,
            "accepted": c.accepted,
            "why": "; ".join(c.reasons) if c.tried else "not refitted",
        }
        for cands in d.rounds
        for c in cands
    ]
    return {
        "first": added[0] if added else "none",
        "added": added,
        "params": [e["params"] for e in d.effects_added],
        "candidates": tried,
        "class": d.classification,
        "before": d.before["heldout_nrmse_pct"],
        "after": after,
        "floor": floor,
        "ratio": (after / floor) if floor else None,
        "cpu_s": cpu,
    }


def _log(path: Path | None, row: dict) -> None:
    if path is not None:
        with path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")


def _done(log: Path | None, part: str) -> dict[tuple, dict]:
    """Rows of ``part`` already in ``log`` (a resumed run skips them and reprints them)."""
    if log is None or not log.is_file():
        return {}
    rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    if part == "effect":
        return {(r["case"], r["seed"]): r for r in rows if r.get("part") == part}
    return {(r["drive"], r["seed"]): r for r in rows if r.get("part") == part}


def effects(
    seeds: list[int],
    max_effects: int,
    log: Path | None,
    report_only: bool = False,
    cases: list[str] | None = None,
) -> list[dict]:
    print("\n## Structural truths: first effect named, held-out against the noise floor\n")
    print(
        "| library effect | bench truth | campaign | seed | first added | all added | verdict "
        "| held-out before -> after (%) | floor (%) | after / floor | CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    done = _done(log, "effect")
    for seed in seeds:  # every case on seed 1 first: a cut-short run still covers them all
        for case in cases or list(CASES):
            planted, drive = CASES[case]
            r = done.get((case, seed))
            if r is None and report_only:
                continue
            if r is None:
                r = run_diagnose(structural_campaign(case, seed), STRUCTURAL_NAMES, max_effects)
                r.update(part="effect", case=case, truth=planted[0]["name"], drive=drive, seed=seed)
                _log(log, r)
            rows.append(r)
            ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}"
            print(
                f"| {case} | {r['truth']} | {drive} | {seed} | {r['first']} | "
                f"{', '.join(r['added']) or 'none'} | {r['class']} | {r['before']:.3g} -> "
                f"{r['after']:.3g} | {r['floor']:.3g} | {ratio} | {r['cpu_s']:.0f} |",
                flush=True,
            )
    found = sum(r["first"] == r["case"] for r in rows)
    within = sum(r["ratio"] is not None and r["ratio"] <= GOAL_FLOOR_RATIO for r in rows)
    print(
        f"\nnamed first: {found} of {len(rows)}; held-out within {GOAL_FLOOR_RATIO} x floor: "
        f"{within} of {len(rows)}"
    )
    return rows


def nulls(
    n_seeds: int, max_effects: int, log: Path | None, report_only: bool = False
) -> list[dict]:
    print("\n## Nulls: no structural truth, without and with --also the structural names\n")
    print(
        "| campaign | seed | without: added, verdict | with --also: added, verdict | changed "
        "| CPU s (without / with) |"
    )
    print("|---|---|---|---|---|---|")
    rows = []
    done = _done(log, "null")
    for drive in NULL_DRIVES:
        for seed in range(1, n_seeds + 1):
            row = done.get((drive, seed))
            if row is None and report_only:
                continue
            if row is None:
                recs = structural_campaign(None, seed, drive=drive)
                plain = run_diagnose(recs, (), max_effects)
                asked = run_diagnose(recs, STRUCTURAL_NAMES, max_effects)
                changed = (plain["class"], plain["added"]) != (asked["class"], asked["added"])
                row = {
                    "part": "null",
                    "drive": drive,
                    "seed": seed,
                    "without": plain,
                    "with": asked,
                    "changed": changed,
                }
                _log(log, row)
            rows.append(row)
            plain, asked, changed = row["without"], row["with"], row["changed"]
            print(
                f"| {drive} | {seed} | {', '.join(plain['added']) or 'none'}, {plain['class']} | "
                f"{', '.join(asked['added']) or 'none'}, {asked['class']} | "
                f"{'yes' if changed else 'no'} | {plain['cpu_s']:.0f} / {asked['cpu_s']:.0f} |",
                flush=True,
            )
    print(f"\nverdicts changed: {sum(r['changed'] for r in rows)} of {len(rows)}")
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2,3", help="seeds of the effect campaigns")
    ap.add_argument("--nulls", type=int, default=10, help="null seeds per campaign (0: none)")
    ap.add_argument("--max-effects", type=int, default=3, help="diagnose --max-effects")
    ap.add_argument(
        "--log",
        type=Path,
        default=None,
        help="append each row as a JSON line; rows already in it are not run again",
    )
    ap.add_argument("--skip-effects", action="store_true", help="run the nulls only")
    ap.add_argument("--cases", default="", help="the cases to run, in this order (default all)")
    ap.add_argument(
        "--report-only", action="store_true", help="print the rows in --log, run nothing"
    )
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",") if s]
    y0 = yardstick_s()
    print("# Structural study\n")
    print(
        f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {platform.node()}, "
        f"{platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; yardstick (numpy.sort "
        f"1e6) {y0 * 1e3:.1f} ms CPU"
    )
    if not a.skip_effects:
        cases = [c for c in a.cases.split(",") if c] or None
        effects(seeds, a.max_effects, a.log, a.report_only, cases)
    if a.nulls:
        nulls(a.nulls, a.max_effects, a.log, a.report_only)
    y1 = yardstick_s()
    print(f"\nyardstick at the end {y1 * 1e3:.1f} ms CPU; load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
