"""Residual evidence for ``labrig diagnose``: noise floor, harmonics, features, sentences.

Everything here *describes* residuals (``measured - predicted``, ue) for the report and for the
candidates' evidence; nothing here decides (docs/method.md: with 1e4-1e5 samples almost
any structure is "significant"; the decision is made by held-out prediction error).

- **Noise floor** of an entry (:mod:`labrig.analysis.noise_floor`, the one estimator of every
  command): the residual's period-to-period scatter, in percent of the measured span.
- **Harmonic table** of a periodic entry: the residual's Fourier coefficients at ``k f0``
  (``k = 1..5``) over its whole periods, in percent of the measured strain's fundamental, with
  the phase relative to that fundamental (-90 deg: the residual *lags*... see ``quadrature``).
- **Features** (campaign level): how the per-entry residual scales with frequency and amplitude,
  its correlation with ``|dV/dt|``, with ``V^2 - mean`` (Billings-Voon, even nonlinearity),
  with the input at lags (residual-input cross-correlation), its lag-1 autocorrelation
  (whiteness), trends within entries, spectral lines that are not drive harmonics, and the aux
  channels (temperature, the amplifier's measured voltage versus the command).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.metrics import drive_frequency_hz, is_periodic
from labrig.analysis.noise_floor import residual_noise, resolution_of
from labrig.analysis.records import Record
from labrig.analysis.signals import step_hold
from labrig.analysis.spectra import spectral_lines
from labrig.model import DynamicHysteresisModel, ModelParams
from labrig.model.effects import Context, Effect

__all__ = [
    "MIN_SPREAD",
    "EntryEvidence",
    "Evidence",
    "collect_evidence",
    "modelled_creep_per_decade",
]


@dataclass
class EntryEvidence:
    name: str
    nrmse_pct: float
    floor_pct: float
    span_ue: float
    rms_ue: float
    frequency_hz: float | None
    amplitude_V: float
    periodic: bool
    harmonics: list[dict[str, float]] = field(default_factory=list)
    quadrature: float | None = None  # fraction of the residual fundamental in quadrature
    lag_deg: float | None = None  # phase of the residual fundamental vs the strain's
    trend_share: float = 0.0  # share of the residual variance a linear trend explains
    lines: list[dict[str, float]] = field(default_factory=list)  # non-synchronous lines
    temperature_rise_K: float | None = None
    amp_departure_V: float | None = None
    #: for a part of a record cut into entries (``meta["split_of"]``): the stretch of that
    #: record it covers, e.g. "t = 62.5-125 s of real50k" (the record's own time, s)
    part_of: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items()}


@dataclass
class Evidence:
    entries: dict[str, EntryEvidence]
    floor_pct: float
    nrmse_pct: float
    ratio: float  # NRMSE / floor
    features: dict[str, float | None]
    sentences: list[str]

    def to_json(self) -> dict[str, Any]:
        return {
            "floor_pct": self.floor_pct,
            "nrmse_pct": self.nrmse_pct,
            "ratio_to_floor": self.ratio,
            "features": dict(self.features),
            "entries": {k: e.to_json() for k, e in self.entries.items()},
            "sentences": list(self.sentences),
        }


def _corr(a: NDArray, b: NDArray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a @ a) * (b @ b)))
    return float(a @ b / den) if den > 0 else 0.0


def _fourier(x: NDArray, rate: float, f: float) -> complex:
    t = np.arange(x.size) / rate
    return complex(2.0 / x.size * np.sum(x * np.exp(-2j * np.pi * f * t)))


def _lines(r: Record, res: NDArray, f0: float | None) -> list[dict[str, float]]:
    """Strongest spectral lines of the residual that are not harmonics of the drive
    (:func:`~labrig.analysis.spectra.spectral_lines`; the drive frequency known to 1e-4 when
    stated, to half a bin of the record when estimated)."""
    du = None
    if f0 is not None:
        du = 1e-4 * f0 if r.frequency_hz is not None else 0.5 * r.rate_hz / r.n
    return [
        {"frequency_hz": x["frequency_hz"], "amplitude_ue": x["amplitude"], "snr": x["snr"]}
        for x in spectral_lines(res, r.rate_hz, f0, du)
    ]


def _harmonics(e: EntryEvidence, res: NDArray, m: NDArray, rate: float, period: int) -> None:
    """The residual's harmonic table over whole periods, in % of the strain's fundamental, and
    the quadrature share and lag of its fundamental."""
    f0 = e.frequency_hz
    assert f0 is not None
    nper = (res.size // period) * period
    x = res[res.size - nper :]
    s = m[m.size - nper :]
    fund = _fourier(s, rate, f0)
    for k in range(1, 6):
        if k * f0 >= 0.5 * rate:
            break
        c = _fourier(x, rate, k * f0)
        e.harmonics.append(
            {
                "k": k,
                "amplitude_pct": 100 * abs(c) / max(abs(fund), 1e-12),
                "phase_deg": float(np.degrees(np.angle(c / fund))) if fund else 0.0,
            }
        )
    c1 = _fourier(x, rate, f0)
    if abs(c1) > 0 and fund:
        rel = c1 / fund
        e.quadrature = float(abs(rel.imag) / abs(rel))
        e.lag_deg = float(np.degrees(np.angle(rel)))


def _entry_evidence(r: Record, m: NDArray, p: NDArray) -> EntryEvidence:
    """The evidence of one entry from its measured ``m`` and predicted ``p`` strain (after the
    warm-up)."""
    res = m - p
    span = float(np.ptp(m))
    f0 = drive_frequency_hz(r)
    per = is_periodic(r.voltage_V, r.rate_hz, f0)
    period = round(r.rate_hz / f0) if per and f0 else None
    rms = float(np.sqrt(np.mean(res * res)))
    e = EntryEvidence(
        r.name,
        100 * rms / span,
        100 * residual_noise(res, period, resolution_of(m)) / span,
        span,
        rms,
        f0,
        float(np.ptp(r.voltage_V)),
        per,
    )
    if per and period:
        _harmonics(e, res, m, r.rate_hz, period)
    cc = _corr(res, np.arange(res.size).astype(float))
    e.trend_share = cc * cc
    e.lines = _lines(r, res, f0)
    if "temperature" in r.aux:
        T = r.aux["temperature"]
        e.temperature_rise_K = float(np.median(T[-50:]) - np.median(T[:50]))
    if "amplifier_voltage" in r.aux:
        e.amp_departure_V = float(np.max(np.abs(r.aux["amplifier_voltage"] - r.voltage_V)))
    e.part_of = _part_of(r)
    return e


def _part_of(r: Record) -> str | None:
    """Where a part of a cut record (:func:`labrig.analysis.split.split_entries`) lies in the
    record it was cut from, in that record's time (s, its last sample's interval included), or
    ``None`` for an entry of its own."""
    src = r.meta.get("split_of")
    if src is None or r.n == 0:
        return None
    t0, t1 = float(r.time_s[0]), float(r.time_s[-1]) + 1.0 / r.rate_hz
    return f"t = {t0:.4g}-{t1:.4g} s of {src}"


#: entries whose frequencies (or amplitudes) all lie within this share of the largest are one
#: drive: no scaling with frequency (amplitude) is read from them (the parts of one record
#: differ by the rounding of their estimates)
MIN_SPREAD = 0.05


def _spread(x: NDArray) -> bool:
    """Whether the values ``x`` differ by at least :data:`MIN_SPREAD` of the largest |x|."""
    top = float(np.max(np.abs(x))) if x.size else 0.0
    return top > 0 and float(np.ptp(x)) >= MIN_SPREAD * top


def _campaign_features(
    ents: list[EntryEvidence],
    res: NDArray,
    inputs: list[NDArray],
    temps: list[tuple[NDArray, NDArray, NDArray]],
    rate_hz: list[float],
) -> dict[str, float | None]:
    """Features over all entries: correlations of the span-normalised residual ``res`` with the
    inputs ``inputs`` (per entry, after the warm-up), scaling of the excess over the floor with
    frequency and amplitude, trends, and the residual against strain x temperature."""
    dv = [np.abs(np.diff(v, prepend=v[0])) * fs for v, fs in zip(inputs, rate_hz, strict=True)]
    v2 = [(v - v.mean()) ** 2 for v in inputs]
    feats: dict[str, float | None] = {}
    feats["abs_residual_vs_abs_dVdt"] = _corr(np.abs(res), np.concatenate(dv))
    feats["residual_vs_V2"] = _corr(res, np.concatenate([x - x.mean() for x in v2]))
    feats["lag1_autocorrelation"] = _corr(res[1:], res[:-1])
    vv = np.concatenate(inputs)
    xc = [abs(_corr(res[k:], vv[: vv.size - k])) for k in (0, 1, 2, 5, 10, 20)]
    feats["max_residual_input_xcorr"] = max(xc)
    fs = np.array([e.frequency_hz or np.nan for e in ents])
    amps = np.array([e.amplitude_V for e in ents])
    ratio_e = np.array([e.nrmse_pct / max(e.floor_pct, 1e-12) for e in ents])
    ok = np.isfinite(fs) & (fs > 0)
    feats["excess_vs_log_frequency"] = (
        _corr(np.log(fs[ok]), ratio_e[ok]) if ok.sum() >= 3 and _spread(fs[ok]) else None
    )
    feats["excess_vs_amplitude"] = (
        _corr(amps, ratio_e) if len(ents) >= 3 and _spread(amps) else None
    )
    q = [e.quadrature for e in ents if e.quadrature is not None]
    feats["mean_quadrature_fraction"] = float(np.mean(q)) if q else None
    feats["mean_trend_share"] = float(np.mean([e.trend_share for e in ents]))
    if temps:
        rr = np.concatenate([a for a, _, _ in temps])
        t_ref = temps[0][2][0]  # the campaign's first temperature: hot and cool entries compare
        pt = np.concatenate([p * (T - t_ref) for _, p, T in temps])
        feats["residual_vs_strain_x_temperature"] = _corr(rr, pt)
    return feats


def collect_evidence(
    records: list[Record], predictions: dict[str, NDArray], warmup_s: float = 0.0
) -> Evidence:
    """Evidence from the residuals of ``predictions`` (entry name -> strain over the record)."""
    ents: dict[str, EntryEvidence] = {}
    all_res, inputs, rates = [], [], []
    temps = []
    for r in records:
        if r.name not in predictions:
            continue
        i0 = round(max(warmup_s, 0.0) * r.rate_hz)
        m = r.strain_ue[i0:]
        p = predictions[r.name][i0:]
        e = ents[r.name] = _entry_evidence(r, m, p)
        if "temperature" in r.aux:
            temps.append((m - p, p, r.aux["temperature"][i0:]))
        all_res.append((m - p) / e.span_ue)
        inputs.append(r.voltage_V[i0:])
        rates.append(r.rate_hz)
    lst = list(ents.values())
    feats = _campaign_features(lst, np.concatenate(all_res), inputs, temps, rates)
    floor = float(np.mean([e.floor_pct for e in lst]))
    nr = float(np.mean([e.nrmse_pct for e in lst]))
    ev = Evidence(ents, floor, nr, nr / floor if floor > 0 else float("inf"), feats, [])
    ev.sentences = _sentences(ev)
    return ev


def _sentences(ev: Evidence) -> list[str]:
    f = ev.features
    out = [
        f"mean NRMSE {ev.nrmse_pct:.3g} % against a noise floor of {ev.floor_pct:.3g} % "
        f"(period-to-period residual differences): {ev.ratio:.2g} times the floor"
    ]
    lst = list(ev.entries.values())
    worst = max(lst, key=lambda e: e.nrmse_pct / max(e.floor_pct, 1e-12))
    where = f" ({worst.part_of})" if worst.part_of else ""
    out.append(
        f"worst entry {worst.name}{where}: {worst.nrmse_pct:.3g} % "
        f"({worst.nrmse_pct / max(worst.floor_pct, 1e-12):.2g} x its floor)"
    )
    cf = f.get("excess_vs_log_frequency")
    if cf is not None and abs(cf) > 0.6:
        out.append(f"the residual {'grows' if cf > 0 else 'shrinks'} with frequency (r = {cf:.2f})")
    ca = f.get("excess_vs_amplitude")
    if ca is not None and abs(ca) > 0.6:
        out.append(f"the residual {'grows' if ca > 0 else 'shrinks'} with amplitude (r = {ca:.2f})")
    q = f.get("mean_quadrature_fraction")
    if q is not None and q > 0.7:
        hf = [e for e in lst if e.lag_deg is not None]
        lag = np.median([e.lag_deg for e in hf]) if hf else 0.0
        out.append(
            f"its fundamental is mostly in quadrature with the strain ({100 * q:.0f} %, "
            f"phase {lag:+.0f} deg)"
        )
    c = f.get("abs_residual_vs_abs_dVdt")
    if c is not None and c > 0.3:
        out.append(f"|residual| rises with |dV/dt| (r = {c:.2f})")
    c = f.get("residual_vs_V2")
    if c is not None and abs(c) > 0.3:
        out.append(
            f"the residual correlates with V^2 (Billings-Voon r = {c:.2f}): even nonlinearity"
        )
    ts = f.get("mean_trend_share")
    if ts is not None and ts > 0.2:
        out.append(f"linear trends within entries carry {100 * ts:.0f} % of the residual variance")
    ct = f.get("residual_vs_strain_x_temperature")
    if ct is not None and abs(ct) > 0.3:
        rise = max((e.temperature_rise_K or 0.0) for e in lst)
        out.append(
            f"the residual follows strain x temperature (r = {ct:.2f}; the stack warmed by up to "
            f"{rise:.2g} K within an entry)"
        )
    dep = [e.amp_departure_V for e in lst if e.amp_departure_V is not None]
    if dep:
        out.append(
            f"the measured amplifier voltage departs from the command by up to {max(dep):.3g} V"
        )
    lines = [ln for e in lst for ln in e.lines]
    if lines:
        top = max(lines, key=lambda x: x["amplitude_ue"])
        out.append(
            f"spectral line at {top['frequency_hz']:.1f} Hz ({top['amplitude_ue']:.2g} ue) that "
            "is not a drive harmonic"
        )
    out.append(
        f"residual lag-1 autocorrelation {f['lag1_autocorrelation']:.2f}, largest residual-input "
        f"cross-correlation {f['max_residual_input_xcorr']:.2f} (descriptive only)"
    )
    return out


def modelled_creep_per_decade(
    params: ModelParams,
    step_V: float,
    t1_s: float = 1.0,
    t2_s: float = 100.0,
    creep_effects: Sequence[tuple[Effect, Mapping[str, float]]] = (),
) -> float:
    """Creep the dynamic model itself describes: the relative growth of the strain per decade of
    time between ``t1_s`` and ``t2_s`` after a step to ``step_V`` (V) from rest,
    ``(S(t2) / S(t1))^(1 / log10(t2 / t1)) - 1`` (a fraction; 0.05 = 5 %/decade; NaN when the
    strain is not positive at both times).

    The step is :func:`labrig.analysis.signals.step_hold` (raised-cosine ramp of
    0.2 s; times count from its end), simulated at 100 Hz with the model's ``predict`` (seed
    Eq. 5-7). The creep comes from the transient relaxor ``G_t`` (the paper's Eq. 4-9: its step
    response ``1 - E_lam(-(t/tau)^lam)`` grows almost logarithmically for a small ``lam``)
    passed through the operator's slope at ``step_V``; the paper's Table 1 stack creeps about
    6 %/decade this way. A logarithmic creep of the strain shifts ``lam_t``, ``tau_t`` and
    ``alpha0`` and shows up here unless it is added as an effect (docs/diagnose.md).

    ``creep_effects``: fitted library effects acting on the strain (``creep``,
    ``viscoelastic_creep``) with their parameters, applied in order to the model's strain, so
    that the figure is the whole model's.
    """
    rate_hz, ramp_s = 100.0, 0.2
    n = round((ramp_s + t2_s) * rate_hz) + 2
    v = step_hold(step_V, 2.0 * (ramp_s + t2_s), rate_hz, ramp_s=ramp_s)[:n]  # the held part
    s = DynamicHysteresisModel(params).predict(v, rate_hz)
    ctx = Context(rate_hz, v, {"step": slice(0, n)})
    for eff, p in creep_effects:
        s = eff.apply(s, ctx, p)
    t = np.arange(n) / rate_hz - ramp_s
    s1, s2 = np.interp([t1_s, t2_s], t, s)
    if not (s1 > 0 and s2 > 0):  # no strain to creep (a 0 V step) or a sign change: undefined
        return float("nan")
    return float((s2 / s1) ** (1.0 / np.log10(t2_s / t1_s)) - 1.0)
