"""A candidate whose fit breaks down numerically (a filter designed from parameters driven to
NaN raised ``LinAlgError`` out of ``labrig diagnose`` on a resonant stack) is refused with the
reason; the diagnosis goes on and still names the effect that is there."""

from __future__ import annotations

import numpy as np
import pytest

import labrig.analysis.diagnose.trial as trial
from labrig.analysis.diagnose import diagnose
from labrig.studies.campaign import study_campaign


def test_a_candidate_whose_fit_fails_is_refused_and_the_diagnosis_goes_on(monkeypatch):
    real_refit = trial.refit
    broken = []

    def refit(setup, settings, current, prob, eff, probe, score=1.0):
        if eff.name != "mains_pickup":
            broken.append(eff.name)
            raise np.linalg.LinAlgError("Matrix is singular.")
        return real_refit(setup, settings, current, prob, eff, probe, score)

    monkeypatch.setattr(trial, "refit", refit)
    d = diagnose(study_campaign("mains_pickup", 11), workers=1)
    doc = d.to_json()
    assert broken, "no other candidate was refitted: the test tests nothing"
    assert [e["effect"] for e in doc["effects_added"]] == ["mains_pickup"]
    failed = [c for cands in d.rounds for c in cands if "could not be fitted" in c.evidence]
    assert {c.effect for c in failed} == set(broken)  # each refit that broke, said
    assert all(any("LinAlgError" in r for r in c.reasons) for c in failed)
    assert not any(c.accepted or c.tried for c in failed)


def test_other_errors_are_not_swallowed(monkeypatch):
    """Only numerical breakdowns are a candidate's refusal; a programming error still stops
    the diagnosis (exit 1 with its traceback, for a bug report)."""

    def refit(*args, **kwargs):
        raise KeyError("a bug")

    monkeypatch.setattr(trial, "refit", refit)
    with pytest.raises(KeyError):
        diagnose(study_campaign("mains_pickup", 11), workers=1)
