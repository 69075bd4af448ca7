"""The verdict's sentences about rivals of the first effect added (labrig.analysis.diagnose.
verdict), on candidates made by hand: an effect that was added too is never named as one that
"fits almost as well" (both are kept; the trial's 40 Hz run said so of offset_drift, added in
the next round), while a rival that was not added still is."""

from __future__ import annotations

from types import SimpleNamespace

from labrig.analysis.diagnose.verdict import verdict
from labrig.model.effects.registry import library


def candidate(effect: str, rnd: int, heldout: float, gain: float) -> SimpleNamespace:
    params = {"delay_s": 1.73e-3} if effect == "time_delay" else {}
    fit = SimpleNamespace(effects={effect: params}, sd={effect: {}})
    return SimpleNamespace(
        effect=effect, round=rnd, heldout_nrmse_pct=heldout, gain=gain, fit=fit, suspicious=[]
    )


def sentence(second_added: bool) -> str:
    lib = library()
    first = candidate("time_delay", 1, 0.617, 0.72)
    rival = candidate("offset_drift", 1, 0.897, 0.60)  # within the 25 % margin of 0.72
    later = candidate("offset_drift", 2, 0.242, 0.61)
    evidence = SimpleNamespace(ratio=1.1, floor_pct=0.222)
    before = {"heldout_nrmse_pct": 2.24, "nrmse_pct": 2.29}
    after = {"heldout_nrmse_pct": 0.242 if second_added else 0.617, "nrmse_pct": 0.28}
    added = [first, later] if second_added else [first]
    rounds = [[], [first, rival], [later]]
    return verdict(evidence, evidence, before, after, added, rounds, lib)[1]


def test_an_effect_added_too_is_not_a_rival_that_fits_almost_as_well():
    assert "offset_drift fits almost as well" not in sentence(second_added=True)


def test_a_rival_not_added_is_named():
    assert "offset_drift fits almost as well (held-out 0.897 %" in sentence(second_added=False)
