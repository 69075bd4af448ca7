"""How the sparse ODE's identification chooses among the contracting candidates
(:func:`~labrig.analysis.diagnose.sparse_ode.identify`: the best of each number of terms,
judged by :func:`~labrig.analysis.diagnose.sparse_ode.inner_score`, leave-segments-out inside
the training parts, the median over groups, the sparsest within 5 %).

Fast tier: the inner folds' grouping; the inner score of the truth against the truth's own
held-out error (the sensor noise alone, an independent reference).
``@pytest.mark.slow``: the kept SmartHysteresis record read in the ways an independent review
found the former selection fragile (its rate to the last digits, resampled to 5 kHz, its first
1 % dropped): the held-out score of the sparse ODE in every case within 0.216 % and within 15 %
of the others.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from labrig.analysis.diagnose.acceptance import MIN_GAIN
from labrig.analysis.diagnose.contraction import contraction_margin
from labrig.analysis.diagnose.sparse_ode import (
    INNER_FOLDS,
    cross_validate,
    driven_items,
    inner_folds,
    inner_score,
    offset_columns,
    sparse_ode_trial,
)
from labrig.analysis.metrics import second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import scored_sequences
from labrig.analysis.sindy import LIBRARY, SindyBaseline
from labrig.analysis.split import split_entries
from tests.diagnose.test_sparse_ode import SMART
from tests.diagnose.test_sparse_ode_rates import CONTRACTING_XI, truth_heldout, two_periods


def _segs(names: list[str]) -> list:
    return [(SimpleNamespace(), [SimpleNamespace(name=n) for n in names])]


def test_inner_folds_are_at_most_four_groups_of_consecutive_segments() -> None:
    names = [f"p{k}" for k in range(10)]
    groups = inner_folds(_segs(names))
    assert len(groups) == INNER_FOLDS == 4
    assert [g for grp in groups for g in grp] == names  # every segment once, in order
    assert sorted(len(g) for g in groups) == [2, 2, 3, 3]
    assert inner_folds(_segs(["a", "b", "c"])) == [["a"], ["b"], ["c"]]
    assert inner_folds(_segs(["a"])) == [["a"]]


def _training(rate_hz: float = 250.0, leave_out: int = 0) -> list:
    recs = two_periods(rate_hz)
    names = [r.name for r in recs]
    scored = scored_sequences(recs, names, 0.0, True)
    items = [(s.seq, [g for g in s.segments if g.name != names[leave_out]]) for s in scored]
    return driven_items(items)


def test_the_truths_inner_score_is_the_noise() -> None:
    """The contracting Duhem-form truth of the rate tests, on three of the four parts of its
    noisy two periods (the first left out, as in the first outer fold): refitted without each
    inner group and scored on it, its median inner score is within 1.3x of what the truth
    itself scores on those parts' second halves (offset fitted on the first halves): the noise
    alone (about 0.24 %)."""
    train = _training()
    truth = SindyBaseline(CONTRACTING_XI, 250.0, 0.0)
    groups = inner_folds(train)
    got = inner_score(train, truth, groups, True, contraction_margin(train))
    seq, segs = train[0]
    y = truth.predict(seq.voltage_V, seq.rest_V, seq.rate_hz)
    ref = float(
        np.median([second_half_nrmse_pct(g.measured_ue, y[g.lo : g.hi], True) for g in segs])
    )
    assert 0.15 < ref < 0.35, ref
    assert got <= 1.3 * ref, (got, ref)


def test_each_start_is_refined_once_and_a_refit_repeats_itself(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The threshold paths from the best and from the picked candidate propose some starts
    again (on these two periods, one of 20): :func:`~labrig.analysis.diagnose.sparse_ode.identify`
    refines each start once. That changes nothing because the output-error refinement is a
    function of its start: refined twice, a start gives the same coefficients and score, bit
    for bit (checked here on the first start and on the one that was proposed twice)."""
    import labrig.analysis.diagnose.sparse_ode as so

    train = _training()
    starts: list[SindyBaseline] = []
    refine = so.refine

    def counted(items, model, offset):  # type: ignore[no-untyped-def]
        starts.append(model)
        return refine(items, model, offset)

    monkeypatch.setattr(so, "refine", counted)
    so.identify(train, True)
    keys = [(m.coefficients, m.limit_ue) for m in starts]
    assert keys and len(keys) == len(set(keys)), keys
    for m in (starts[0], starts[-1]):
        (a, sa), (b, sb) = refine(train, m, True), refine(train, m, True)
        assert a.coefficients == b.coefficients and sa == sb


def _smart(rate: float, v: np.ndarray, s: np.ndarray) -> list[Record]:
    rec = Record.from_arrays("smart", rate, v, s, hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def _ode_heldout(recs: list[Record]) -> float:
    """The sparse ODE's mean held-out NRMSE (%) with the offset as the only nuisance term."""
    cv = cross_validate(recs, [r.name for r in recs], 0.0, True, True)
    return float(np.mean(list(cv.heldout.values())))


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_real_record_the_sparse_odes_score_does_not_hinge_on_how_the_record_was_read() -> None:
    """The kept record read at exactly 1000 Hz, at 1000.0000000005542 Hz (what ``labrig import
    --time`` reads from exact 1 ms steps printed with nine digits), resampled to 5 kHz
    (``resample_poly``: the field's file is sampled at 5 kHz), and with its first 1 % of samples
    dropped. Before the inner-fold selection these gave 0.189 %, 1.64 % (one fold's ODE a lag
    of 1/13.6 s at 5.9 %), 2.15 % (the noise above the identification's band read as ``|V'|``)
    and 0.224 %; now each is within the 0.216 % a six-term ODE reached on the field's whole file
    and within 15 % of the others; on two processes the numbers are the same. About 40 s of
    CPU."""
    from scipy.signal import resample_poly  # here: importing it costs every worker ~0.6 s

    rows = np.loadtxt(SMART, delimiter=",", usecols=(1, 2, 3))
    t, s, v = rows[:, 0], rows[:, 1], rows[:, 2]
    k = t.size // 100
    cases = {
        "1000 Hz": _smart(1000.0, v, s),
        "1000.0000000005542 Hz": _smart(1000.0000000005542, v, s),
        "5 kHz": _smart(
            5000.0, resample_poly(v, 5, 1, padtype="line"), resample_poly(s, 5, 1, padtype="line")
        ),
        "first 1 % dropped": _smart(1000.0, v[k:], s[k:]),
    }
    got = {name: _ode_heldout(recs) for name, recs in cases.items()}
    assert max(got.values()) <= 0.216, got
    assert max(got.values()) <= 1.15 * min(got.values()), got
    # the five identifications on two processes: the same numbers
    recs = cases["1000 Hz"]
    two = cross_validate(recs, [r.name for r in recs], 0.0, True, True, workers=2)
    assert float(np.mean(list(two.heldout.values()))) == got["1000 Hz"]


def test_the_trial_adopts_the_contracting_ode_of_a_contracting_truth() -> None:
    """``sparse_ode_trial`` end to end on the contracting Duhem-form truth's two noisy periods
    at 250 Hz, against a stand-in current model whose held-out error is 1 % in every part: the
    ODE is cross-validated, predicts the parts within 1.25x of the truth's own held-out error,
    passes the acceptance rule, and its evidence says it contracts (with the drive range when
    its lag alone holds it back). About 4 s of CPU."""
    recs = two_periods(250.0)
    names = [r.name for r in recs]
    current = SimpleNamespace(
        heldout={n: 1.0 for n in names},
        heldout_pct=1.0,
        effects=[],
        problem=SimpleNamespace(nuisance_columns=offset_columns),
        evidence=SimpleNamespace(floor_pct=0.2),
        fit=SimpleNamespace(nrmse_pct=1.0),
    )
    setup = SimpleNamespace(records=tuple(recs), span_s=sum(r.duration_s for r in recs))
    settings = SimpleNamespace(warmup_s=0.0, chain=True, offset=True, workers=1, min_gain=MIN_GAIN)
    trial = sparse_ode_trial(setup, settings, current, 0, lambda _m: None)
    assert trial.heldout_pct <= 1.25 * truth_heldout(recs), trial.heldout_pct
    assert trial.candidate.accepted, trial.candidate.evidence
    assert "contracts under the records' own drive" in trial.candidate.evidence
    assert "grows under" not in trial.candidate.evidence


def test_the_verdictsdrive_range_names_what_holds_the_ode_back() -> None:
    """A lag that outweighs a positive ``|V'| S`` term below some drive rate: the words give
    that rate (``-xi_S / xi_{|V'|S}`` = 0.797 / 0.00117 = 681 V/s) and its ratio to the records'
    about 600 V/s; a non-negative lag with the same ``|V'| S`` grows under any drive, and what holds
    it back is its ``S|S|`` term, which the words then say instead of a rate of 0 V/s; a
    non-negative lag with a negative ``|V'| S`` is held back by fast drives only (above
    ``xi_S / |xi_{|V'|S}|`` = 100 V/s), and a negative lag with a non-positive ``|V'| S`` by
    any drive (no words)."""
    from labrig.analysis.diagnose.sparse_ode import drive_range

    v = 150.0 * np.sin(2 * np.pi * np.arange(1000) / 1000.0)  # mean |V'| 600 V/s
    items = [
        (
            SimpleNamespace(voltage_V=v, rest_V=0.0, rate_hz=1000.0),
            [SimpleNamespace(lo=0, hi=v.size, name="a")],
        )
    ]
    names = [t.name for t in LIBRARY]

    def model(**terms: float) -> SindyBaseline:
        xi = np.zeros(len(names))
        for k, x in terms.items():
            xi[names.index(k)] = x
        return SindyBaseline(tuple(xi), 1000.0, 0.0)

    lag = drive_range(model(S=-0.797, **{"|V'| S": 0.00117}), items)
    assert "stays below 681 V/s" in lag and "1.14x the records'" in lag, lag
    sat = drive_range(model(S=0.05, **{"|V'| S": 0.00117, "S|S|": -0.01}), items)
    assert "S|S| term" in sat and "0 V/s" not in sat, sat
    # a non-negative lag with a negative |V'| S: held back by fast drives, not slow ones
    fast = drive_range(model(S=0.2, **{"|V'| S": -0.002, "S|S|": -0.001}), items)
    assert "stays above 100 V/s" in fast and "slower drives" in fast, fast
    assert drive_range(model(S=-0.5, **{"|V'| S": -0.001}), items) == ""  # any drive
    # no lag term at all: said in words, not as a threshold of 0 V/s ("0x the records' ...")
    moving = drive_range(model(**{"|V'| S": -0.002, "S|S|": -0.001}), items)
    assert "while the drive moves" in moving and "0 V/s" not in moving, moving
    assert "0x" not in moving and "S|S| term" in moving, moving


def test_one_entry_cannot_be_cross_validated_and_says_so() -> None:
    recs = two_periods(250.0)[:1]
    with pytest.raises(ValueError, match="at least two entries"):
        cross_validate(recs, [recs[0].name], 0.0, True, True)
