"""The sparse ODE's held-out score does not depend on the sample rate
(``labrig/analysis/diagnose/sparse_ode.py``: identification on a band-limited working rate,
coefficients refined by output error, supports that do not settle at a held voltage dropped),
and a long idle start of a single record is left out before it is cut into parts
(``labrig/analysis/split.py``).

The reference of every score is independent of the identification: the truth's own held-out
prediction (its free run, scored by the same rule), whose error is the sensor noise alone.
Fast tier: a Duhem-form truth (the stand-in's, :mod:`labrig.studies.smart_standin`, with a
tenth of its ``|V'| S`` coefficient so that it contracts under its drive: the identification
keeps contracting ODEs) driven bipolar +-150 V at 1 Hz for two periods, sampled at 250 Hz and
at 2 kHz, two folds each; the
building blocks against their own references. ``@pytest.mark.slow``: every fold at both rates,
and the whole-file stand-in (5 kHz, 7.36 s idle then 2.64 periods) through ``diagnose``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from labrig.analysis.diagnose import diagnose
from labrig.analysis.diagnose.sparse_ode import (
    NAME,
    decimation,
    entry_score,
    identify,
    refine,
    settles,
    working_records,
)
from labrig.analysis.records import Record
from labrig.analysis.simulate import scored_sequences
from labrig.analysis.sindy import LIBRARY, SindyBaseline, free_run
from labrig.analysis.split import idle_lead, split_entries
from labrig.studies.smart_standin import NOISE_UM, TRUTH_XI, drive_on_s, standin_rows

TERMS = [t.name for t in LIBRARY]


def _ones(t: np.ndarray, _rate: float) -> np.ndarray:
    return np.ones((t.size, 1))


#: the stand-in's truth with a tenth of its ``|V'| S`` coefficient: it contracts under the
#: +-150 V 1 Hz drive (long-run growth -0.2088 + 1.196e-4 x 600 = -0.137 /s), where the
#: stand-in's own grows (+0.51 /s) and is, since the identification keeps contracting ODEs,
#: no longer what it returns (tests/diagnose/test_sparse_ode_contraction.py)
CONTRACTING_XI = tuple(
    x * 0.1 if t == "|V'| S" else x for x, t in zip(TRUTH_XI, TERMS, strict=True)
)


def two_periods(
    rate_hz: float, seed: int = 3, truth: tuple[float, ...] = CONTRACTING_XI
) -> list[Record]:
    """``truth`` driven by ``150 sin(2 pi t)`` V for 2 s from rest, noise ``NOISE_UM``, cut
    into 4 chained parts as diagnose cuts an imported record (one offset per part)."""
    t = np.arange(round(2.0 * rate_hz)) / rate_hz
    v = 150.0 * np.sin(2.0 * math.pi * t)
    s = free_run(truth, v, rate_hz) + np.random.default_rng(seed).normal(0, NOISE_UM, t.size)
    rec = Record.from_arrays("truth", rate_hz, v, s, hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def heldout(records: list[Record], fit, folds: tuple[int, ...] | None = None) -> float:
    """Mean held-out NRMSE (%) of leave-one-part-out (the parts ``folds``, all by default), as
    the sparse-ODE trial scores it: the model from ``fit(training items of the working
    records)`` run free over the chained record at its own rate, offset fitted on the first
    half of the part, scored on the second."""
    names = [r.name for r in records]
    scored = scored_sequences(records, names, 0.0, True)
    work = scored_sequences(working_records(records, decimation(records)), names, 0.0, True)
    out = []
    for n in names if folds is None else [names[k] for k in folds]:
        items = [(s.seq, [g for g in s.segments if g.name != n]) for s in work]
        out.append(entry_score(scored, fit(items), n, _ones, True)[0])
    return float(np.mean(out))


def truth_heldout(
    records: list[Record], folds: tuple[int, ...] | None = None, truth: tuple = CONTRACTING_XI
) -> float:
    model = SindyBaseline(truth, records[0].rate_hz, 0.0)
    return heldout(records, lambda _items: model, folds)


@pytest.mark.parametrize("rate_hz", [250.0, 2000.0])
def test_the_sparse_ode_predicts_two_held_out_parts_within_1_25x_the_truth_at_two_rates(rate_hz):
    """At 250 Hz (no resampling) and 2 kHz (identified at a working rate of 1/4 of it), the ODE
    identified without part 2 (then without part 4, the last) predicts it within 1.25x of the
    truth's own held-out score there (the noise alone: 0.05 um on parts of 20-23 um, about
    0.24 %). Measured 2026-11-27 (the contracting truth): 1.06x at 250 Hz, 1.02x at 2 kHz;
    2.9 and 1.2 s of CPU (two of the four folds; all four: the slow test below)."""
    recs = two_periods(rate_hz)
    ref = truth_heldout(recs, (1, 3))
    got = heldout(recs, lambda items: identify(items, True), (1, 3))
    assert 0.2 < ref < 0.3, ref
    assert got <= 1.25 * ref, (got, ref)


@pytest.mark.slow
@pytest.mark.parametrize("rate_hz", [250.0, 2000.0])
def test_the_sparse_ode_predicts_held_out_parts_within_1_25x_the_truth_at_two_rates(rate_hz):
    """Every fold of the test above. Measured 2026-11-27 (the contracting truth): 0.276 %
    against the truth's 0.251 % (1.10x) at 250 Hz, 0.249 % against 0.246 % (1.01x) at 2 kHz;
    3.0 s of CPU each."""
    recs = two_periods(rate_hz)
    ref = truth_heldout(recs)
    got = heldout(recs, lambda items: identify(items, True))
    assert 0.2 < ref < 0.3, ref
    assert got <= 1.25 * ref, (got, ref)


def test_decimation_keeps_250_samples_per_period_and_working_records_average_the_noise():
    """5 kHz with a 1 Hz drive: q = 20 (250 samples per period); 200 Hz: q = 1 (left as is).
    The resampled noise RMS is sigma / sqrt(q) within 15 % (independent: the noise's own RMS),
    and a 1 Hz sine passes within 1e-3 of its amplitude away from the ends."""
    rate = 5000.0
    t = np.arange(10_000) / rate
    rng = np.random.default_rng(0)
    v = 150.0 * np.sin(2 * math.pi * t)
    noise = rng.normal(0.0, 1.0, t.size)
    recs = [
        Record.from_arrays("a", rate, v, noise, hold="linear"),
        Record.from_arrays("b", rate, v, v, hold="linear"),
    ]
    q = decimation(recs)
    assert q == 20
    a, b = working_records(recs, q)
    assert a.rate_hz == pytest.approx(250.0) and a.n == 500
    assert np.std(a.strain_ue) == pytest.approx(1.0 / math.sqrt(q), rel=0.15)
    inner = slice(25, -25)
    assert np.max(np.abs(b.strain_ue - 150.0 * np.sin(2 * math.pi * a.time_s))[inner]) < 0.15
    slow = [Record.from_arrays("c", 200.0, v[::25], v[::25], hold="linear")]
    assert decimation(slow) == 1 and working_records(slow, 1)[0] is slow[0]
    # an idle part (0 V held) does not count; a driven one with no drive frequency (a PRBS-like
    # step train, content above any one frequency) keeps the rate
    idle = Record.from_arrays("idle", rate, np.zeros(2000), noise[:2000], hold="linear")
    assert decimation([*recs, idle]) == 20
    steps = np.repeat(rng.choice([-150.0, 150.0], 40), 250)
    prbs = Record.from_arrays("prbs", rate, steps, steps, hold="linear")
    assert decimation([*recs, prbs]) == 1


def test_refinement_recovers_the_truth_from_coefficients_30_percent_off():
    """Output error from a start 30 % off in every coefficient: the refined coefficients are
    the truth's within 3 % (noise 0.05 um on parts of 20-23 um), and the training score (RMS of
    the parts' NRMSE) falls to within 5 % of the noise's own (``NOISE_UM`` over each span)."""
    recs = two_periods(500.0, truth=TRUTH_XI)
    items = [(s.seq, s.segments) for s in scored_sequences(recs, [r.name for r in recs], 0, True)]
    start = SindyBaseline(tuple(1.3 * x for x in TRUTH_XI), 500.0, 0.0)
    model, score = refine(items, start, True)
    kept = np.flatnonzero(TRUTH_XI)
    np.testing.assert_allclose(np.array(model.coefficients)[kept], np.array(TRUTH_XI)[kept], 0.03)
    noise = 100.0 * math.sqrt(np.mean([(NOISE_UM / np.ptp(r.strain_ue)) ** 2 for r in recs]))
    assert score < 1.05 * noise, (score, noise)


def _xi(**terms: float) -> SindyBaseline:
    xi = [0.0] * len(TERMS)
    for k, v in terms.items():
        xi[TERMS.index(k)] = v
    return SindyBaseline(tuple(xi), 1000.0, 0.0)


def test_settles_only_when_a_held_voltage_has_a_stable_rest_strain():
    """The truth (a lag, -0.21 S) settles; a pure gain (0.146 V', no change at a hold) settles;
    a positive lag (runs away) and a pure integrator of V (drifts at any held V != 0) do not;
    a saturating S|S| with no real rest strain at 150 V does not, while the same at 100 V does
    (the roots of 0.0287 S^2 - 1.82 S + 0.205 V exist for V <= 140.7 V)."""
    assert settles(SindyBaseline(TRUTH_XI, 1000.0, 0.0), -150, 150)
    assert settles(_xi(**{"V'": 0.146}), -150, 150)
    assert not settles(_xi(S=0.865, **{"V'": 0.125}), -150, 150)
    assert not settles(_xi(V=0.0482, **{"V'": 0.129}), -150, 150)
    sat = _xi(S=-1.82, V=0.205, **{"S|S|": 0.0287})
    assert settles(sat, -140, 140) and not settles(sat, -141, 141)


def _idle_record(idle_s: float, rate_hz: float = 1000.0) -> Record:
    t = np.arange(round((idle_s + 2.0) * rate_hz)) / rate_hz
    v = np.where(t >= idle_s, 150.0 * np.sin(2 * math.pi * (t - idle_s)), 0.0)
    s = 0.3 * v + np.random.default_rng(1).normal(0, 0.05, t.size)
    return Record.from_arrays("r", rate_hz, v, s, hold="linear")


def test_a_long_idle_start_is_left_out_and_said_a_short_one_kept():
    """Idle for more than half a part (1/8 of the record with 4 parts): left out, every part
    says how long (``idle_lead_s``) and the first starts from rest at the held 0 V; no part is
    idle. Just under the threshold it is kept (parts cover the whole record)."""
    long = _idle_record(7.36)
    parts = split_entries([long], 4)
    assert parts[0].meta["idle_lead_s"] == pytest.approx(7.36, abs=5e-3)
    assert parts[0].rest_V == 0.0 and parts[0].time_s[0] == pytest.approx(7.36, abs=5e-3)
    assert all(np.ptp(p.voltage_V) > 100 for p in parts)
    assert sum(p.n for p in parts) == long.n - idle_lead(long)
    # threshold: the lead (samples before the voltage first moves by 1 % of its 300 V span,
    # 3.2 ms after idle_s) must exceed n / 8 samples: 0.28 s gives 284 of 285, 0.29 s 294 of 286
    for idle_s, trimmed in ((0.28, False), (0.29, True)):
        r = _idle_record(idle_s)
        parts = split_entries([r], 4)
        lead = np.flatnonzero(np.abs(r.voltage_V) > 0.01 * np.ptp(r.voltage_V))[0]
        assert bool(lead > r.n / 8) is trimmed, (lead, r.n / 8)
        assert ("idle_lead_s" in parts[0].meta) is trimmed
        assert sum(p.n for p in parts) == (r.n - lead if trimmed else r.n)


# -- the whole-file stand-in, through diagnose --------------------------------------------------


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_whole_file_standin_at_5khz_whose_truth_grows_gets_a_contracting_ode_that_cannot_follow():
    """SIMULATED stand-in of the whole SmartHysteresis file (10 s at 5 kHz, 7.36 s idle, then
    2.64 periods), as ``labrig import`` + ``diagnose`` read it: the idle start is left out; the
    truth is the record's first ODE, which grows under this drive (+0.55 /s). What diagnose
    returns contracts (it never adopts one that grows), so it cannot follow the truth to the
    noise: at least 5x the truth's own held-out error, while still better than the model by the
    acceptance rule, and then named EMPIRICAL, never "explained". Measured 2026-11-27: fifth
    round, the growing ODE 1.38 % refused for growth (the folds' contracting ODEs 2.7-5.7 % per
    part: their ``|V'|`` read the noise above the identification's band); sixth round, with the
    band limit and the inner-fold choice, a contracting ODE 1.53 % adopted against 4.38 % for
    the model with offset_drift and empirical_terms, the truth's own 0.155 %. 30-60 s of CPU:
    slow tier (the fast equivalents: test_sparse_ode_contraction.py, test_sparse_ode_growth.py,
    tests/analysis/test_band_limit.py)."""
    from labrig.analysis.sindy import SindyBaseline

    rows = standin_rows(1)
    rec = Record.from_arrays("standin", 5000.0, rows[:, 2], rows[:, 1], hold="linear")
    rec.meta["kind"] = "import"
    parts = split_entries([rec], 4)
    assert parts[0].meta["idle_lead_s"] == pytest.approx(drive_on_s(), abs=5e-3)
    truth = heldout(parts, lambda _items: SindyBaseline(TRUTH_XI, 5000.0, 0.0))
    d = diagnose(parts, offset=True)
    ode = next(c for c in d.candidates if c["effect"] == NAME)
    assert ode["heldout_nrmse_pct"] is not None, ode["evidence"]
    assert ode["heldout_nrmse_pct"] >= 5.0 * truth, (ode["heldout_nrmse_pct"], truth)
    assert "grows under" not in ode["evidence"] and "contracts under" in ode["evidence"]
    assert d.classification != "explained"
    if any(e["effect"] == NAME for e in d.effects_added):
        assert "EMPIRICAL alternative base" in d.verdict
