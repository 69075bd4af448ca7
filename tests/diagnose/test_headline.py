"""The diagnosis' one-line headline, its rounds in the candidates table and its clock.

The headline is read back by parsing its numbers, not by rebuilding the same f-string."""

from __future__ import annotations

import re

import pytest
from rich.console import Console

from labrig.analysis.diagnose.evidence import Evidence
from labrig.analysis.diagnose.verdict import HEADLINE_WORDS, headline
from labrig.cli.diagnose import StepClock, print_diagnosis


def evidence(nrmse: float, floor: float) -> Evidence:
    return Evidence({}, floor, nrmse, nrmse / floor, {}, [])


def score(heldout: float) -> dict:
    return {"nrmse_pct": heldout * 0.9, "heldout_nrmse_pct": heldout, "per_entry": {}}


NUMBER = r"([0-9.]+)"


def test_nothing_added_states_the_ratio_to_the_floor():
    line = headline("unexplained", evidence(0.893, 0.152), evidence(0.893, 0.152),
                    score(0.893), score(0.893), [])  # fmt: skip
    assert line.startswith("Unexplained:") and "nothing added" in line
    ratio = float(re.search(NUMBER + r"x the noise floor", line).group(1))
    assert ratio == pytest.approx(0.893 / 0.152, rel=0.02)
    assert "\n" not in line and len(line.split()) < 30  # one line, not a paragraph


def test_added_effects_give_before_after_and_what_remains():
    line = headline("explained", evidence(0.52, 0.30), evidence(0.31, 0.30),
                    score(0.52), score(0.31), ["creep", "quadratic_term"])  # fmt: skip
    assert line.startswith("Explained: added creep then quadratic_term")
    before, after = map(float, re.search(NUMBER + r" % -> " + NUMBER + " %", line).groups())
    assert (before, after) == (0.52, 0.31)
    assert float(re.search(NUMBER + r"x the noise", line).group(1)) == pytest.approx(1.0, 0.05)


def test_the_ratio_is_the_held_out_figure_over_the_floor():
    """The headline's ratio goes with the held-out NRMSE it prints, not the in-sample one (a
    record whose held-out error is 1.01 % and in-sample 0.965 % over a 0.284 % floor: 3.6x,
    not 3.4x)."""
    after = {"nrmse_pct": 0.965, "heldout_nrmse_pct": 1.01, "per_entry": {}}
    line = headline("partially_explained", evidence(1.18, 0.44), evidence(0.965, 0.284),
                    score(1.46), after, ["sparse_ode"])  # fmt: skip
    assert float(re.search(NUMBER + r"x the noise", line).group(1)) == pytest.approx(
        1.01 / 0.284, abs=0.05
    )
    insample = float(re.search(r"in-sample " + NUMBER + "x", line).group(1))
    assert insample == pytest.approx(0.965 / 0.284, abs=0.05)  # the class's ratio, beside it
    line = headline("unexplained", evidence(1.18, 0.44), evidence(1.18, 0.44),
                    score(1.46), score(1.46), [])  # fmt: skip
    assert float(re.search(NUMBER + r"x the noise", line).group(1)) == pytest.approx(
        1.46 / 0.44, abs=0.05
    )


def test_every_verdict_class_has_words():
    for cls, words in HEADLINE_WORDS.items():
        line = headline(cls, evidence(1, 1), evidence(1, 1), score(1), score(1), [])
        assert line.startswith(words + ":")
    with pytest.raises(KeyError):
        headline("no such class", evidence(1, 1), evidence(1, 1), score(1), score(1), [])


def test_the_table_separates_rounds_and_the_headline_comes_first(capsys):
    doc = {
        "headline": "Explained: added creep; a headline",
        "before": score(0.5), "after": score(0.3), "effects_added": [],
        "candidates": [
            {"effect": "creep", "round": 1, "heldout_nrmse_pct": 0.3, "evidence": "e1"},
            {"effect": "time_delay", "round": 1, "heldout_nrmse_pct": None, "evidence": "e2"},
            {"effect": "quadratic_term", "round": 2, "heldout_nrmse_pct": 0.29, "evidence": "e3"},
        ],
        "verdict": "the paragraph",
    }  # fmt: skip
    print_diagnosis(doc, "x.h5")
    out = capsys.readouterr().out
    assert (
        out.index("Explained: added creep")
        < out.index("diagnose x.h5")
        < out.index("the paragraph")
    )
    lines = out.splitlines()
    names = ("creep", "time_delay", "quadratic_term")
    row = {name: i for i, line in enumerate(lines) for name in names if f" {name} " in line}
    between = lines[row["time_delay"] + 1 : row["quadratic_term"]]
    assert any(set(s.strip()) <= set("├┼─┤") and s.strip() for s in between), (
        "no rule between rounds"
    )
    within = lines[row["creep"] + 1 : row["time_delay"]]
    assert not any(set(s.strip()) <= set("├┼─┤") and s.strip() for s in within)


def test_progress_lines_carry_the_elapsed_time(monkeypatch):
    console = Console(record=True, width=100)
    now = iter([100.0, 112.25])
    monkeypatch.setattr("labrig.cli.diagnose.time.monotonic", lambda: next(now))
    clock = StepClock(console)
    clock("round 1: ranking 9 candidates [x]")
    text = console.export_text()
    assert "[  12.2 s] round 1: ranking 9 candidates [x]" in text or "[  12.3 s]" in text
