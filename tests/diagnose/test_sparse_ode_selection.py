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
from scipy.signal import resample_poly

from labrig.analysis.diagnose.contraction import contraction_margin
from labrig.analysis.diagnose.sparse_ode import (
    INNER_FOLDS,
    decimation,
    driven_items,
    entry_score,
    identify,
    inner_folds,
    inner_score,
    working_records,
)
from labrig.analysis.metrics import second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.analysis.simulate import scored_sequences
from labrig.analysis.sindy import SindyBaseline
from labrig.analysis.split import split_entries
from tests.diagnose.test_sparse_ode import SMART
from tests.diagnose.test_sparse_ode_rates import CONTRACTING_XI, two_periods


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


def _smart(rate: float, v: np.ndarray, s: np.ndarray) -> list[Record]:
    rec = Record.from_arrays("smart", rate, v, s, hold="linear")
    rec.meta["kind"] = "import"
    return split_entries([rec], 4)


def _ode_heldout(recs: list[Record]) -> float:
    """The sparse ODE's held-out NRMSE (%) as the trial scores it with the offset as the only
    nuisance term: each part left out in turn, the ODE identified on the working records of the
    other parts, its free run over the chained record at its own rate."""
    names = [r.name for r in recs]
    scored = scored_sequences(recs, names, 0.0, True)
    work = scored_sequences(working_records(recs, decimation(recs)), names, 0.0, True)
    out = []
    with np.errstate(over="ignore", invalid="ignore"):
        for n in names:
            items = [(s.seq, [g for g in s.segments if g.name != n]) for s in work]
            model = identify(items, True)
            out.append(entry_score(scored, model, n, lambda t, _r: np.ones((t.size, 1)), True)[0])
    return float(np.mean(out))


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_real_record_the_sparse_odes_score_does_not_hinge_on_how_the_record_was_read() -> None:
    """The kept record read at exactly 1000 Hz, at 1000.0000000005542 Hz (what ``labrig import
    --time`` reads from exact 1 ms steps printed with nine digits), resampled to 5 kHz
    (``resample_poly``: the field's file is sampled at 5 kHz), and with its first 1 % of samples
    dropped. Before the inner-fold selection these gave 0.189 %, 1.64 % (one fold's ODE a lag
    of 1/13.6 s at 5.9 %), 2.15 % (the noise above the identification's band read as ``|V'|``)
    and 0.224 %; now each is within the 0.216 % a six-term ODE reached on the field's whole file
    and within 15 % of the others. About 30 s of CPU."""
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
