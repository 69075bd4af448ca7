"""docs/python-api.md's notebook session runs as written: every fenced ``python`` block is
executed in order, in one namespace, in an empty folder (the xarray block only where xarray is
installed: it is optional)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import matplotlib
import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "python-api.md"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)


def python_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def test_the_block_finder_finds_blocks():
    text = "a\n```python\nx = 1\n```\n```\nnot python\n```\n```python\ny = 2\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = 2\n"]


@pytest.mark.timeout(120)
def test_the_notebook_session_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    blocks = python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) >= 8
    has_xarray = importlib.util.find_spec("xarray") is not None
    namespace: dict = {"__name__": "__notebook__"}
    for i, code in enumerate(blocks):
        if "to_xarray" in code and not has_xarray:
            continue
        exec(compile(code, f"{DOC.name} block {i + 1}", "exec"), namespace)
    assert (tmp_path / "runs" / "short.h5").is_file()
    assert (tmp_path / "loops.png").stat().st_size > 1000
    assert "<html" in (tmp_path / "short.html").read_text(encoding="utf-8")[:500].lower()
    assert namespace["run"].status == "complete"
    assert list(namespace["table"]["path"]) == [str(Path("runs") / "short.h5")]
