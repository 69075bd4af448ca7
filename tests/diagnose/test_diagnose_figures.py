"""The diagnosis report's residual panels: every panel has both axes labelled."""

from __future__ import annotations

import numpy as np

from labrig.analysis.diagnose import Diagnosis
from labrig.analysis.records import Record
from labrig.report.diagnose_html import residual_figure


def scaled_predictions(recs: list[Record], before: float, after: float) -> Diagnosis:
    """A diagnosis whose predictions before and after are the records' strain times ``before``
    and ``after`` (what the residual figure draws; nothing else filled in)."""
    return Diagnosis(
        before={},
        after={},
        effects_added=[],
        candidates=[],
        verdict="",
        classification="unexplained",
        evidence_before=None,  # type: ignore[arg-type]
        evidence_after=None,  # type: ignore[arg-type]
        predictions_before={r.name: before * r.strain_ue for r in recs},
        predictions_after={r.name: after * r.strain_ue for r in recs},
    )


def test_every_residual_panel_has_axis_labels() -> None:
    recs = [
        Record.from_arrays(f"e{k}", 100.0, np.linspace(0, 10, 300), np.sin(np.arange(300) / 9))
        for k in range(3)
    ]
    fig = residual_figure(scaled_predictions(recs, 0.9, 1.0), recs)
    panels = [ax for ax in fig.axes if ax.lines]
    assert len(panels) == 3
    for ax in panels:
        assert ax.get_xlabel() == "time (s)"
        assert ax.get_ylabel().startswith("residual (")


def test_residual_panels_fit_the_figure_without_overlapping() -> None:
    """The fixed margins (no tight layout) leave room for every panel's tick labels, axis labels
    and title: each panel's drawn extent lies inside the figure and no two panels' extents
    overlap, for 1, 2 and 5 panels and wide tick labels (strain in the tens of thousands)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    for n in (1, 2, 5):
        recs = [
            Record.from_arrays(
                f"entry_{k}_with_a_long_name",
                100.0,
                np.linspace(0, 10, 300),
                -25000.0 * np.sin(np.arange(300) / 9),
            )
            for k in range(n)
        ]
        fig = residual_figure(scaled_predictions(recs, 0.5, 0.9), recs)
        renderer = FigureCanvasAgg(fig).get_renderer()
        boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]
        page = fig.bbox
        for b in boxes:
            assert b.x0 >= page.x0 and b.y0 >= page.y0, (n, b)
            assert b.x1 <= page.x1 and b.y1 <= page.y1, (n, b)
        for i, a in enumerate(boxes):
            for b in boxes[i + 1 :]:
                assert not a.overlaps(b), (n, a, b)
