"""Synthetic campaigns on the virtual bench, for testing and measuring ``labrig diagnose``.

:func:`bench_campaign` plays a list of entries through
:class:`labrig.drivers.sim.bench.VirtualBench` in-process, each followed by a rest at 0 V, with
the bench's optional effects switched on by name (``drivers/sim/effects.py``), and returns the
entries as :class:`Record` objects the way ``records_from_run`` would: the commanded voltage as
``voltage_V`` (hold ``"zoh"``), the strain from the gauge channel, the amplifier monitor as
``aux["amplifier_voltage"]`` and, with ``self_heating``, the temperature channel as
``aux["temperature"]``. An entry is either

- ``(amplitude V, frequency Hz, duration s)``: a unipolar sine ``V = A/2 (1 - cos 2 pi f t)``
  over whole cycles (frequency 0: a :func:`step_hold`); ``meta`` holds ``kind``,
  ``frequency_hz``, ``amplitude_V`` and ``rest_after_s``; or
- a protocol step (a :mod:`labrig.protocol.schema` step model or its dict, e.g. an
  ``offset_sine`` around a bias with an envelope, a ramp-in and a settle): planned by the
  protocol's own expansion and preflight at ``rate_hz`` against the bench rig's limits, so it
  plays exactly the samples ``labrig run`` would (the closing 0 V sample included); ``meta`` is
  the entry's definition (as a run file stores it) and ``rest_after_s``.

``rig`` chooses the bench's limits and amplifier (:data:`BENCH_RIGS`): ``sim`` (the built-in
rig, -20..100 V) or ``bipolar`` (``experiments/rigs/bipolar.yaml`` without its effects,
-150..150 V). :data:`DRIVES` names the campaigns (entries, rig, rate) the studies use.

The bench is driven directly rather than through :func:`labrig.runner.execute` because the
runner (correctly) aborts a run when the amplifier reports current limiting, which is exactly the
``amplifier_current_limit`` effect; the physics is the same object the simulated rig uses.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labrig.analysis.records import Record
from labrig.analysis.signals import sine, step_hold
from labrig.protocol.schema import OffsetSineStep
from labrig.rig.limits import RigLimits

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

#: bipolar sines around 0 V, 150 and 75 V at 1, 10, 40 Hz (3, 2, 2 s), each after 0.2 s at 0 V:
#: the steps of experiments/bipolar.yaml (15.2 s recorded at 1 kHz, on the ``bipolar`` rig)
BIPOLAR_ENTRIES: tuple[OffsetSineStep, ...] = tuple(
    OffsetSineStep(
        kind="offset_sine",
        offset_V=0.0,
        amplitude_V=a,
        frequency_hz=f,
        cycles=cycles,
        ramp_s=0.0,
        settle_s=0.2,
    )
    for a in (150.0, 75.0)
    for f, cycles in ((1.0, 3.0), (10.0, 20.0), (40.0, 80.0))
)

#: growing envelopes (0 to 60 V over 2 s) around a -90 V bias at 20, 40, 100 Hz, each after a
#: 0.5 s raised-cosine ramp to -90 V and 0.5 s settle, then 0.5 s back to 0 V: the steps of
#: experiments/biased-envelope.yaml (10.5 s recorded at 2 kHz, on the ``bipolar`` rig)
BIASED_ENTRIES: tuple[OffsetSineStep, ...] = tuple(
    OffsetSineStep(
        kind="offset_sine",
        offset_V=-90.0,
        amplitude_V=60.0,
        frequency_hz=f,
        cycles=cycles,
        envelope="growing",
        ramp_s=0.5,
        settle_s=0.5,
    )
    for f, cycles in ((20.0, 40.0), (40.0, 80.0), (100.0, 200.0))
)

Entry = tuple[float, float, float] | OffsetSineStep | Mapping[str, Any]


@dataclass(frozen=True)
class BenchRig:
    """What a campaign's bench takes from a rig file: its limits (which the amplifier's
    VMI/VMA start at) and the ``bench:`` keys that differ from the defaults."""

    limits: RigLimits
    bench: dict[str, Any] = field(default_factory=dict)


#: the benches of the campaigns: the built-in rig and experiments/rigs/bipolar.yaml (its limits
#: and amplifier; its field saturation is an effect, given like any other)
BENCH_RIGS: dict[str, BenchRig] = {
    "sim": BenchRig(RigLimits()),
    "bipolar": BenchRig(
        RigLimits(
            v_min_V=-150.0,
            v_max_V=150.0,
            capacitance_F=1.0e-6,
            large_signal_factor=1.5,
            i_peak_A=0.18,
            i_avg_A=0.12,
        ),
        {
            "amplifier": {
                "gain_V_per_V": 20.0,
                "out_min_V": -160.0,
                "out_max_V": 160.0,
                "monitor_V_per_V": 0.025,
            }
        },
    ),
}


@dataclass(frozen=True)
class Drive:
    """A named campaign: its entries, the rig they are played on and the sample rate (Hz)."""

    entries: tuple[Entry, ...]
    rig: str = "sim"
    rate_hz: float = 1000.0


DRIVES: dict[str, Drive] = {
    "short": Drive(SHORT_ENTRIES),
    "hold": Drive(HOLD_ENTRIES),
    "bipolar": Drive(BIPOLAR_ENTRIES, "bipolar", 1000.0),
    "biased": Drive(BIASED_ENTRIES, "bipolar", 2000.0),
}

__all__ = [
    "BENCH_RIGS",
    "BIASED_ENTRIES",
    "BIPOLAR_ENTRIES",
    "DRIVES",
    "HOLD_ENTRIES",
    "SHORT_ENTRIES",
    "STUDY_CASES",
    "STUDY_DRIVES",
    "TRUTHS",
    "BenchRig",
    "Drive",
    "attribution_study",
    "bench_campaign",
    "study_campaign",
    "truth_campaign",
]


def _name(a: float, f: float) -> str:
    def fmt(x: float) -> str:
        return f"{x:g}".replace(".", "p").replace("-", "m")

    return f"sine_{fmt(a)}V_{fmt(f)}Hz" if f > 0 else f"hold_{fmt(a)}V"


def _planned(entry: OffsetSineStep | Mapping[str, Any], rate_hz: float, limits: RigLimits):
    """A protocol step as the plan's entry (name, samples, definition), checked against the
    rig's limits like ``labrig run`` does (``InputFileError`` when it breaks one)."""
    from labrig.protocol.expand import build_plan
    from labrig.protocol.preflight import preflight_checks
    from labrig.protocol.schema import Protocol

    step = entry.model_dump(exclude_none=True) if hasattr(entry, "model_dump") else dict(entry)
    protocol = Protocol.model_validate({"name": "campaign", "rate_hz": rate_hz, "steps": [step]})
    plan = build_plan(protocol, path="<campaign>")
    preflight_checks(plan, limits)
    (planned,) = plan.steps
    return planned


def _drives(entries: Sequence[Entry], rate_hz: float, rest_s: float, limits: RigLimits):
    """``(base name, commanded voltage, meta)`` of every entry, in order; a protocol step's
    ``source_step`` is its place in ``entries`` (as in a protocol file with these steps)."""
    for index, entry in enumerate(entries):
        if isinstance(entry, tuple):
            a, f, d = entry
            v = sine(a, f, d, rate_hz) if f > 0 else step_hold(a, d, rate_hz)
            meta = {
                "kind": "sine" if f > 0 else "step_hold",
                "frequency_hz": f,
                "amplitude_V": a,
                "rest_after_s": rest_s,
            }
            yield _name(a, f), v, meta
        else:
            planned = _planned(entry, rate_hz, limits)
            meta = {**planned.definition, "source_step": index, "rest_after_s": rest_s}
            yield planned.name, planned.samples(), meta


def _bench(config_keys: dict[str, Any], rig: BenchRig, seed: int, rate_hz: float):
    """A virtual bench at rest, zeroed as the runner leaves it at the start of a run."""
    from labrig.drivers.sim.bench import BenchConfig, VirtualBench

    config = BenchConfig.model_validate(config_keys)
    bench = VirtualBench(config, rig.limits, seed=seed, rate_hz=rate_hz)
    bench.settle(0.1)
    bench.balance()  # the runner zeroes the conditioner at the start of a run
    return bench


def _config_keys(
    effects: Sequence[dict[str, Any]],
    truth: str,
    noise_ue: float,
    paper_overrides: dict[str, float] | None,
    rig: BenchRig,
    extra: dict[str, Any] | None,
) -> dict[str, Any]:
    """The ``bench:`` section: truth, gauge noise, effects, the rig's keys, then ``extra``."""
    cfg: dict[str, Any] = {
        "truth": {"preset": truth, "paper_overrides": dict(paper_overrides or {})},
        "gauge": {"noise_ue": noise_ue},
        "effects": [dict(e) for e in effects],
    }
    for source in (rig.bench, extra or {}):
        for k, v in source.items():
            cfg[k] = {**cfg.get(k, {}), **v} if isinstance(v, dict) else v
    return cfg


def bench_campaign(
    effects: Sequence[dict[str, Any]] = (),
    *,
    truth: str = "paper",
    seed: int = 0,
    entries: Sequence[Entry] = SHORT_ENTRIES,
    rate_hz: float = 1000.0,
    rest_s: float = 1.0,
    noise_ue: float = 2.0,
    paper_overrides: dict[str, float] | None = None,
    extra: dict[str, Any] | None = None,
    rig: str = "sim",
) -> list[Record]:
    """Run ``entries`` (in order; see the module docstring) on a virtual bench.

    ``effects``: the bench's effects as rig-file dicts, e.g. ``[{"name": "mains_pickup",
    "amplitude_mV": 20}]``. ``truth``: ``"paper"`` (the model family) or ``"hybrid"``.
    ``extra``: further ``bench:`` keys (``amplifier``, ``gauge``...) merged into the config.
    ``rig``: a :data:`BENCH_RIGS` name (limits and amplifier of the bench).
    """
    bench_rig = BENCH_RIGS[rig]
    keys = _config_keys(effects, truth, noise_ue, paper_overrides, bench_rig, extra)
    bench = _bench(keys, bench_rig, seed, rate_hz)
    config = bench.config
    gain = config.amplifier.gain_V_per_V
    names: dict[str, int] = {}
    out = []
    for name, v, meta in _drives(entries, rate_hz, rest_s, bench_rig.limits):
        ch = bench.step(v / gain)
        sens = bench.sensitivity_V_per_ue() * bench.cond.gain
        names[name] = names.get(name, 0) + 1
        if names[name] > 1:
            name = f"{name}_{names[name]}"
        aux = {"amplifier_voltage": ch["amp_monitor"] / config.amplifier.monitor_V_per_V}
        if "temperature" in ch:
            from labrig.rig.instruments import TEMPERATURE_V_PER_DEGC

            aux["temperature"] = ch["temperature"] / TEMPERATURE_V_PER_DEGC
        time_s = np.arange(v.size) / rate_hz
        out.append(Record(name, rate_hz, time_s, v, ch["gauge"] / sens, aux, "zoh", meta))
        n_rest = round(rest_s * rate_hz)
        if n_rest:
            bench.step(np.zeros(n_rest))
    return out


# -- attribution study (python -m labrig.studies.campaign) --------------------------

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
    "field_saturation": [{"name": "field_saturation"}],
    "viscoelastic_creep": [{"name": "viscoelastic_mode"}],
    "cubic_term": [{"name": "cubic_term", "c3_ue": 40.0}],
}

#: the :data:`DRIVES` each case is studied on (the first is the case's own); ``short`` for the
#: cases not listed. The null is studied on every drive; ``cubic_term`` is outside the library
#: (the empirical step, not a named effect, should find it)
STUDY_DRIVES: dict[str, tuple[str, ...]] = {
    "none": ("short", "bipolar", "biased"),
    "field_saturation": ("bipolar", "biased"),
    "viscoelastic_creep": ("short", "bipolar"),
    "cubic_term": ("bipolar", "short"),
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
    entries: Sequence[Entry] = SHORT_ENTRIES,
    *,
    drive: str | None = None,
) -> list[Record]:
    """:func:`bench_campaign` on one of :data:`TRUTHS`; ``drive``: a :data:`DRIVES` name
    (its entries, rig and rate, in place of ``entries``)."""
    preset, overrides = TRUTHS[truth]
    if drive is None:
        return bench_campaign(
            effects, seed=seed, truth=preset, paper_overrides=overrides, entries=entries
        )
    d = DRIVES[drive]
    return bench_campaign(
        effects,
        seed=seed,
        truth=preset,
        paper_overrides=overrides,
        entries=d.entries,
        rig=d.rig,
        rate_hz=d.rate_hz,
    )


def study_campaign(
    case: str, seed: int = 0, *, truth: str = "paper", drive: str | None = None
) -> list[Record]:
    """The campaign of the study case ``case`` (:data:`STUDY_CASES`) on ``drive`` (default:
    the case's own, the first of :data:`STUDY_DRIVES`)."""
    drive = drive or STUDY_DRIVES.get(case, ("short",))[0]
    return truth_campaign(truth, STUDY_CASES[case], seed, drive=drive)


def _study_row(truth: str, case: str, drive: str, seed: int) -> dict[str, Any]:
    """Diagnose one study campaign: the row of :func:`attribution_study`."""
    import time

    from labrig.analysis.diagnose.procedure import diagnose

    recs = truth_campaign(truth, STUDY_CASES[case], seed, drive=drive)
    t0 = time.perf_counter()
    d = diagnose(recs)
    added = [e["effect"] for e in d.effects_added]
    return {
        "truth": truth,
        "case": case,
        "drive": drive,
        "seed": seed,
        "first": added[0] if added else "none",
        "added": added,
        "class": d.classification,
        "before": d.before["heldout_nrmse_pct"],
        "after": d.after["heldout_nrmse_pct"],
        "seconds": time.perf_counter() - t0,
    }


def attribution_study(
    seeds: Sequence[int] = (1, 2),
    truths: Sequence[str] = ("paper",),
    out=print,
    cases: Sequence[str] | None = None,
) -> list[dict[str, Any]]:
    """Run :func:`labrig.analysis.diagnose.diagnose` on every case (:data:`STUDY_CASES`, or
    ``cases``), drive of the case (:data:`STUDY_DRIVES`), seed and truth (:data:`TRUTHS`);
    print one line per run and return the rows (truth, case, drive, first added effect, all
    added, verdict class, held-out before/after, seconds)."""
    rows = []
    for truth in truths:
        for case in cases or list(STUDY_CASES):
            for drive in STUDY_DRIVES.get(case, ("short",)):
                for seed in seeds:
                    row = _study_row(truth, case, drive, seed)
                    rows.append(row)
                    out(
                        f"{truth:14s} {case:24s} {drive:8s} seed {seed:3d} -> "
                        f"{','.join(row['added']) or 'none':40s} {row['class']:22s} held-out "
                        f"{row['before']:.3g} -> {row['after']:.3g} % ({row['seconds']:.0f} s)"
                    )
    return rows


if __name__ == "__main__":  # pragma: no cover
    import sys

    truths = sys.argv[1].split(",") if len(sys.argv) > 1 else ["paper"]
    seeds = [int(s) for s in sys.argv[2].split(",")] if len(sys.argv) > 2 else [1, 2]
    chosen = sys.argv[3].split(",") if len(sys.argv) > 3 else None
    rows = attribution_study(seeds, truths, cases=chosen)
    cases = list(dict.fromkeys(r["case"] for r in rows))
    cols = sorted({r["first"] for r in rows} | set(cases))
    print("\nconfusion (rows: truth, case, drive; columns: first effect added)")
    print(" " * 43 + " ".join(f"{c[:10]:>10s}" for c in cols))
    for t in truths:
        for c in cases:
            for drive in STUDY_DRIVES.get(c, ("short",)):
                sel = [r for r in rows if (r["case"], r["truth"], r["drive"]) == (c, t, drive)]
                print(
                    f"{t[:14]:14s} {c:19s} {drive:8s}"
                    + " ".join(f"{sum(r['first'] == k for r in sel):10d}" for k in cols)
                )
