"""A simulated stand-in for a four-waveform record: four 2-s captures of one stack at 10 kHz.

The record it stands in for (which labrig does not have): one piezo stack driven biased,
-100..+73 V, by a 50 Hz sine, a 100 Hz sine, a 100 Hz triangle and a pseudo-random binary
sequence, each captured for 2 s at 10 kHz while the drive runs (a capture does not start at
rest), the four given as delimited text. Identified on three, predicting the fourth
(leave-one-record-out) is predicting a waveform the fit never saw.

**What it is.** A simulation on the virtual bench (:class:`labrig.drivers.sim.bench.VirtualBench`,
the physics of the simulated rig, on the ``bipolar`` bench rig of
:mod:`labrig.studies.campaign`: -150..150 V, 1 uF stack, 0.18 A peak), not a measurement. Its
truth is a plant outside the fitted family (:data:`TRUTHS`; by default ``stack``: the
quasi-static blocks of the paper's section-4 reference plant, a linear, a system-level and a
Bouc-Wen block, without its Eq. 11, whose pole pair at 145 Hz would put a 85 degree lag on a
100 Hz drive) with what such a stack plausibly shows at these drives, each in the bench's own
form (:mod:`labrig.drivers.sim.structural`), not the library's:

=========================  =====================================================================
bench effect               what it gives the captures (:data:`STAND_IN_EFFECTS`)
=========================  =====================================================================
``amplifier_output_rc``    the amplifier's corner on the capacitive load: 200 ohm into 1 uF
                           rising to 1.7 uF at 100 V, 800 Hz at 0 V falling to 470 Hz; the
                           recorded voltage is the amplifier's monitor, ahead of it
``stack_resonance``        the stack on a 0.35 kg mass, 20 N/um, damping ratio 0.05: 1.2 kHz,
                           rung by the triangle's corners and the PRBS's edges
``depoling``               bias-dependent ``d33``: less strain per volt under negative field
                           (``V_c`` 250 V)
``viscous_slip``           rate-dependent hysteresis width: 4 viscous Maxwell-slip elements,
                           2..20 V, tau 2 ms (the loop widens from 50 to 100 Hz), 1.5 ue/V
=========================  =====================================================================

plus the gauge's white noise (:data:`NOISE_UE`, rms at the bridge) and the DAQ's 16-bit
quantisation. The four drives (:data:`CAPTURES`) are protocol steps, planned and preflighted
against the bench rig's limits as ``labrig run`` plans them; each is reached from rest by a
0.2 s ramp, runs 0.5 s before its capture starts, and the capture keeps the next 2 s
(:data:`LEAD_S`, :data:`CAPTURE_S`).

:func:`write_captures` writes the four as CSV files (``time_s,voltage_V,strain_ue``: the
amplifier's monitor and the gauge, as another lab's logger would give them) for ``labrig
import``; ``python -m labrig.studies.waveforms OUT_DIR`` does it from the command line and
prints the commands that import, validate leave-one-record-out and diagnose them
(docs/validate.md, "The four-waveform stand-in").
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from labrig.analysis.records import Record
from labrig.studies.campaign import BENCH_RIGS, bench_campaign

__all__ = [
    "BIAS_V",
    "CAPTURES",
    "CAPTURE_S",
    "HALF_SPAN_V",
    "LEAD_S",
    "NOISE_UE",
    "RATE_HZ",
    "STAND_IN_EFFECTS",
    "TRUTHS",
    "capture_records",
    "write_captures",
]

#: sample rate of the captures (Hz)
RATE_HZ = 10_000.0
#: length of each capture (s)
CAPTURE_S = 2.0
#: time each drive runs before its capture starts (s)
LEAD_S = 0.5
#: ramp from rest to the drive's first value (s)
RAMP_S = 0.2
#: the drives swing -100..+73 V: around this bias (V) ...
BIAS_V = -13.5
#: ... by this much either way (V)
HALF_SPAN_V = 86.5
#: the gauge's white noise at the bridge (ue rms)
NOISE_UE = 0.3

#: the bench's effects on the stand-in stack (rig-file form; module docstring)
STAND_IN_EFFECTS: tuple[dict[str, Any], ...] = (
    {"name": "amplifier_output_rc", "output_resistance_ohm": 200.0},
    {"name": "stack_resonance", "stiffness_N_per_um": 20.0, "mass_kg": 0.35, "damping_ratio": 0.05},
    {"name": "depoling", "coercive_V": 250.0},
    {"name": "viscous_slip", "gain_ue_per_V": 1.5},
)

#: the stand-in's truths: name -> (bench truth preset, its ``bench: truth:`` keys)
TRUTHS: dict[str, tuple[str, dict[str, Any]]] = {
    "stack": ("hybrid", {"hybrid": {"use_eq11": False}}),
    "hybrid": ("hybrid", {}),
    "paper": ("paper", {}),
}

_RUN_S = LEAD_S + CAPTURE_S + 0.05  # a little beyond the capture: nothing of the end is kept

#: capture name -> its drive (a protocol step, run for :data:`LEAD_S` + :data:`CAPTURE_S`)
CAPTURES: dict[str, dict[str, Any]] = {
    "sine_50Hz": {
        "kind": "offset_sine",
        "offset_V": BIAS_V,
        "amplitude_V": HALF_SPAN_V,
        "frequency_hz": 50.0,
        "duration_s": _RUN_S,
        "ramp_s": 0.0,
        "settle_s": 0.0,
    },
    "sine_100Hz": {
        "kind": "offset_sine",
        "offset_V": BIAS_V,
        "amplitude_V": HALF_SPAN_V,
        "frequency_hz": 100.0,
        "duration_s": _RUN_S,
        "ramp_s": 0.0,
        "settle_s": 0.0,
    },
    "triangle_100Hz": {
        "kind": "triangle",
        "offset_V": BIAS_V,
        "amplitude_V": HALF_SPAN_V,
        "frequency_hz": 100.0,
        "duration_s": _RUN_S,
    },
    "prbs": {
        "kind": "prbs",
        "offset_V": BIAS_V,
        "amplitude_V": HALF_SPAN_V,
        "clock_hz": 250.0,
        "order": 9,
        "seed": 5,
        "transition_s": 0.002,
        "duration_s": _RUN_S,
    },
}


def _entries(name: str) -> list[dict[str, Any]]:
    """The ramp from rest to the drive's first value, then the drive."""
    from labrig.protocol.expand import build_plan
    from labrig.protocol.preflight import preflight_checks
    from labrig.protocol.schema import Protocol

    step = CAPTURES[name]
    protocol = Protocol.model_validate({"name": name, "rate_hz": RATE_HZ, "steps": [step]})
    plan = build_plan(protocol, path="<stand-in>")
    preflight_checks(plan, BENCH_RIGS["bipolar"].limits)
    first = float(plan.steps[0].samples()[0])
    ramp = {"kind": "ramp", "from_V": 0.0, "to_V": first, "duration_s": RAMP_S}
    return [ramp, step]


def capture_records(
    seed: int = 1,
    *,
    truth: str = "stack",
    effects: Sequence[dict[str, Any]] = STAND_IN_EFFECTS,
    noise_ue: float = NOISE_UE,
    names: Sequence[str] | None = None,
) -> list[Record]:
    """The captures (:data:`CAPTURES`, or ``names`` of them) of one stack: each drive played
    from rest on its own bench (the same truth and effects, the seed ``seed + k`` for capture
    ``k``'s noise), the :data:`CAPTURE_S` s after :data:`LEAD_S` s of it kept; voltage (V) the
    amplifier's monitor, strain (ue) the gauge, time (s) from the capture's start, linear hold
    (a measured voltage), ``meta`` the drive and ``kind: import``; ``truth`` a :data:`TRUTHS`
    name."""
    preset, keys = TRUTHS[truth]
    out = []
    for k, name in enumerate(names or list(CAPTURES)):
        _ramp, drive = bench_campaign(
            effects,
            truth=preset,
            extra={"truth": keys} if keys else None,
            seed=seed + k,
            entries=_entries(name),
            rate_hz=RATE_HZ,
            rest_s=0.0,
            noise_ue=noise_ue,
            rig="bipolar",
        )
        i0 = round(LEAD_S * RATE_HZ)
        n = round(CAPTURE_S * RATE_HZ)
        volts = drive.aux["amplifier_voltage"][i0 : i0 + n]
        strain = drive.strain_ue[i0 : i0 + n]
        meta = {**CAPTURES[name], "kind": "import", "drive": CAPTURES[name]["kind"]}
        out.append(
            dataclasses.replace(
                drive,
                name=name,
                time_s=np.arange(n) / RATE_HZ,
                voltage_V=volts,
                strain_ue=strain,
                aux={},
                hold="linear",
                meta=meta,
            )
        )
    return out


def write_captures(
    out_dir: Path | str,
    seed: int = 1,
    *,
    truth: str = "stack",
    overwrite: bool = False,
    names: Sequence[str] | None = None,
) -> list[Path]:
    """Write the captures (:func:`capture_records`: the four, or ``names`` of them) as
    ``OUT_DIR/NAME.csv`` (header ``time_s,voltage_V,strain_ue``; ``%.6g`` s, ``%.5f`` V,
    ``%.4f`` ue) and return their paths. An existing file is replaced only with ``overwrite``
    (each written beside, then renamed; checked for all before any is simulated)."""
    from labrig.core.outputs import check_writable, write_text_output

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    chosen = list(names or CAPTURES)
    paths = [out / f"{name}.csv" for name in chosen]
    check_writable(paths, inputs=[], overwrite=overwrite)
    for path, r in zip(paths, capture_records(seed, truth=truth, names=chosen), strict=True):
        rows = np.column_stack([r.time_s, r.voltage_V, r.strain_ue])
        lines = ["time_s,voltage_V,strain_ue"]
        lines += [f"{t:.6g},{v:.5f},{s:.4f}" for t, v, s in rows.tolist()]
        write_text_output(path, "\n".join(lines) + "\n", overwrite=overwrite)
    return paths


def _commands(paths: Sequence[Path]) -> list[str]:
    """The commands that import the captures, validate leave-one-record-out and diagnose."""
    stems = [p.with_suffix(".h5") for p in paths]
    cmds = [f"labrig import {p} --out {h}" for p, h in zip(paths, stems, strict=True)]
    cmds.append(
        "labrig import " + " ".join(str(p) for p in paths) + f" --out {paths[0].parent}/all.h5"
    )
    cmds.append("labrig validate --leave-one-out " + " ".join(str(h) for h in stems) + " --json")
    cmds.append(f"labrig diagnose {paths[0].parent}/all.h5 --out {paths[0].parent}/diagnosis")
    return cmds


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m labrig.studies.waveforms OUT_DIR [--seed N] [--truth T] [--overwrite]``."""
    ap = argparse.ArgumentParser(prog="python -m labrig.studies.waveforms", description=__doc__)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--truth", choices=tuple(TRUTHS), default="stack")
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args(argv)
    paths = write_captures(a.out_dir, a.seed, truth=a.truth, overwrite=a.overwrite)
    print("\n".join(str(p) for p in paths))
    print("\n".join(_commands(paths)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
