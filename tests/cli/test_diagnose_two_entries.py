"""``labrig diagnose`` of a file of two entries (two records imported together, as the
micromanipulator pair is in docs/analysis.md): leave-one-entry-out needs three, a single entry
is cut into parts; the refusal is exit 2 naming the file, the count and the ways on."""

from __future__ import annotations

from pathlib import Path

from helpers import invoke, run_protocol

TWO = """\
name: two entries
rate_hz: 1000
rest_s: 0.5
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [5, 10]
    cycles: 2
    min_duration_s: 0.5
"""


def test_two_entries_are_refused_with_the_ways_on(tmp_path: Path) -> None:
    run = run_protocol(TWO, tmp_path, seed=1)
    res = invoke("diagnose", run, "--out", tmp_path / "d")
    assert res.exit_code == 2, res.output
    said = " ".join(res.output.split())
    assert str(run.name) in said and "found 2" in said
    assert "import each record on its own" in said and "labrig validate" in said
    assert "Traceback" not in res.output and not (tmp_path / "d").exists()
