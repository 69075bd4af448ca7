"""One file, one noise floor: ``labrig fit`` and ``labrig diagnose`` print the same one.

The floor is measured on the model's residual by one estimator
(:mod:`labrig.analysis.noise_floor`); before, ``fit`` printed the simulated bench's configured
noise (0.331 %) and ``diagnose`` the residual's scatter (0.328 %) for one paper campaign. The
tiny run is simulated with a known gauge noise, so the floor is also checked against that truth
(independent reference: tests/reference/noise_ref.py).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.diagnose.evidence import collect_evidence
from labrig.analysis.load import records_from_run
from labrig.analysis.noise_floor import noise_floor
from labrig.analysis.records import Record
from labrig.store import read_run

from helpers import invoke
from reference.noise_ref import configured_noise_ue

FIT_FLOOR = re.compile(r"noise floor \(NRMSE of a perfect model\): ([0-9.eE+-]+) %")
DIAGNOSE_FLOOR = re.compile(r"noise\s+floor\s+\(([0-9.eE+-]+) %\)")


# a whole diagnosis (10-30 s); the fast twin: test_diagnose_evidence_uses_the_one_floor
@pytest.mark.slow
def test_fit_and_diagnose_print_one_floor(tiny_run: Path, tmp_path: Path) -> None:
    fit = invoke("fit", tiny_run, "--no-heldout", "--out", tmp_path / "p.json")
    assert fit.exit_code == 0, fit.stderr
    diag = invoke("diagnose", tiny_run, "--workers", "1", "--max-effects", "1")
    assert diag.exit_code == 0, diag.stderr
    m_fit = FIT_FLOOR.search(fit.stdout)
    m_diag = DIAGNOSE_FLOOR.search(" ".join(diag.stdout.split()))  # rich wraps lines
    assert m_fit and m_diag, (fit.stdout, diag.stdout)
    assert m_fit.group(1) == m_diag.group(1)
    # and both are the truth of the simulated bench: its gauge noise over each entry's span
    records = records_from_run(tiny_run)
    sigma = configured_noise_ue(read_run(tiny_run, load_data=False).instrument)
    assert sigma is not None
    truth = float(np.mean([100 * sigma / np.ptp(r.strain_ue) for r in records]))
    assert float(m_fit.group(1)) == pytest.approx(truth, rel=0.15)


def test_diagnose_evidence_uses_the_one_floor() -> None:
    """The diagnosis' evidence (what ``diagnose`` prints and decides near the floor with) and
    :func:`noise_floor` (what fit, report and validate print) give the same number on three
    entries: a periodic one, a periodic one with a warm-up, and a step record."""
    rng = np.random.default_rng(3)
    rate = 1000.0
    t = np.arange(3000) / rate
    drives = {
        "sine": 50 * (1 - np.cos(2 * np.pi * 5 * t)),
        "fast": 40 * (1 - np.cos(2 * np.pi * 20 * t)),
        "step": np.where(t > 1.0, 80.0, 0.0),
    }
    recs, preds = [], {}
    for name, v in drives.items():
        model = 7.5 * v + 2.0 * np.sin(2 * np.pi * 3 * t)
        recs.append(Record.from_arrays(name, rate, v, 7.5 * v + rng.normal(0, 1.0, t.size)))
        preds[name] = model
    for warmup in (0.0, 0.4):
        ev = collect_evidence(recs, preds, warmup)
        nf = noise_floor(recs, preds, warmup)
        assert nf is not None
        assert nf.nrmse_pct == pytest.approx(ev.floor_pct, rel=1e-12)
