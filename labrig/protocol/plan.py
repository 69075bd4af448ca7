"""The plan: what ``labrig run`` will do, one concrete step (a run-file entry) after another.

:func:`labrig.protocol.expand.build_plan` makes it from a validated protocol; the preflight
(:mod:`labrig.protocol.preflight`) measures it against a rig's limits and the plan keeps the
results (:meth:`Plan.take_checks`); the runner plays its steps. :class:`Where` ties every step
back to the line and field of the protocol file that produced it, for error messages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from labrig.protocol import waveforms as wf
from labrig.protocol.schema import Protocol
from labrig.rig.drive_load import DriveLoad
from labrig.rig.limits import RigLimits

__all__ = ["Plan", "PlannedStep", "Where", "field_name", "line_of"]


def field_name(path: tuple) -> str:
    """``("steps", 0, "frequencies_hz", 3)`` -> ``"steps[0].frequencies_hz[3]"``."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def line_of(path: tuple, lines: dict) -> int | None:
    """Line of ``path`` in the YAML file, else of its nearest written parent."""
    p = tuple(path)
    while p:
        if p in lines:
            return lines[p]
        p = p[:-1]
    return lines.get(())


@dataclass(frozen=True)
class Where:
    """A place in the protocol file: dotted field path and line."""

    field: str
    line: int | None


@dataclass
class PlannedStep:
    """One concrete step: an entry of the run file.

    ``definition`` is the JSON-able description stored with the entry; ``waveform`` produces
    the command samples (V) at ``rate_hz``, starting and ending at 0 V; ``where`` maps the keys
    that shaped the step (``amplitude_V``, ``frequency_hz``, ``length``, ``step``, ...) to their
    place in the protocol file.
    """

    index: int
    name: str
    kind: str
    source_step: int
    repeat_index: int
    definition: dict
    rate_hz: float
    waveform: wf.Waveform
    rest_after_s: float = 0.0
    amplitude_V: float | None = None
    frequency_hz: float | None = None
    where: dict[str, Where] = field(default_factory=dict)
    #: extra channels the runner records with the entry: name -> (units, long name, samples
    #: over the whole entry); strain-command steps record ``command_strain`` (ue)
    aux: dict[str, tuple[str, str, np.ndarray]] = field(default_factory=dict)

    @property
    def n_samples(self) -> int:
        return self.waveform.n_samples

    @property
    def duration_s(self) -> float:
        return self.waveform.duration_s

    def samples(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Command voltage samples ``start .. stop-1`` (V)."""
        return self.waveform.samples(start, stop)

    def times(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Sample times ``start .. stop-1`` (s since the start of the entry)."""
        return self.waveform.times(start, stop)

    @property
    def title(self) -> str:
        """Human-readable one-liner, e.g. ``sine 100 V, 40 Hz, 160 cycles (4 s)``."""
        d = self.definition
        if self.kind == "sine":
            what = f"sine {d['amplitude_V']:g} V, {d['frequency_hz']:g} Hz, {d['cycles']:g} cycles"
        elif self.kind == "offset_sine":
            what = (
                f"{d['envelope']} sine {d['offset_V']:g} V +- {d['amplitude_V']:g} V, "
                f"{d['frequency_hz']:g} Hz, {d['cycles']:g} cycles, after a {d['ramp_s']:g} s "
                f"ramp and {d['settle_s']:g} s settle"
            )
        elif self.kind == "triangle":
            what = (
                f"triangle {d['offset_V']:g} V +- {d['amplitude_V']:g} V, "
                f"{d['frequency_hz']:g} Hz, {d['cycles']:g} cycles"
            )
        elif self.kind == "prbs":
            what = (
                f"prbs {d['low_V']:g} / {d['high_V']:g} V, {d['clock_hz']:g} Hz clock, "
                f"{d['chips']} chips (LFSR order {d['order']}, seed {d['seed']}), "
                f"{d['transition_s']:g} s edges"
            )
        elif self.kind == "multisine":
            f = d["frequencies_hz"]
            what = (
                f"multisine {d['offset_V']:g} V +- {d['amplitude_V']:g} V, {len(f)} lines "
                f"{f[0]:g}..{f[-1]:g} Hz (Schroeder phases)"
            )
        elif self.kind == "vanishing":
            what = (
                f"vanishing envelope {d['amplitude_V']:g} V, {d['frequency_hz']:g} Hz carrier, "
                f"{d['shape']} decay over {d['decay_s']:g} s, {d['hold_s']:g} s hold"
            )
        elif self.kind == "hold":
            what = f"hold {d['voltage_V']:g} V"
        elif self.kind == "ramp":
            what = f"ramp {d['from_V']:g} V to {d['to_V']:g} V"
        elif self.kind == "strain_sine":
            what = (
                f"strain sine {d['amplitude_ue']:g} ue, {d['frequency_hz']:g} Hz, "
                f"{d['cycles']:g} cycles, {d['control']} control"
            )
        elif self.kind == "strain_vanishing":
            what = (
                f"vanishing strain {d['amplitude_ue']:g} ue, {d['frequency_hz']:g} Hz carrier, "
                f"{d['shape']} decay over {d['decay_s']:g} s, {d['hold_s']:g} s hold, "
                f"{d['control']} control"
            )
        elif self.kind == "strain_csv":
            what = f"strain from {d.get('file', 'CSV')}, {d['control']} control"
        else:
            what = f"samples from {d.get('file', 'CSV')}"
        return f"{what} ({self.duration_s:.4g} s)"

    def blame(self, key: str) -> Where:
        return self.where.get(key) or self.where["step"]


@dataclass
class Plan:
    """A validated, expanded protocol: what ``labrig run`` would do, step by step."""

    path: Path
    file: str
    text: str
    protocol: Protocol
    lines: dict
    steps: list[PlannedStep]
    rig_path: Path | None = None
    #: what the preflight measured on each entry and the limits it checked them against; set
    #: by :meth:`take_checks` (``None`` before the preflight)
    checks: list[DriveLoad] | None = None
    limits: RigLimits | None = None

    @property
    def name(self) -> str:
        return self.protocol.name

    @property
    def rate_hz(self) -> float:
        return self.protocol.rate_hz

    @property
    def recorded_duration_s(self) -> float:
        return sum(s.duration_s for s in self.steps)

    @property
    def total_duration_s(self) -> float:
        """Recorded time plus rests."""
        return sum(s.duration_s + s.rest_after_s for s in self.steps)

    @property
    def total_samples(self) -> int:
        return sum(s.n_samples for s in self.steps)

    def where(self, path: tuple) -> Where:
        return Where(field_name(path), line_of(path, self.lines))

    def step(self, name: str) -> PlannedStep:
        for s in self.steps:
            if s.name == name:
                return s
        raise KeyError(name)

    def take_checks(self, checks: list[DriveLoad], limits: RigLimits) -> None:
        """Keep the preflight's results (:func:`labrig.protocol.preflight.preflight_checks`)
        with the plan, for :meth:`to_dict` and :func:`labrig.protocol.check.format_plan`."""
        self.checks = checks
        self.limits = limits

    def to_dict(self) -> dict:
        """JSON-able summary (name, rate, entries with their definitions and checks)."""
        checks = {c.name: c for c in self.checks or []}
        entries = []
        for s in self.steps:
            d = {"name": s.name, "rest_after_s": s.rest_after_s, **s.definition}
            c = checks.get(s.name)
            if c is not None:
                d.update(
                    peak_current_A=c.peak_current_A,
                    mean_current_A=c.mean_current_A,
                    v_min_V=c.v_min_V,
                    v_max_V=c.v_max_V,
                )
            entries.append(d)
        return {
            "protocol": self.name,
            "file": self.file,
            "rig": str(self.rig_path) if self.rig_path else None,
            "rate_hz": self.rate_hz,
            "entries": entries,
            "recorded_duration_s": self.recorded_duration_s,
            "total_duration_s": self.total_duration_s,
        }
