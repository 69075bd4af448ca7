"""The corpus of bad protocol files: each is refused with InputFileError at a known file:line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from labrig.core.errors import InputFileError
from labrig.protocol.check import check_protocol

BAD = Path(__file__).parents[1] / "data" / "bad"
EXPECTED: dict = yaml.safe_load((BAD / "EXPECTED.yaml").read_text())


def test_corpus_is_complete():
    files = {p.name for p in BAD.glob("*.yaml")} - {"EXPECTED.yaml"}
    assert files == set(EXPECTED), "every bad file needs an EXPECTED.yaml entry and back"
    assert len(files) >= 30


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_protocol_is_refused_at_its_line(name):
    exp = EXPECTED[name]
    path = BAD / name
    with pytest.raises(InputFileError) as e:
        check_protocol(path)
    err = e.value
    assert err.exit_code == 2
    assert all(i.file == str(path) for i in err.issues)
    hits = [
        i
        for i in err.issues
        if i.line == exp["line"]
        and exp["field"] in i.field
        and exp["message"].lower() in i.message.lower()
    ]
    assert hits, f"expected line {exp['line']} [{exp['field']}] ~{exp['message']!r}, got:\n{err}"
    # the printed form names file:line, as the CLI shows it
    assert f"{path}:{exp['line']}:" in str(err)
