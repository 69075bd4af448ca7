"""The paper's section-2 figures: files written, valid PNGs, and a layout with fixed margins
that cuts nothing off and overlaps nothing (their cost is a benchmark's business, not a timed
test's)."""

from __future__ import annotations

import itertools
import struct
from pathlib import Path

import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

from labrig.report import model_figures
from labrig.report.model_figures import write_model_figures

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
EXPECTED = {
    "fig1_hysteresis_loop.png",
    "fig3_frequency_response.png",
    "fig4_input_output.png",
    "fig5_step_response.png",
}


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path], list[Figure]]:
    """The figures written (into a folder that must be created), and the Figure objects drawn
    for them (kept on their way to the file)."""
    out = tmp_path_factory.mktemp("figs") / "nested" / "dir"
    figures: list[Figure] = []
    save = model_figures._save

    def keep(fig: Figure, path: Path) -> Path:
        figures.append(fig)
        return save(fig, path)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(model_figures, "_save", keep)
        paths = write_model_figures(out)
    return out, paths, figures


def test_writes_expected_files(written) -> None:
    out, paths, _ = written
    assert {p.name for p in paths} == EXPECTED
    assert len(paths) == len(EXPECTED)
    assert all(p.parent == out for p in paths)
    assert {p.name for p in out.iterdir()} == EXPECTED


def test_each_file_is_a_valid_png(written) -> None:
    for p in written[1]:
        data = p.read_bytes()
        assert len(data) > 10_000, p  # a real plot, not an empty canvas
        assert data[:8] == PNG_MAGIC, p
        # first chunk is IHDR with a plausible size
        length, kind = struct.unpack(">I4s", data[8:16])
        assert (length, kind) == (13, b"IHDR"), p
        width, height = struct.unpack(">II", data[16:24])
        assert 400 <= width <= 3000 and 300 <= height <= 3000, (p, width, height)
        assert data[-12:] == b"\x00\x00\x00\x00IEND\xaeB`\x82", p


def test_nothing_is_cut_off_and_nothing_overlaps(written) -> None:
    """Each panel with its tick labels, axis labels, title and legend lies inside its figure
    (to a pixel), no two panels touch, and the figure's title touches no panel: what the
    fixed margins (instead of a constrained layout) must keep."""
    figures = written[2]
    assert len(figures) == len(EXPECTED)
    for fig in figures:
        renderer = fig.canvas.get_renderer()
        w, h = fig.bbox.width, fig.bbox.height
        boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]
        assert len(boxes) >= 2
        for b in boxes:
            assert b.x0 >= -1 and b.y0 >= -1 and b.x1 <= w + 1 and b.y1 <= h + 1, b
        for a, b in itertools.combinations(boxes, 2):
            assert not a.overlaps(b), (a, b)
        (title,) = [
            t
            for t in fig.get_children()
            if isinstance(t, Text) and t.get_text() == fig.get_suptitle()
        ]
        top = title.get_window_extent(renderer)
        assert top.y1 <= h and not any(top.overlaps(b) for b in boxes), top
