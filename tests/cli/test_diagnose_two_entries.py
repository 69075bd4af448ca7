"""``labrig diagnose`` of a file of two entries (two records imported together, as the
micromanipulator pair is in docs/analysis.md): leave-one-entry-out needs three, a single entry
is cut into parts; the refusal is exit 2 naming the file, the count and the ways on. A run file
of one entry is diagnosed (cut into parts)."""

from __future__ import annotations

import json
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


#: 500 samples: four parts of one period each
ONE = """\
name: one entry
rate_hz: 500
rest_s: 0.5
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [4]
    cycles: 4
    min_duration_s: 1
"""


def test_one_entry_of_a_run_is_cut_into_parts_and_diagnosed(tmp_path: Path) -> None:
    """A run's single entry (its record's meta holds the step's ``rate_hz``): exit 0, the
    verdict and the four parts' held-out score, no traceback."""
    run = run_protocol(ONE, tmp_path, seed=1)
    res = invoke("diagnose", run, "--json")
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    doc = json.loads(res.stdout)
    assert doc["verdict"] and doc["before"]["heldout_nrmse_pct"] > 0


def _imported(tmp_path: Path, n: int) -> Path:
    """A CSV of ``n`` samples of a 0-100 V sine (from rest) imported at 1 kHz."""
    import numpy as np

    k = np.arange(n)
    v = 50 * (1 - np.cos(2 * np.pi * k / 40))
    csv = tmp_path / f"x{n}.csv"
    rows = "\n".join(
        f"{i / 1000:.6f},{x:.6f},{9 * x + 0.01 * (i % 7):.6f}" for i, x in enumerate(v)
    )
    csv.write_text("time,voltage,strain\n" + rows + "\n")
    out = tmp_path / f"x{n}.h5"
    res = invoke(
        "import", csv, "--out", out, "--voltage", "voltage", "--strain", "strain",
        "--strain-units", "ue",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    return out


def test_a_single_entry_too_short_to_cut_is_refused_naming_it(tmp_path: Path) -> None:
    """It was refused naming a part the file does not hold (``..._part3/data: 12 samples``).
    4 parts of 20 samples: 80 samples are cut (just inside), 79 refused naming the entry."""
    from labrig.commands.prepare import DIAGNOSE_SPLIT, MIN_SAMPLES, prepare_diagnosis
    from labrig.core.errors import InputFileError

    n = DIAGNOSE_SPLIT * MIN_SAMPLES
    setup = prepare_diagnosis(_imported(tmp_path, n), say=lambda _: None)
    assert len(setup.records) == DIAGNOSE_SPLIT
    short = _imported(tmp_path, n - 1)
    res = invoke("diagnose", short, "--json")
    assert res.exit_code == 2, res.output
    said = " ".join(res.output.split())
    assert f"[x{n - 1}/data] {n - 1} samples" in said and "part" in said and "_part" not in said
    try:
        prepare_diagnosis(short, say=lambda _: None)
    except InputFileError:
        pass
    else:
        raise AssertionError("a single entry of 79 samples was cut")
