"""What a model-versus-measurement report shows, computed from records and fitted models.

No files and no drawing here: :func:`build_report` turns the scored records, the predictions of
our model and of the baselines, and the run's provenance into a :class:`ReportData`;
:mod:`labrig.report.html` renders it and :func:`metrics_json` gives its metrics table to scripts.

Metrics (one definition each, :mod:`labrig.analysis.metrics`), per entry and per model:

- ``nrmse_pct``: NRMSE over the scored samples (after the warm-up): in-sample on the entries the
  models were identified on, out-of-sample on the others (``labrig report --params`` from
  another file or other entries; ``settings["in_sample"]`` names the former);
- ``heldout_nrmse_pct``: the same for a fit that did not use the entry (leave-one-entry-out);
- ``max_error_ue``: ``max |measured - predicted|`` over the scored samples;
- ``loop_area_error_pct``: predicted minus measured loop area over the last full period,
  relative to the measured one (periodic entries only);
- ``strain_shift_error_ue``: predicted minus measured strain at zero voltage over the last full
  period (periodic entries only).

The noise floor (the NRMSE a perfect model would reach) is measured on our model's residual by
:func:`labrig.analysis.noise_floor.noise_floor`, the estimator every command uses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.metrics import compare, drive_frequency_hz, is_periodic, last_period
from labrig.analysis.noise_floor import NoiseFloor
from labrig.analysis.records import Record
from labrig.core.jsonsafe import json_safe

#: models of a report, in display order: ours first, then the baselines
MODEL_KEYS: tuple[str, ...] = ("dynamic", "prandtl_ishlinskii", "bouc_wen", "sindy")
MODEL_LABELS: dict[str, str] = {
    "dynamic": "fractional-order model",
    "prandtl_ishlinskii": "Prandtl-Ishlinskii",
    "bouc_wen": "Bouc-Wen",
    "sindy": "SINDy (sparse ODE)",
}
#: the peers' names in a sentence
PEER_NAMES: dict[str, str] = {
    "prandtl_ishlinskii": "Prandtl-Ishlinskii",
    "bouc_wen": "Bouc-Wen",
    "sindy": "SINDy",
}
MODEL_SHORT: dict[str, str] = {
    "dynamic": "ours",
    "prandtl_ishlinskii": "PI",
    "bouc_wen": "BW",
    "sindy": "SINDy",
}

#: the metrics table: key, heading, unit (the NRMSE's heading says whether it is in-sample:
#: :func:`labrig.report.html.nrmse_scope`)
METRICS: tuple[tuple[str, str, str], ...] = (
    ("nrmse_pct", "NRMSE", "%"),
    ("heldout_nrmse_pct", "NRMSE held-out", "%"),
    ("max_error_ue", "max error", "ue"),
    ("loop_area_error_pct", "loop-area error", "%"),
    ("strain_shift_error_ue", "strain-shift error", "ue"),
)

#: parameters of our model: field, symbol, unit
PARAM_ROWS: tuple[tuple[str, str, str], ...] = (
    ("alpha0_ue_per_V", "α0", "ue/V"),
    ("gamma_ue_per_V", "γ", "ue/V"),
    ("vc_V", "Vc", "V"),
    ("lam_t", "λt", ""),
    ("tau_t_s", "τt", "s"),
    ("lam_d", "λd", ""),
    ("tau_d_s", "τd", "s"),
)


#: signed metrics, summarised by the mean of their absolute values
_SIGNED = frozenset({"loop_area_error_pct", "strain_shift_error_ue"})


@dataclass
class Fitted:
    """One model as the report sees it: its predictions of the scored entries and its scores.

    ``predictions`` is ``None`` when the model could not be fitted (``note`` says why).
    """

    key: str
    predictions: dict[str, NDArray[np.float64]] | None
    heldout_per_entry: dict[str, float] | None = None
    heldout_mean_pct: float | None = None  # when only the mean is known (a params file)
    params: dict[str, Any] = field(default_factory=dict)
    uncertainty: dict[str, float | None] = field(default_factory=dict)
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    method: str = ""
    note: str | None = None
    #: the stroke (V) of our model's loop coordinates (labrig.analysis.identifiability)
    loop_span_V: float | None = None
    #: our model's unidentifiable parameters as its fit judged them (parameter -> why: its
    #: free parameters and bounds known there), or ``None`` to judge them from the numbers
    unidentifiable: dict[str, str] | None = None

    @property
    def label(self) -> str:
        return MODEL_LABELS.get(self.key, self.key)


@dataclass
class EntryView:
    """One scored entry: its record and every model's metrics on it."""

    record: Record
    frequency_hz: float | None
    amplitude_V: float
    periodic: bool
    kind: str
    #: model key -> metrics of :func:`labrig.analysis.metrics.compare` plus ``heldout_nrmse_pct``
    metrics: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.record.name


@dataclass
class Provenance:
    """Where the data came from (the run file's own record of it)."""

    run_file: str
    status: str = ""
    reason: str = ""
    start_time: str = ""
    end_time: str = ""
    protocol_name: str = ""
    protocol_file: str = ""
    protocol_text: str = ""
    rig_file: str = ""
    rig_text: str = ""
    software_version: str = ""
    seed: int | None = None
    instrument: dict[str, Any] = field(default_factory=dict)
    n_entries: int = 0


@dataclass
class ReportData:
    title: str
    provenance: Provenance
    settings: dict[str, Any]
    entries: list[EntryView]
    models: dict[str, Fitted]
    warmup_s: float
    noise_floor: NoiseFloor | None
    notes: list[str]
    generated: str
    labrig_version: str

    def mean(self, model: str, metric: str) -> float | None:
        """Mean of a metric over the entries where it is defined (of ``|value|`` for the signed
        errors, loop area and strain shift)."""
        if metric == "heldout_nrmse_pct":
            fm = self.models.get(model)
            if fm is not None and fm.heldout_per_entry is None and fm.heldout_mean_pct is not None:
                return fm.heldout_mean_pct
        vals = []
        for e in self.entries:
            v = e.metrics.get(model, {}).get(metric)
            if v is not None and math.isfinite(v):
                vals.append(abs(v) if metric in _SIGNED else v)
        return float(np.mean(vals)) if vals else None


def amplitude_of(record: Record, frequency_hz: float | None) -> float:
    """The drive's peak-to-peak voltage (V): ``meta["amplitude_V"]`` if stated, else the span
    of the last period at ``frequency_hz`` (or of the whole record without one: pass ``None``
    when the last periods do not repeat, a vanishing envelope whose last period is a fraction
    of its drive), rounded to 3 significant digits."""
    a = record.meta.get("amplitude_V")
    try:
        if a is not None and float(a) > 0:
            return float(a)
    except (TypeError, ValueError):
        pass
    sl = last_period(record.n, record.rate_hz, frequency_hz)
    span = float(np.ptp(record.voltage_V[sl] if sl is not None else record.voltage_V))
    return float(f"{span:.3g}") if span > 0 else 0.0


def drive_of(record: Record) -> tuple[float | None, bool, float]:
    """The drive as a report states it: its frequency (Hz; stated in ``meta``, else estimated
    from the voltage and kept only when the last two periods at it repeat), whether they repeat
    (:func:`~labrig.analysis.metrics.is_periodic`) and the peak-to-peak voltage
    (:func:`amplitude_of`: of the last period when the periods repeat there, else of the whole
    record). A step sequence or a PRBS has a strongest spectral line but no period: an estimate
    there would describe it as a fast drive of one period's span; a vanishing envelope's last
    period spans a fraction of its drive (0.66 V of a drive up to 70 V)."""
    f = drive_frequency_hz(record)
    periodic = is_periodic(record.voltage_V, record.rate_hz, f)
    if record.frequency_hz is None and not periodic:
        f = None
    return f, periodic, amplitude_of(record, f if periodic else None)


def build_report(
    title: str,
    records: Sequence[Record],
    models: Mapping[str, Fitted],
    warmup_s: float,
    provenance: Provenance,
    settings: Mapping[str, Any],
    notes: Sequence[str] = (),
    noise_floor: NoiseFloor | None = None,
    generated: str = "",
    labrig_version: str = "",
) -> ReportData:
    """The report's content for the scored ``records`` and the fitted ``models``."""
    notes = list(notes)
    entries = []
    for r in records:
        f, per, amplitude = drive_of(r)
        ev = EntryView(r, f, amplitude, per, str(r.meta.get("kind", "")))
        for key, fm in models.items():
            if fm.predictions is None or r.name not in fm.predictions:
                continue
            m = compare(r, fm.predictions[r.name], warmup_s)
            held = None
            if fm.heldout_per_entry is not None:
                held = fm.heldout_per_entry.get(r.name)
            m["heldout_nrmse_pct"] = held
            ev.metrics[key] = json_safe(m)  # undefined metrics as None
        entries.append(ev)
    not_periodic = [e.name for e in entries if not e.periodic]
    if not_periodic:
        notes.append(
            "loop area and strain shift need a periodic drive (two repeating periods at the end "
            f"of the record); not computed for {', '.join(not_periodic)}"
        )
    for fm in models.values():
        if fm.predictions is None:
            notes.append(f"{fm.label}: not fitted ({fm.note})")
    return ReportData(
        title=title,
        provenance=provenance,
        settings=dict(settings),
        entries=entries,
        models=dict(models),
        warmup_s=warmup_s,
        noise_floor=noise_floor,
        notes=notes,
        generated=generated,
        labrig_version=labrig_version,
    )


def metrics_json(data: ReportData) -> dict[str, dict[str, float | None]]:
    """The metrics table for scripts: entry name -> ``"<model>.<metric>"`` -> value.

    ``<model>`` is ``dynamic`` (ours), ``prandtl_ishlinskii``, ``bouc_wen`` or ``sindy``;
    ``<metric>`` one of :data:`METRICS`; ``measured.loop_area_Vue`` and
    ``measured.strain_shift_ue`` give the measured values the errors refer to, and
    ``frequency_hz`` / ``amplitude_V`` the drive.
    ``null`` where a metric is undefined (non-periodic entry, no held-out fit, model not fitted).
    """
    out: dict[str, dict[str, float | None]] = {}
    for e in data.entries:
        row: dict[str, float | None] = {
            "frequency_hz": e.frequency_hz,
            "amplitude_V": e.amplitude_V,
        }
        meas = next(iter(e.metrics.values()), {})
        row["measured.loop_area_Vue"] = meas.get("loop_area_Vue")
        row["measured.strain_shift_ue"] = meas.get("strain_shift_ue")
        for key in data.models:
            m = e.metrics.get(key, {})
            for metric, _, _ in METRICS:
                v = m.get(metric)
                row[f"{key}.{metric}"] = None if v is None else float(v)
        out[e.name] = row
    return out
