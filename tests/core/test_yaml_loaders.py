"""The two YAML loaders of ``labrig/core/yamlio.py``: libyaml's parser (``BoundedLoader`` where
PyYAML has its C extension) and PyYAML's parser in Python (``PythonLoader``, the fallback) read
every YAML file of the repository to the same data and the same line of each key, refuse the
same bad files at the same line, and keep the same bounds."""

from __future__ import annotations

from pathlib import Path

import pytest

from labrig.core.errors import InputFileError
from labrig.core.yamlio import BoundedLoader, PythonLoader, load_text, read_yaml

ROOT = Path(__file__).resolve().parents[2]
#: every YAML file of the repository: the shipped protocols and rigs, and the test data's bad
#: protocols and rigs (syntax errors, tabs, unclosed brackets, duplicate keys, odd numbers)
FILES = sorted(
    p.relative_to(ROOT)
    for folder in ("experiments", "tests/data")
    for p in (ROOT / folder).rglob("*.yaml")
)

pytestmark = pytest.mark.skipif(
    BoundedLoader is PythonLoader, reason="PyYAML without libyaml: one loader only"
)


def outcome(path: Path, loader) -> tuple:
    """``("read", data, lines)`` or ``("refused", line of each issue)``."""
    try:
        data, lines, _ = read_yaml(path, loader=loader)
    except InputFileError as e:
        return ("refused", [i.line for i in e.issues])
    return ("read", data, lines)


def test_the_repository_has_yaml_files_good_and_bad():
    assert len(FILES) > 100
    assert any(str(p).startswith("experiments") for p in FILES)
    assert any("bad" in str(p) for p in FILES)


@pytest.mark.parametrize("name", [str(p) for p in FILES])
def test_both_loaders_read_a_file_alike(name: str):
    want = outcome(ROOT / name, PythonLoader)
    got = outcome(ROOT / name, BoundedLoader)
    assert got == want


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("a: 1\nb: " + "[" * 64 + "]" * 64 + "\n", 2, "nested more than 64"),
        ("a: 1\nb: " + "[" * 2000 + "]" * 2000 + "\n", 2, "nested more than 64"),
        ("a: 1\nb: 2026-13-45\n", 2, "'2026-13-45' is not a date (month must be in 1..12)"),
        ("a: 1\nb: 1:30\n", 2, "'1:30' is a base-60 number"),
        ("a: 1\nb: 017\n", 2, "'017' is an octal number in YAML 1.1 (read as 15)"),
        ("a: 1\nb: " + "9" * 101 + "\n", 2, "a number with 101 digits (at most 100 are read)"),
    ],
)
@pytest.mark.parametrize("loader", [BoundedLoader, PythonLoader], ids=["libyaml", "python"])
def test_both_loaders_refuse_at_the_line(loader, text: str, line: int, message: str):
    """Just outside each bound (65 levels: the mapping and 64 lists), on both parsers; the
    2000 brackets of one line pass libyaml's own nesting limit (1000) before the event count
    reaches 65, and are named alike."""
    with pytest.raises(InputFileError) as e:
        load_text(text, "t.yaml", loader=loader)
    (issue,) = e.value.issues
    assert (issue.line, message in issue.message) == (line, True), issue


@pytest.mark.parametrize("loader", [BoundedLoader, PythonLoader], ids=["libyaml", "python"])
def test_both_loaders_read_just_inside_the_bounds(loader):
    """64 levels of nesting (the mapping and 63 lists), an integer of 100 digits, a real date."""
    text = "a: " + "[" * 63 + "]" * 63 + "\nb: " + "9" * 100 + "\nc: 2026-12-31\n"
    data = load_text(text, "t.yaml", loader=loader)
    assert data["b"] == int("9" * 100)
    assert str(data["c"]) == "2026-12-31"
    depth, x = 0, data["a"]
    while x is not None:
        depth += 1
        x = x[0] if x else None
    assert depth == 63
