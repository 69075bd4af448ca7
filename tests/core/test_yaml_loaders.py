"""The two YAML loaders of ``labrig/core/yamlio.py``: libyaml's parser (``BoundedLoader`` where
PyYAML has its C extension) and PyYAML's parser in Python (``PythonLoader``, the fallback) read
every YAML file of the repository to the same data and the same line of each key, refuse the
same bad files at the same line, and keep the same bounds."""

from __future__ import annotations

from pathlib import Path

import pytest

from labrig.core import yamlio
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


LOADERS = pytest.mark.parametrize(
    "loader", [BoundedLoader, PythonLoader], ids=["libyaml", "python"]
)


def refusal(text: str, loader) -> tuple[int | None, str]:
    """The line and message of the one issue ``text`` is refused with."""
    with pytest.raises(InputFileError) as e:
        load_text(text, "t.yaml", loader=loader)
    (issue,) = e.value.issues
    return issue.line, issue.message


def chain(inner: int) -> str:
    """``a1`` wraps the anchored ``a0`` (``inner`` lists deep) in 30 more lists: neither is
    nested over 64 levels as written, the expansion is ``1 + 30 + inner`` levels deep."""
    a0 = "a0: &a0 " + "[" * inner + "1" + "]" * inner + "\n"
    return a0 + "a1: " + "[" * 30 + "*a0" + "]" * 30 + "\n"


@LOADERS
@pytest.mark.parametrize("text", ["a: 1\nb: &x [1, *x]\n", "a: 1\nb: &x {c: [*x]}\n"])
def test_an_alias_inside_the_value_it_names_is_a_loop_refused(loader, text: str):
    """Before, the line index recursed through the loop until Python's recursion limit (a
    traceback, exit 1)."""
    line, message = refusal(text, loader)
    assert (line, "a loop" in message) == (2, True), message


@LOADERS
def test_nesting_reached_through_aliases_counts_once_expanded(loader):
    """64 levels once expanded are read, 65 refused, though no part is written deeper than
    34 levels (before, the depth check counted only what was written)."""
    data = load_text(chain(33), "t.yaml", loader=loader)
    assert data["a1"][0] is not None
    line, message = refusal(chain(34), loader)
    assert line is not None and "nested more than 64 levels deep" in message, message


@LOADERS
@pytest.mark.parametrize(
    ("value", "tag"),
    [("abc", "int"), ("_", "int"), ("''", "float"), ("maybe", "bool"), ("never", "timestamp")],
)
def test_a_value_its_tag_cannot_convert_is_refused_at_its_line(loader, value: str, tag: str):
    """``!!bool maybe`` and the like: before, PyYAML's converter's KeyError, IndexError or
    AttributeError came out as a traceback (exit 1)."""
    line, message = refusal(f"a: 1\nb: !!{tag} {value}\nc: 3\n", loader)
    assert (line, message) == (2, f"{value.strip(chr(39))!r} cannot be read as !!{tag}")


@LOADERS
def test_values_are_counted_before_the_document_is_composed(loader, monkeypatch):
    """A document of more values than the bound is refused by counting the parser's events,
    with no alias in it (before: composed in full, ~1 GB and 30 s for 5 MB, then refused as
    an alias expansion). The bound lowered to 1000 to test it just inside and just outside:
    the mapping, its key, the list and its ``n`` items."""
    monkeypatch.setattr(yamlio, "MAX_EXPANDED_NODES", 1000)
    assert len(load_text("a: [" + "1, " * 996 + "1]\n", "t.yaml", loader=loader)["a"]) == 997
    line, message = refusal("a: [" + "1, " * 997 + "1]\n", loader)
    assert (line, message) == (1, "this document has more than 1000 values")


@LOADERS
def test_a_tab_is_named_and_an_error_at_the_end_names_the_last_line(loader):
    line, message = refusal("name: x\nsteps:\n\t- a\n", loader)
    assert (line, "a tab: YAML indents and separates with spaces" in message) == (3, True)
    line, _ = refusal("name: x\nrate_hz: 1000\nsteps: [a, b", loader)
    assert line == 3  # libyaml's mark is on a fourth line the text does not have


@LOADERS
def test_a_lone_surrogate_in_a_text_is_refused(loader):
    with pytest.raises(InputFileError, match=r"t\.yaml"):
        load_text("a: \ud800\n", "t.yaml", loader=loader)
