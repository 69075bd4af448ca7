"""The paper's section-2 figures: files written, valid PNGs (their cost is a benchmark's
business, not a timed test's)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from labrig.report.model_figures import write_model_figures

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
EXPECTED = {
    "fig1_hysteresis_loop.png",
    "fig3_frequency_response.png",
    "fig4_input_output.png",
    "fig5_step_response.png",
}


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path]]:
    out = tmp_path_factory.mktemp("figs") / "nested" / "dir"  # must be created
    return out, write_model_figures(out)


def test_writes_expected_files(written: tuple[Path, list[Path]]) -> None:
    out, paths = written
    assert {p.name for p in paths} == EXPECTED
    assert len(paths) == len(EXPECTED)
    assert all(p.parent == out for p in paths)
    assert {p.name for p in out.iterdir()} == EXPECTED


def test_each_file_is_a_valid_png(written: tuple[Path, list[Path]]) -> None:
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
