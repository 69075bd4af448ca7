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
        assert ax.get_ylabel() == "residual (ue)"  # a simulated run's strain
    # an import that kept a sensor's numbers (`--strain-units raw`): its residual is in raw, as
    # the run file's units say (the reader puts them in each record's meta)
    for r in recs:
        r.meta["units"] = {"time": "s", "command_voltage": "V", "strain": "raw"}
    fig = residual_figure(scaled_predictions(recs, 0.9, 1.0), recs)
    assert {ax.get_ylabel() for ax in fig.axes if ax.lines} == {"residual (raw)"}


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


def _pixels(png_bytes: bytes) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png_bytes)))


def test_reused_residual_figure_draws_the_pixels_of_a_new_one() -> None:
    """``ResidualFigures`` (one figure emptied between diagnoses) against a new figure each
    time, pixel for pixel: diagnoses of other scales, lengths and names on the same layout
    (tick counts and labels change), a panel whose y axis needs an offset (its title placed
    by matplotlib: a new figure), then another panel count."""
    from labrig.report.diagnose_html import ResidualFigures
    from labrig.report.plots import png

    def records(n: int, scale: float, shift: float, m: int, tag: str) -> list[Record]:
        t = np.linspace(0, m / 100.0, m)
        return [
            Record.from_arrays(
                f"{tag}{k}", 100.0, t, shift + scale * np.sin(np.arange(m) / (7 + k))
            )
            for k in range(n)
        ]

    cases = [
        (records(2, 1.0, 0.0, 300, "a"), 0.9, 1.0),
        (records(2, 250.0, 0.0, 500, "entry_"), 0.5, 0.95),  # other ticks, labels, names
        (records(2, 2.0, 1e4, 300, "c"), 0.0, 0.0),  # residual 1e4 + small: y offset
        (records(2, 0.01, 0.0, 120, "d"), 0.6, 0.9),
        (records(3, 40.0, 0.0, 200, "e"), 0.7, 0.9),  # another layout
    ]
    figures = ResidualFigures()
    for recs, before, after in cases:
        d = scaled_predictions(recs, before, after)
        reused = _pixels(figures(d, recs))
        fresh = _pixels(png(residual_figure(d, recs)))
        assert reused.shape == fresh.shape
        assert np.array_equal(reused, fresh), recs[0].name
