"""Expand a validated protocol into a flat list of concrete steps (the plan).

Sweeps become one sine step per amplitude x frequency pair, ``repeat`` copies a step (a whole
sweep is repeated as a block), rests become ``rest_after_s`` on the step before them. Every
concrete step gets a unique entry name (the run file's NXentry name): the derived base name
(``sine_100V_40Hz``, ``offset_sine_m90V_60V_20Hz_growing``, ``vanishing_100V_1Hz``,
``hold_50V_2s``, ``ramp_0V_to_100V``, ``csv_<file stem>``,
``strain_sine_500ue_10Hz_compensated``; a step's ``name`` replaces it, or prefixes a sweep's
names), then ``_2``, ``_3``, ... for later occurrences of the same name (repeats).

Strain-command steps (``strain_sine``, ``strain_vanishing``, ``strain_csv``) compose their
command in ue (edge ramps at ``edge_slew_V_per_s * alpha0``), compute the drive with
:func:`labrig.control.compute_drive` and the step's model parameters, and play one 0 V sample
then the drive; :attr:`PlannedStep.aux` carries the ``command_strain`` channel (docs/control.md).

The plan's types are in :mod:`labrig.protocol.plan`. Nothing here touches hardware or checks the
rig's limits: see :mod:`labrig.protocol.preflight`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.numbers import at_most, beyond, fixed
from labrig.protocol import broadband as bb
from labrig.protocol import waveforms as wf
from labrig.protocol.concrete import Concrete, intervals, num_tag, sanitize
from labrig.protocol.csvsource import CsvError, load_csv, resolve_csv_path
from labrig.protocol.offset_sine import offset_sine_name, offset_sine_parts
from labrig.protocol.plan import Plan, PlannedStep, Where, field_name, line_of
from labrig.protocol.schema import (
    CsvStep,
    HoldStep,
    MultisineStep,
    OffsetSineStep,
    PrbsStep,
    Protocol,
    RampStep,
    SineStep,
    StrainCsvStep,
    StrainSineStep,
    StrainVanishingStep,
    SweepStep,
    TriangleStep,
    VanishingStep,
)

#: refuse single entries longer than this many samples (split them or lower rate_hz)
MAX_STEP_SAMPLES = 50_000_000
#: refuse plans with more concrete steps than this
MAX_ENTRIES = 10_000
#: refuse plans lasting longer than this (s), rests included
MAX_TOTAL_S = 7 * 86400.0
#: a voltage beyond this is a mistake in the file, not a drive (piezo amplifiers give at most
#: about a kilovolt): an entry too long to sample because of its edge ramp to such a voltage
#: is blamed on the key that sets the voltage, not on edge_slew_V_per_s
MAX_SANE_VOLTAGE_V = 1e6
#: refuse strain commands longer than this many samples (the drive is computed when planning)
MAX_STRAIN_SAMPLES = 2_000_000


class _PlanError(Exception):
    def __init__(self, issues: list[InputIssue]):
        self.issues = issues


class _Builder:
    def __init__(self, protocol: Protocol, lines: dict, file: str, base_dir: Path):
        self.p = protocol
        self.lines = lines
        self.file = file
        self.base_dir = base_dir
        self.rate = protocol.rate_hz
        self.issues: list[InputIssue] = []
        self._params: dict[Path, object] = {}

    def where(self, path: tuple) -> Where:
        return Where(field_name(path), line_of(path, self.lines))

    def issue(self, w: Where, msg: str) -> None:
        found = InputIssue(self.file, w.line, w.field, msg)
        if found not in self.issues:  # a shared key (params:) read by every step: said once
            self.issues.append(found)

    def n_of(self, seconds: float, w: Where, what: str) -> int | None:
        """Sample intervals for ``seconds`` at the protocol rate, or None (issue recorded)."""
        n = intervals(seconds, self.rate)
        if n > MAX_STEP_SAMPLES:
            self.issue(
                w,
                f"{what} lasts {seconds:g} s = {n} samples at {self.rate:g} Hz; one entry may "
                f"have at most {MAX_STEP_SAMPLES} samples (split it or lower rate_hz)",
            )
            return None
        if n < 2:
            self.issue(
                w,
                f"{what} lasts {seconds:g} s, less than two samples at {self.rate:g} Hz "
                f"(at least {2 / self.rate:g} s)",
            )
            return None
        return n

    # --- one method per step kind: returns the concrete steps of one repetition ---

    def sine(self, s: SineStep, base: tuple) -> list[Concrete]:
        lw = self.where((*base, "cycles" if s.cycles is not None else "duration_s"))
        where = {
            "step": self.where(base),
            "amplitude_V": self.where((*base, "amplitude_V")),
            "frequency_hz": self.where((*base, "frequency_hz")),
            "length": lw,
        }
        c = self._sine(s.amplitude_V, s.frequency_hz, s.cycles, s.duration_s, None, where)
        if c is None:
            return []
        if s.name:
            c.base_name = s.name
        return [c]

    def _sine(self, a, f, cycles, duration_s, min_duration_s, where) -> Concrete | None:
        if cycles is not None and min_duration_s is not None:
            need = min_duration_s * f
            cycles = max(cycles, math.ceil(need - 1e-9) if need < 2.0**62 else 2.0**62)
        seconds = cycles / f if cycles is not None else duration_s
        n = self.n_of(seconds, where["length"], f"the {num_tag(a)} V, {f:g} Hz sine")
        if n is None:
            return None
        definition = {
            "kind": "sine",
            "amplitude_V": a,
            "frequency_hz": f,
            "cycles": cycles if cycles is not None else duration_s * f,
            "duration_s": n / self.rate,
        }
        seg = wf.sine_segment(a, f, n, "frequency_hz")
        name = f"sine_{num_tag(a)}V_{num_tag(f)}Hz"
        return Concrete("sine", name, [seg], definition, where, a, f)

    def n_short(self, seconds: float, w: Where, key: str) -> int | None:
        """Sample intervals of an optional piece (a ramp, a settle): 0 for 0 s, else at least
        one, or None (issue recorded)."""
        n = intervals(seconds, self.rate)
        if seconds > 0 and n < 1:
            self.issue(
                w,
                f"{key} {seconds:g} s is shorter than one sample at {self.rate:g} Hz: give 0 or "
                f"at least {1 / self.rate:g} s",
            )
            return None
        if n > MAX_STEP_SAMPLES:
            return self.n_of(seconds, w, key)
        return n

    def offset_sine(self, s: OffsetSineStep, base: tuple) -> list[Concrete]:
        keys = ("offset_V", "amplitude_V", "frequency_hz", "envelope", "ramp_s", "settle_s")
        where = {k: self.where((*base, k)) for k in keys}
        where["step"] = self.where(base)
        where["length"] = self.where((*base, "cycles" if s.cycles is not None else "duration_s"))
        seconds = s.cycles / s.frequency_hz if s.cycles is not None else s.duration_s
        what = f"the {s.amplitude_V:g} V, {s.frequency_hz:g} Hz sine around {s.offset_V:g} V"
        n = self.n_of(seconds, where["length"], what)
        n_ramp = self.n_short(s.ramp_s, where["ramp_s"], "ramp_s")
        n_settle = self.n_short(s.settle_s, where["settle_s"], "settle_s")
        if n is None or n_ramp is None or n_settle is None:
            return []
        pieces, definition = offset_sine_parts(s, n, n_ramp, n_settle, self.rate)
        name = s.name or offset_sine_name(s)
        return [
            Concrete("offset_sine", name, pieces, definition, where, s.amplitude_V, s.frequency_hz)
        ]

    def sweep(self, s: SweepStep, base: tuple) -> list[Concrete]:
        out = []
        lkey = "cycles" if s.cycles is not None else "duration_s"
        pairs = [
            (ai, fi) for ai in range(len(s.amplitudes_V)) for fi in range(len(s.frequencies_hz))
        ]
        if s.order == "by_frequency":
            pairs.sort(key=lambda p: (p[1], p[0]))
        for ai, fi in pairs:
            a, f = s.amplitudes_V[ai], s.frequencies_hz[fi]
            where = {
                "step": self.where(base),
                "amplitude_V": self.where((*base, "amplitudes_V", ai)),
                "frequency_hz": self.where((*base, "frequencies_hz", fi)),
                "length": self.where((*base, lkey)),
            }
            c = self._sine(a, f, s.cycles, s.duration_s, s.min_duration_s, where)
            if c is None:
                continue
            if s.name:
                c.base_name = f"{s.name}_{num_tag(a)}V_{num_tag(f)}Hz"
            c.definition["sweep"] = {"amplitude_index": ai, "frequency_index": fi}
            out.append(c)
        return out

    def _envelope(self, s, base: tuple, amplitude_key: str, amplitude: float):
        """Pieces, definition and places of a vanishing envelope (volts or ue), or None."""
        where = {
            "step": self.where(base),
            amplitude_key: self.where((*base, amplitude_key)),
            "frequency_hz": self.where((*base, "frequency_hz")),
            "length": self.where((*base, "decay_s")),
            "hold_s": self.where((*base, "hold_s")),
        }
        n = self.n_of(0.5 / s.frequency_hz + s.decay_s, where["length"], "the envelope")
        nh = intervals(s.hold_s, self.rate)
        if nh > MAX_STEP_SAMPLES:
            self.n_of(s.hold_s, where["hold_s"], "the hold")
            return None
        if n is None:
            return None
        tau = (
            (s.decay_s / 2.0 if s.tau_s is None else s.tau_s) if s.shape == "exponential" else None
        )
        f = s.frequency_hz
        pieces = [
            wf.vanishing_segment(amplitude, f, s.decay_s, s.shape, tau, n, "frequency_hz"),
            wf.const_segment(0.0, nh, "hold_s"),
        ]
        definition = {
            amplitude_key: amplitude,
            "frequency_hz": f,
            "first_peak_s": 0.5 / f,
            "decay_s": s.decay_s,
            "envelope_end_s": n / self.rate,
            "shape": s.shape,
            "tau_s": tau,
            "hold_s": nh / self.rate,
        }
        return pieces, definition, where

    def vanishing(self, s: VanishingStep, base: tuple) -> list[Concrete]:
        env = self._envelope(s, base, "amplitude_V", s.amplitude_V)
        if env is None:
            return []
        pieces, definition, where = env
        definition = {"kind": "vanishing", **definition}
        name = s.name or f"vanishing_{num_tag(s.amplitude_V)}V_{num_tag(s.frequency_hz)}Hz"
        return [
            Concrete("vanishing", name, pieces, definition, where, s.amplitude_V, s.frequency_hz)
        ]

    def hold(self, s: HoldStep, base: tuple) -> list[Concrete]:
        where = {
            "step": self.where(base),
            "voltage_V": self.where((*base, "voltage_V")),
            "length": self.where((*base, "duration_s")),
        }
        n = self.n_of(s.duration_s, where["length"], "the hold")
        if n is None:
            return []
        definition = {"kind": "hold", "voltage_V": s.voltage_V, "duration_s": n / self.rate}
        name = s.name or f"hold_{num_tag(s.voltage_V)}V_{num_tag(s.duration_s)}s"
        seg = wf.const_segment(s.voltage_V, n, "voltage_V")
        return [Concrete("hold", name, [seg], definition, where, abs(s.voltage_V))]

    def ramp(self, s: RampStep, base: tuple) -> list[Concrete]:
        where = {
            "step": self.where(base),
            "from_V": self.where((*base, "from_V")),
            "to_V": self.where((*base, "to_V")),
            "length": self.where((*base, "duration_s")),
        }
        n = self.n_of(s.duration_s, where["length"], "the ramp")
        if n is None:
            return []
        definition = {
            "kind": "ramp",
            "from_V": s.from_V,
            "to_V": s.to_V,
            "duration_s": n / self.rate,
        }
        name = s.name or f"ramp_{num_tag(s.from_V)}V_to_{num_tag(s.to_V)}V"
        seg = wf.ramp_segment(s.from_V, s.to_V, n, self.rate, "length")
        amp = max(abs(s.from_V), abs(s.to_V))
        return [Concrete("ramp", name, [seg], definition, where, amp)]

    def csv(self, s: CsvStep, base: tuple) -> list[Concrete]:
        where = {k: self.where((*base, k)) for k in ("path", "column", "time_column", "scale")}
        where["step"] = self.where(base)
        where["length"] = where["path"]
        try:
            v, info = load_csv(s, self.base_dir, self.rate)
        except CsvError as e:
            self.issue(where.get(e.key, where["path"]), e.message)
            return []
        if v.size - 1 > MAX_STEP_SAMPLES:
            self.issue(where["path"], f"{v.size} samples; at most {MAX_STEP_SAMPLES} per entry")
            return []
        definition = {"kind": "csv", **info, "duration_s": (v.size - 1) / self.rate}
        name = s.name or f"csv_{sanitize(resolve_csv_path(s, self.base_dir).stem)}"[:60]
        seg = wf.table_segment(v, self.rate, "path")
        return [Concrete("csv", name, [seg], definition, where, float(np.max(np.abs(v))))]

    # --- triangle, PRBS, multisine (labrig.protocol.broadband) ---

    def _around_where(self, base: tuple, keys: tuple[str, ...], length_key: str) -> dict:
        where = {k: self.where((*base, k)) for k in ("offset_V", "amplitude_V", *keys)}
        where["step"] = self.where(base)
        where["length"] = self.where((*base, length_key))
        return where

    def triangle(self, s: TriangleStep, base: tuple) -> list[Concrete]:
        lkey = "cycles" if s.cycles is not None else "duration_s"
        where = self._around_where(base, ("frequency_hz", "start"), lkey)
        seconds = s.cycles / s.frequency_hz if s.cycles is not None else s.duration_s
        what = f"the {s.amplitude_V:g} V, {s.frequency_hz:g} Hz triangle"
        n = self.n_of(seconds, where["length"], what)
        if n is None:
            return []
        pieces, definition = bb.triangle_parts(s, n, self.rate)
        name = s.name or bb.triangle_name(s)
        a, f = s.amplitude_V, s.frequency_hz
        return [Concrete("triangle", name, pieces, definition, where, a, f)]

    def prbs(self, s: PrbsStep, base: tuple) -> list[Concrete]:
        lkey = "periods" if s.periods is not None else "duration_s"
        keys = ("clock_hz", "order", "seed", "transition_s")
        where = self._around_where(base, keys, lkey)
        chips = bb.prbs_chips(s)
        n = self.n_of(chips / s.clock_hz, where["length"], "the prbs")
        if n is None:
            return []
        if s.transition_s * self.rate < 1.0 - 1e-9:
            self.issue(
                where["transition_s"],
                f"transition_s {s.transition_s:g} s is shorter than one sample at "
                f"{self.rate:g} Hz: the DAC would step; use transition_s >= {1 / self.rate:g} "
                "or raise rate_hz",
            )
            return []
        pieces, definition = bb.prbs_parts(s, n, self.rate)
        name = s.name or bb.prbs_name(s)
        return [Concrete("prbs", name, pieces, definition, where, s.amplitude_V, None)]

    def multisine(self, s: MultisineStep, base: tuple) -> list[Concrete]:
        where = self._around_where(base, ("frequencies_hz",), "duration_s")
        n = self.n_of(s.duration_s, where["length"], "the multisine")
        if n is None:
            return []
        work, most = bb.multisine_work(len(s.frequencies_hz), n), bb.MAX_MULTISINE_LINE_SAMPLES
        if work > most:  # its peak search and its samples would take minutes to compute
            self.issue(
                where["length"],
                f"{len(s.frequencies_hz)} lines over {n + 1} samples ({work:.3g} "
                f"line-samples) are more than a multisine may have ({most:.3g}; each sample "
                "sums every line): "
                f"use fewer lines, a shorter duration_s or a lower rate_hz (at most "
                f"{at_most(most / len(s.frequencies_hz) / self.rate)} s here)",
            )
            return []
        pieces, definition = bb.multisine_parts(s, n, self.rate)
        name = s.name or bb.multisine_name(s)
        c = Concrete("multisine", name, pieces, definition, where, s.amplitude_V, None)
        return [c]

    # --- strain-command steps: the command is a strain, the controller makes the voltage ---

    def _load_params(self, s, base: tuple):
        """The step's model parameters (or the protocol's), or None with an issue recorded."""
        from labrig.control import load_control_model

        if s.params is not None:
            ref, w = s.params, self.where((*base, "params"))
        elif self.p.params is not None:
            ref, w = self.p.params, self.where(("params",))
        else:
            self.issue(
                self.where(base),
                f"a {s.kind} step needs model parameters: params: FILE (a JSON file from "
                "`labrig fit --out`), on the step or at the top of the protocol",
            )
            return None, None
        path = Path(ref).expanduser()
        if not path.is_absolute():
            path = self.base_dir / path
        if path not in self._params:
            try:
                self._params[path] = load_control_model(path)
            except FileNotFoundError:
                self._params[path] = f"parameter file not found: {path}"
            except (OSError, ValueError) as e:
                self._params[path] = f"cannot use {path}: {e}"
        got = self._params[path]
        if isinstance(got, str):
            self.issue(w, got)
            return None, None
        return got, path

    def _strain(
        self, s, base: tuple, kind: str, name: str, pieces, definition, where, freq
    ) -> list[Concrete]:
        """Compose the strain command, compute the drive, return the concrete step."""
        from labrig.control import compute_drive

        model, _ = self._load_params(s, base)
        if model is None:
            return []
        params = model.params
        where = {
            **where,
            "params": self.where((*base, "params") if s.params else ("params",)),
        }
        slew_ue = self.p.edge_slew_V_per_s * params.alpha0_ue_per_V
        try:
            command = wf.compose(pieces, self.rate, slew_ue, "", MAX_STRAIN_SAMPLES)
        except wf.TooLongError as e:
            self.issue(
                where["length"],
                f"the strain command would have {e.n} samples; a {kind} step may have at most "
                f"{MAX_STRAIN_SAMPLES} (its drive is computed in advance): shorten it or lower "
                "rate_hz",
            )
            return []
        strain = command.samples()
        try:
            drive = compute_drive(strain, model, self.rate, s.control)
        except ValueError as e:
            self.issue(where["step"], f"cannot compute the {s.control} drive: {e}")
            return []
        if not np.all(np.isfinite(drive)):
            self.issue(where["step"], f"the {s.control} drive is not finite (check params)")
            return []
        key = "path" if kind == "strain_csv" else "amplitude_ue"
        # a 0 V sample first: the controller assumes the actuator at rest before t_0, and the
        # waveform starts at exactly 0 V; drive[n] is then sample n + 1 of the entry
        table = np.concatenate(([0.0], drive))
        seg = wf.table_segment(table, self.rate, key)
        seg = wf.Segment(kind, seg.n, seg.func, key)
        definition = {
            "kind": kind,
            **definition,
            "control": s.control,
            "params_file": str(s.params if s.params is not None else self.p.params),
            "model_params": params.model_dump(),
            "model_creep": (
                None if model.creep is None else {"c": model.creep[0], "tau_s": model.creep[1]}
            ),
            "model_remanence": (
                None
                if model.remanence is None
                else dict(
                    zip(("A_ue_per_V", "beta_per_V", "gamma_per_V"), model.remanence, strict=True)
                )
            ),
            "strain_edge_ramps": sum(1 for g in command.segments if g.role == "edge"),
            "command_start_index": 1,
            "command_stop_index": int(strain.size + 1),
            "drive_min_V": float(np.min(drive)),
            "drive_max_V": float(np.max(drive)),
        }
        amp = round(float(np.max(np.abs(drive))), 2) if drive.size else 0.0
        c = Concrete(kind, f"{name}_{s.control}", [seg], definition, where, amp, freq)
        if s.name:
            c.base_name = s.name
        c.strain = strain
        return [c]

    def strain_sine(self, s: StrainSineStep, base: tuple) -> list[Concrete]:
        lw = self.where((*base, "cycles" if s.cycles is not None else "duration_s"))
        where = {
            "step": self.where(base),
            "amplitude_ue": self.where((*base, "amplitude_ue")),
            "frequency_hz": self.where((*base, "frequency_hz")),
            "length": lw,
        }
        a, f = s.amplitude_ue, s.frequency_hz
        seconds = s.cycles / f if s.cycles is not None else s.duration_s
        n = self.n_of(seconds, lw, f"the {num_tag(a)} ue, {f:g} Hz strain sine")
        if n is None:
            return []
        definition = {
            "amplitude_ue": a,
            "frequency_hz": f,
            "cycles": s.cycles if s.cycles is not None else s.duration_s * f,
            "duration_s": n / self.rate,
        }
        pieces = [wf.sine_segment(a, f, n, "frequency_hz")]
        name = f"strain_sine_{num_tag(a)}ue_{num_tag(f)}Hz"
        return self._strain(s, base, "strain_sine", name, pieces, definition, where, f)

    def strain_vanishing(self, s: StrainVanishingStep, base: tuple) -> list[Concrete]:
        env = self._envelope(s, base, "amplitude_ue", s.amplitude_ue)
        if env is None:
            return []
        pieces, definition, where = env
        a, f = s.amplitude_ue, s.frequency_hz
        name = f"strain_vanishing_{num_tag(a)}ue_{num_tag(f)}Hz"
        return self._strain(s, base, "strain_vanishing", name, pieces, definition, where, f)

    def strain_csv(self, s: StrainCsvStep, base: tuple) -> list[Concrete]:
        where = {k: self.where((*base, k)) for k in ("path", "column", "time_column", "scale")}
        where["step"] = self.where(base)
        where["length"] = where["path"]
        try:
            v, info = load_csv(s, self.base_dir, self.rate)  # type: ignore[arg-type]
        except CsvError as e:
            self.issue(where.get(e.key, where["path"]), e.message)
            return []
        if v.size - 1 > MAX_STRAIN_SAMPLES:
            self.issue(
                where["path"],
                f"{v.size} samples; a strain command may have at most {MAX_STRAIN_SAMPLES}",
            )
            return []
        definition = {**info, "duration_s": (v.size - 1) / self.rate}
        stem = sanitize(resolve_csv_path(s, self.base_dir).stem)  # type: ignore[arg-type]
        name = f"strain_csv_{stem}"[:48]
        pieces = [wf.table_segment(v, self.rate, "path")]
        return self._strain(s, base, "strain_csv", name, pieces, definition, where, None)

    def count(self) -> int:
        total = 0
        for s in self.p.steps:
            k = len(s.amplitudes_V) * len(s.frequencies_hz) if isinstance(s, SweepStep) else 1
            total += k * s.repeat
        return total

    def build(self) -> list[PlannedStep]:
        n_entries = self.count()
        if n_entries > MAX_ENTRIES:
            self.issue(
                self.where(("steps",)),
                f"the protocol expands to {n_entries} entries; at most {MAX_ENTRIES} are allowed",
            )
            raise _PlanError(self.issues)
        steps: list[PlannedStep] = []
        used: set[str] = set()
        for si, step in enumerate(self.p.steps):
            one = getattr(self, step.kind)(step, ("steps", si))
            rest = self.p.rest_s if step.rest_s is None else step.rest_s
            for r in range(step.repeat):
                for c in one:
                    name = _unique_name(c.base_name, used)
                    used.add(name.lower())
                    planned = self.entry(c, name, len(steps), si, r + 1, rest)
                    if planned is not None:
                        steps.append(planned)
        if steps:
            steps[-1].rest_after_s = 0.0
        recorded = sum(s.duration_s for s in steps)
        rests = sum(s.rest_after_s for s in steps)
        total = recorded + rests
        if total > MAX_TOTAL_S:
            # the rests (rest_s) count: name where the time is
            where = (
                ("rest_s",)
                if rests > recorded and "rest_s" in self.p.model_fields_set
                else ("steps",)
            )
            self.issue(
                self.where(where),
                f"the protocol lasts {beyond(total / 3600, MAX_TOTAL_S / 3600)} h "
                f"({fixed(recorded / 3600, 1)} h of entries, {fixed(rests / 3600, 1)} h of "
                f"rests); at most {MAX_TOTAL_S / 3600:.0f} h are allowed in one run (split it "
                "into several protocols, or shorten the rests)",
            )
        if self.issues:
            raise _PlanError(self.issues)
        return steps

    def entry(
        self, c: Concrete, name: str, index: int, si: int, repeat: int, rest: float
    ) -> PlannedStep | None:
        """Repetition ``repeat`` of the concrete step ``c`` of protocol step ``si`` as the plan's
        entry ``index``: its pieces joined by edge ramps, or None (issue recorded)."""
        edge_where = self.where(("edge_slew_V_per_s",))
        where = dict(c.where)
        where["edge_slew_V_per_s"] = edge_where
        where["rate_hz"] = self.where(("rate_hz",))
        try:
            waveform = wf.compose(
                c.pieces, self.rate, self.p.edge_slew_V_per_s, "edge_slew_V_per_s", MAX_STEP_SAMPLES
            )
        except wf.TooLongError as e:
            # the count saturates at 2**62 (labrig.protocol.waveforms.edge_samples): not shown
            count = f"{e.n} samples, more" if e.n < 2**62 else "more samples"
            blame, why = where["length"], ""
            if e.edge:
                volts = max(abs(e.from_V), abs(e.to_V))
                why = (
                    f" (its edge ramp from {e.from_V:.4g} V to {e.to_V:.4g} V at "
                    f"edge_slew_V_per_s {self.p.edge_slew_V_per_s:g} V/s is too long)"
                )
                # a voltage no amplifier gives is what to fix, not the slew rate
                absurd = volts > MAX_SANE_VOLTAGE_V and e.field in where
                blame = where[e.field] if absurd else edge_where
            self.issue(
                blame,
                f"{name} would have {count} than the {MAX_STEP_SAMPLES} allowed in one entry{why}",
            )
            return None
        aux = {}
        if c.strain is not None:
            # expected strain at each entry sample: rest, the command, then its last value
            # during the closing 0 V edge ramp (control is lost there)
            tail = waveform.n_samples - 1 - c.strain.size
            aux["command_strain"] = (
                "ue",
                "strain command (expected strain at each sample)",
                np.concatenate(([0.0], c.strain, np.full(tail, c.strain[-1]))),
            )
        definition = {
            **c.definition,
            "rate_hz": self.rate,
            "n_samples": waveform.n_samples,
            "total_duration_s": waveform.duration_s,
            "edge_ramps": sum(1 for g in waveform.segments if g.role == "edge"),
            "source_step": si,
            "repeat": repeat,
        }
        return PlannedStep(
            index=index,
            name=name,
            kind=c.kind,
            source_step=si,
            repeat_index=repeat,
            definition=definition,
            rate_hz=self.rate,
            waveform=waveform,
            rest_after_s=rest,
            amplitude_V=c.amplitude_V,
            frequency_hz=c.frequency_hz,
            where=where,
            aux=aux,
        )


def _unique_name(base: str, used: set[str]) -> str:
    """``base``, else ``base_2``, ``base_3``, ...: the first not in ``used`` (lower case) and not
    ``run`` (the run file's own group)."""
    name = base
    k = 2
    while name.lower() in used or name.lower() == "run":
        name = f"{base}_{k}"
        k += 1
    return name


def build_plan(
    protocol: Protocol,
    *,
    path: Path | str = "<protocol>",
    text: str = "",
    lines: dict | None = None,
) -> Plan:
    """Expand ``protocol`` (read from ``path``; CSV and rig paths are relative to its folder).

    Raises :class:`InputFileError` for problems found while expanding (CSV files, lengths).
    """
    path = Path(path)
    file = str(path)
    lines = lines or {}
    b = _Builder(protocol, lines, file, path.parent)
    try:
        steps = b.build()
    except _PlanError as e:
        raise InputFileError(e.issues) from None
    rig_path = None
    if protocol.rig is not None:
        rig_path = Path(protocol.rig).expanduser()
        if not rig_path.is_absolute():
            rig_path = path.parent / rig_path
        if not rig_path.is_file():
            w = Where("rig", line_of(("rig",), lines))
            why = "not a file" if rig_path.exists() else "rig file not found"
            raise InputFileError([InputIssue(file, w.line, w.field, f"{why}: {rig_path}")])
    return Plan(
        path=path,
        file=file,
        text=text,
        protocol=protocol,
        lines=lines,
        steps=steps,
        rig_path=rig_path,
    )
