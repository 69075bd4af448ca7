"""The diagnosis report's residual panels: every panel has both axes labelled."""

from __future__ import annotations

import numpy as np

from labrig.analysis.diagnose import Diagnosis
from labrig.analysis.records import Record
from labrig.report.diagnose_html import residual_figure


def test_every_residual_panel_has_axis_labels() -> None:
    recs = [
        Record.from_arrays(f"e{k}", 100.0, np.linspace(0, 10, 300), np.sin(np.arange(300) / 9))
        for k in range(3)
    ]
    d = Diagnosis(
        before={},
        after={},
        effects_added=[],
        candidates=[],
        verdict="",
        classification="unexplained",
        evidence_before=None,  # type: ignore[arg-type]
        evidence_after=None,  # type: ignore[arg-type]
        predictions_before={r.name: 0.9 * r.strain_ue for r in recs},
        predictions_after={r.name: r.strain_ue for r in recs},
    )
    fig = residual_figure(d, recs)
    panels = [ax for ax in fig.axes if ax.lines]
    assert len(panels) == 3
    for ax in panels:
        assert ax.get_xlabel() == "time (s)"
        assert ax.get_ylabel().startswith("residual (")
