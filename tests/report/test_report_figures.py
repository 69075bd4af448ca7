"""The report's entry figures drawn on one reused figure are the figures a new figure draws,
pixel for pixel, whatever the entries before them had (warm-up, noise band, final hold with
its inset, an axis offset that moves a title); ``png`` gives matplotlib's own ``savefig``
pixels; ``set_title`` fixes a title only where matplotlib's automatic placement would leave it.

Figures are compared as decoded pixels (Pillow), the reference being matplotlib's drawing of a
new figure: a reused figure that kept anything of a previous entry (a line, a limit, a title
position, an inset) changes pixels."""

from __future__ import annotations

import io

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

import labrig.report.plots as plots
from labrig.analysis.records import Record
from labrig.report.data import EntryView


def pixels(png: bytes) -> np.ndarray:
    with Image.open(io.BytesIO(png)) as im:
        return np.asarray(im.convert("RGBA"))


def entry(name: str, *, hold_s: float = 0.0, base_ue: float = 0.0, f_hz: float = 2.0) -> tuple:
    """A sine entry at 200 Hz (3 s), optionally ending with ``hold_s`` at 0 V, its strain
    ``base_ue`` + a loop; the prediction a slightly different loop."""
    rate = 200.0
    t = np.arange(int(3 * rate)) / rate
    v = 50.0 * (1 - np.cos(2 * np.pi * f_hz * t))
    if hold_s:
        v = np.concatenate([v, np.zeros(int(hold_s * rate))])
    s = base_ue + 0.9 * v + 3.0 * np.sin(np.linspace(0, 9, v.size))
    p = base_ue + 0.88 * v + 2.0 * np.sin(np.linspace(0, 9, v.size)) + 0.2
    rec = Record.from_arrays(name, rate, v, s)
    return EntryView(rec, f_hz, 50.0, True, "sine"), p


#: a unit long enough for the inset's title to reach its axis' offset text
WIDE_UNIT = "microstrain, bridge-corrected, gauge 2 of 2"
CASES = [
    # (entry, warm-up s, noise ue, others, strain unit)
    (entry("plain"), 0.0, None, None, "ue"),
    (entry("warmup_noise", f_hz=3.0), 0.5, 0.8, None, "ue"),
    (entry("hold", hold_s=1.5), 0.0, 0.5, {"PI": None, "BW": None}, "ue"),
    (entry("offset_axis", base_ue=1e4), 0.0, None, None, "ue"),  # 1e4 + a few ue: an offset
    (entry("after_offset"), 0.25, None, None, "ue"),
    (entry("hold_again", hold_s=2.0, f_hz=1.0), 0.0, None, {"PI": None}, "ue"),
    (entry("no_hold_after_hold"), 0.0, 0.3, None, "ue"),
    # the inset's title lifted over its offset text by matplotlib, after fixed titles
    (entry("hold_offset", hold_s=1.5, base_ue=1e4), 0.0, None, {"PI": None}, WIDE_UNIT),
    (entry("plain_again"), 0.0, None, None, "ue"),
]


def call_args(case: tuple) -> tuple:
    (view, p), warm, noise, others, unit = case
    if others is not None:
        others = {k: p + 5.0 * (i + 1) for i, k in enumerate(others)}
    return view, p, warm, noise, unit, others


@pytest.fixture(scope="module")
def reused_pixels() -> list[np.ndarray]:
    """The pixels of :data:`CASES` drawn in order on one reused figure (read by two tests)."""
    reused = plots.EntryFigures()
    return [pixels(reused(*call_args(case))) for case in CASES]


def test_reused_entry_figure_is_a_new_figure_pixel_for_pixel(reused_pixels) -> None:
    for case, a in zip(CASES, reused_pixels, strict=True):
        args = call_args(case)
        b = pixels(plots.entry_figure(*args))
        assert a.shape == b.shape
        assert np.array_equal(a, b), (args[0].name, int(np.sum(np.any(a != b, axis=-1))))


def test_reused_entry_figure_differs_when_entries_differ(reused_pixels) -> None:
    """The comparison above can fail: two different entries, the first two drawn on the
    reused figure, do not draw the same pixels."""
    a, b = reused_pixels[0], reused_pixels[1]
    assert a.shape == b.shape and not np.array_equal(a, b)


def test_png_is_savefig_pixels() -> None:
    """``png`` (one draw, Pillow) against matplotlib's ``savefig`` at the same dpi."""
    fig = Figure(figsize=(4.0, 3.0))
    ax = fig.add_subplot()
    ax.plot([0, 1, 2], [0, 1, 0.5], color="tab:red", lw=1.3)
    ax.set_title("t")
    ours = plots.png(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=plots.DPI)
    assert ours.startswith(b"\x89PNG\r\n\x1a\n")
    assert pixels(ours).shape == (300, 400, 4)
    assert np.array_equal(pixels(ours), pixels(buf.getvalue()))


def line_figure(ys: list[float], label: str) -> Figure:
    fig = Figure(figsize=(4.0, 3.0))
    ax = fig.add_subplot()
    ax.plot(range(len(ys)), ys, color="tab:red", lw=1.3)
    ax.set_xlabel(label)
    ax.set_title(label)
    return fig


def test_png_of_a_figure_drawn_again_is_a_new_figures_pixels() -> None:
    """``png`` of a figure drawn before (as :class:`~labrig.report.plots.EntryFigures` draws
    its figure entry after entry): after the line, the limits and the texts changed, the
    pixels of a new figure drawn once with the new content, as ``savefig`` writes them, and
    not those of the first drawing."""
    fig = line_figure([0.0, 1.0, 0.5], "first label")
    first = pixels(plots.png(fig))
    ax = fig.axes[0]
    ax.lines[0].set_data(range(4), [3.0, -2.0, 250.0, 1.0])
    ax.relim()
    ax.autoscale_view()
    ax.set_xlabel("a second, longer label")
    ax.set_title("a second, longer label")
    again = pixels(plots.png(fig))
    new = line_figure([3.0, -2.0, 250.0, 1.0], "a second, longer label")
    buf = io.BytesIO()
    new.savefig(buf, format="png", dpi=plots.DPI)
    assert np.array_equal(again, pixels(plots.png(new)))
    assert np.array_equal(again, pixels(buf.getvalue()))
    assert not np.array_equal(again, first)


def titled(lo: float, hi: float, title: str, how: str) -> tuple[bytes, Figure]:
    """A line from ``lo`` to ``hi`` titled with ``set_title`` (``how="ours"``), matplotlib's
    ``Axes.set_title`` (``"auto"``) or a title fixed at the top (``"top"``)."""
    fig = Figure(figsize=(4.0, 3.0))
    ax = fig.add_subplot()
    ax.plot([0, 1], [lo, hi])
    if how == "ours":
        plots.set_title(ax, title, fontsize=9)
    else:
        ax.set_title(title, fontsize=9, y=1.0 if how == "top" else None)
    return plots.png(fig), fig


#: wide enough to reach the y axis' offset text at the top left
LONG = "a title as wide as the axes, over the offset text"


@pytest.mark.parametrize(("lo", "hi", "fixed"), [(0.0, 50.0, True), (1e4, 1e4 + 5.0, False)])
def test_set_title_places_titles_as_matplotlib(lo: float, hi: float, fixed: bool) -> None:
    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([0, 1], [lo, hi])
    assert plots.set_title(ax, "t") is fixed
    ours, _ = titled(lo, hi, LONG, "ours")
    auto, fig = titled(lo, hi, LONG, "auto")
    assert np.array_equal(pixels(ours), pixels(auto))
    ax = fig.axes[0]
    assert bool(ax.yaxis.get_offset_text().get_text()) is not fixed  # drawn as predicted
    if not fixed:  # matplotlib lifted the title over the offset text: fixing it would differ
        assert ax.title.get_position()[1] > 1.0
        assert not np.array_equal(pixels(titled(lo, hi, LONG, "top")[0]), pixels(auto))
