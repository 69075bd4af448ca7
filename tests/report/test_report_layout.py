"""The report's summary figure on fixed margins (no constrained layout): both panels with their
tick labels, axis labels and titles, and the legend of models and amplitudes, lie inside the
figure and do not overlap, with the longest labels the report uses and wide tick labels."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import labrig.report.plots as plots
from labrig.analysis.records import Record
from labrig.report.data import EntryView


def entries(scale: float) -> list[EntryView]:
    out = []
    for amp in (25.0, 50.0, 100.0, 120.0):
        for f in (1.0, 5.0, 10.0, 40.0):
            r = Record.from_arrays(f"sine_{amp:g}V_{f:g}Hz", 1000.0, np.zeros(10), np.zeros(10))
            metrics = {
                "measured": {"loop_area_Vue": scale * amp * f, "strain_shift_ue": -scale * f},
            }
            for k in ("dynamic", "prandtl_ishlinskii", "bouc_wen", "sindy"):
                metrics[k] = {
                    "loop_area_pred_Vue": 1.1 * scale * amp * f,
                    "strain_shift_pred_ue": -1.2 * scale * f,
                }
            out.append(EntryView(r, f, amp, True, "sine", metrics))
    return out


@pytest.mark.parametrize("scale", [1.0, 1e4])
def test_frequency_figure_fits_without_overlap(monkeypatch, scale: float) -> None:
    figs = []
    monkeypatch.setattr(plots, "png", lambda fig: figs.append(fig) or b"")
    plots.frequency_figure(
        entries(scale), ["dynamic", "prandtl_ishlinskii", "bouc_wen", "sindy"], "ue"
    )
    (fig,) = figs
    renderer = FigureCanvasAgg(fig).get_renderer()
    boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]
    boxes += [leg.get_window_extent(renderer) for leg in fig.legends]
    assert len(boxes) == 3
    page = fig.bbox
    for b in boxes:
        assert page.x0 <= b.x0 and b.x1 <= page.x1 and page.y0 <= b.y0 and b.y1 <= page.y1, b
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            assert not a.overlaps(b), (a, b)
