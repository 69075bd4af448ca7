"""Synthetic campaigns on the virtual bench, for testing and measuring ``labrig diagnose``.

:func:`bench_campaign` plays a list of unipolar sines (``V = A/2 (1 - cos 2 pi f t)``, whole
cycles, each followed by a rest at 0 V) through :class:`labrig.drivers.sim.bench.VirtualBench`
in-process, with the bench's optional effects switched on by name (``drivers/sim/effects.py``),
and returns the entries as :class:`Record` objects the way ``records_from_run`` would: the
commanded voltage as ``voltage_V`` (hold ``"zoh"``), the strain from the gauge channel, the
amplifier monitor as ``aux["amplifier_voltage"]`` and, with ``self_heating``, the temperature
channel as ``aux["temperature"]``; ``meta`` holds ``frequency_hz``, ``amplitude_V`` and
``rest_after_s``.

The bench is driven directly rather than through :func:`labrig.runner.execute` because the
runner (correctly) aborts a run when the amplifier reports current limiting, which is exactly the
``amplifier_current_limit`` effect; the physics is the same object the simulated rig uses.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from labrig.analysis.records import Record
from labrig.analysis.signals import sine, step_hold
from labrig.limits import RigLimits

#: a short campaign (about 14 s recorded, 20 s with rests): both amplitudes at 1, 10, 40 Hz
SHORT_ENTRIES: tuple[tuple[float, float, float], ...] = (
    (100.0, 1.0, 3.0),
    (100.0, 10.0, 2.0),
    (100.0, 40.0, 2.0),
    (50.0, 1.0, 3.0),
    (50.0, 10.0, 2.0),
    (50.0, 40.0, 2.0),
)

#: :data:`SHORT_ENTRIES` and a 100 V step held 300 s, then 300 s at 0 V: the longest look at creep
HOLD_ENTRIES: tuple[tuple[float, float, float], ...] = (*SHORT_ENTRIES, (100.0, 0.0, 600.0))

__all__ = [
    "HOLD_ENTRIES",
    "SHORT_ENTRIES",
    "STUDY_CASES",
    "TRUTHS",
    "attribution_study",
    "bench_campaign",
    "truth_campaign",
]


def _name(a: float, f: float) -> str:
    def fmt(x: float) -> str:
        return f"{x:g}".replace(".", "p").replace("-", "m")

    return f"sine_{fmt(a)}V_{fmt(f)}Hz" if f > 0 else f"hold_{fmt(a)}V"


def bench_campaign(
    effects: Sequence[dict[str, Any]] = (),
    *,
    truth: str = "paper",
    seed: int = 0,
    entries: Sequence[tuple[float, float, float]] = SHORT_ENTRIES,
    rate_hz: float = 1000.0,
    rest_s: float = 1.0,
    noise_ue: float = 2.0,
    paper_overrides: dict[str, float] | None = None,
    extra: dict[str, Any] | None = None,
) -> list[Record]:
    """Run ``entries`` ((amplitude V, frequency Hz, duration s), in order; frequency 0 for a
    :func:`step_hold`) on a virtual bench.

    ``effects``: the bench's effects as rig-file dicts, e.g. ``[{"name": "mains_pickup",
    "amplitude_mV": 20}]``. ``truth``: ``"paper"`` (the model family) or ``"hybrid"``.
    ``extra``: further ``bench:`` keys (``amplifier``, ``gauge``...) merged into the config.
    """
    from labrig.drivers.sim.bench import BenchConfig, VirtualBench

    cfg: dict[str, Any] = {
        "truth": {"preset": truth, "paper_overrides": dict(paper_overrides or {})},
        "gauge": {"noise_ue": noise_ue},
        "effects": [dict(e) for e in effects],
    }
    for k, v in (extra or {}).items():
        cfg[k] = {**cfg.get(k, {}), **v} if isinstance(v, dict) else v
    config = BenchConfig.model_validate(cfg)
    bench = VirtualBench(config, RigLimits(), seed=seed, rate_hz=rate_hz)
    gain = config.amplifier.gain_V_per_V
    bench.settle(0.1)
    bench.balance()  # the runner zeroes the conditioner at the start of a run
    names: dict[str, int] = {}
    out = []
    for a, f, d in entries:
        v = sine(a, f, d, rate_hz) if f > 0 else step_hold(a, d, rate_hz)
        ch = bench.step(v / gain)
        sens = bench.sensitivity_V_per_ue() * bench.cond.gain
        name = _name(a, f)
        names[name] = names.get(name, 0) + 1
        if names[name] > 1:
            name = f"{name}_{names[name]}"
        aux = {"amplifier_voltage": ch["amp_monitor"] / config.amplifier.monitor_V_per_V}
        if "temperature" in ch:
            from labrig.instruments import TEMPERATURE_V_PER_DEGC

            aux["temperature"] = ch["temperature"] / TEMPERATURE_V_PER_DEGC
        out.append(
            Record(
                name,
                rate_hz,
                np.arange(v.size) / rate_hz,
                v,
                ch["gauge"] / sens,
                aux,
                "zoh",
                {
                    "kind": "sine" if f > 0 else "step_hold",
                    "frequency_hz": f,
                    "amplitude_V": a,
                    "rest_after_s": rest_s,
                },
            )
        )
        n_rest = round(rest_s * rate_hz)
        if n_rest:
            bench.step(np.zeros(n_rest))
    return out


# -- attribution study (python -m labrig.analysis.diagnose.campaign) --------------------------

#: bench effect (rig-file form) for each library effect, at clear strengths
STUDY_CASES: dict[str, list[dict[str, Any]]] = {
    "none": [],
    "sensor_lowpass": [{"name": "conditioner_lowpass", "cutoff_hz": 150.0, "order": 2}],
    "mains_pickup": [{"name": "mains_pickup", "amplitude_mV": 20.0}],
    "amplifier_current_limit": [{"name": "amplifier_current_limit"}],
    "thermal_drift": [
        {
            "name": "self_heating",
            "heat_capacity_J_per_K": 0.2,
            "tan_delta": 0.1,
            "strain_coeff_per_K": 0.01,
        }
    ],
    "offset_drift": [
        {"name": "offset_drift", "rate_ue_per_s": 1.5, "random_walk_ue_per_sqrt_s": 0.5}
    ],
    "creep": [{"name": "log_creep", "per_decade": 0.04}],
}


#: the bench's truths of the study: ``paper`` (the fitted family itself), ``paper_gaussian``
#: (slightly imperfect: the paper's model with the Gaussian hysteresis shape, fitted with the
#: exponential one), ``hybrid`` (the paper's section-4 reference plant, further from the family)
TRUTHS: dict[str, tuple[str, dict[str, Any]]] = {
    "paper": ("paper", {}),
    "paper_gaussian": ("paper", {"shape": "gaussian"}),
    "hybrid": ("hybrid", {}),
}


def truth_campaign(
    truth: str,
    effects: Sequence[dict[str, Any]] = (),
    seed: int = 0,
    entries: Sequence[tuple[float, float, float]] = SHORT_ENTRIES,
):
    """:func:`bench_campaign` on one of :data:`TRUTHS`."""
    preset, overrides = TRUTHS[truth]
    return bench_campaign(
        effects, seed=seed, truth=preset, paper_overrides=overrides, entries=entries
    )


def attribution_study(
    seeds: Sequence[int] = (1, 2), truths: Sequence[str] = ("paper",), out=print
) -> list[dict[str, Any]]:
    """Run :func:`labrig.analysis.diagnose.diagnose` on every case, seed and truth
    (:data:`TRUTHS`); print one line per run and return the rows (truth effect, first added
    effect, all added, verdict class, held-out before/after, seconds)."""
    import time

    from labrig.analysis.diagnose.procedure import diagnose

    rows = []
    for truth in truths:
        for case, effects in STUDY_CASES.items():
            for seed in seeds:
                recs = truth_campaign(truth, effects, seed)
                t0 = time.perf_counter()
                d = diagnose(recs)
                dt = time.perf_counter() - t0
                added = [e["effect"] for e in d.effects_added]
                row = {
                    "truth": truth,
                    "case": case,
                    "seed": seed,
                    "first": added[0] if added else "none",
                    "added": added,
                    "class": d.classification,
                    "before": d.before["heldout_nrmse_pct"],
                    "after": d.after["heldout_nrmse_pct"],
                    "seconds": dt,
                }
                rows.append(row)
                out(
                    f"{truth:14s} {case:24s} seed {seed:3d} -> {','.join(added) or 'none':40s} "
                    f"{d.classification:22s} held-out {row['before']:.3g} -> {row['after']:.3g} % "
                    f"({dt:.0f} s)"
                )
    return rows


if __name__ == "__main__":  # pragma: no cover
    import sys

    truths = sys.argv[1].split(",") if len(sys.argv) > 1 else ["paper"]
    seeds = [int(s) for s in sys.argv[2].split(",")] if len(sys.argv) > 2 else [1, 2]
    rows = attribution_study(seeds, truths)
    cases = list(STUDY_CASES)
    cols = sorted({r["first"] for r in rows} | set(cases))
    print("\nconfusion (rows: truth, columns: first effect added)")
    print(" " * 34 + " ".join(f"{c[:10]:>10s}" for c in cols))
    for t in truths:
        for c in cases:
            sel = [r for r in rows if r["case"] == c and r["truth"] == t]
            print(
                f"{t[:14]:14s} {c:19s}"
                + " ".join(f"{sum(r['first'] == k for r in sel):10d}" for k in cols)
            )
