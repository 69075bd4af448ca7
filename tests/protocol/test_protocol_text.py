"""A protocol's name and description are printable text (they are printed on terminals and
pages): control and format characters are refused with their line; line breaks and tabs are
allowed in a description, not in a name (one line of a listing)."""

from __future__ import annotations

import pytest

from labrig.core.errors import InputFileError
from labrig.protocol.check import check_protocol
from labrig.rig.rigspec import DEFAULT_RIG_YAML
from labrig.runner.rigfile import load_rig

HOLD = "rate_hz: 500\nsteps:\n  - {kind: hold, voltage_V: 5, duration_s: 0.1}\n"


@pytest.mark.parametrize(
    ("head", "field", "shown"),
    [
        ('name: "a \\x07 bell"\n', "name", "'\\x07'"),
        ('name: "a \\u202e override"\n', "name", "'\\u202e'"),
        ('name: ok\ndescription: "an \\x1b[31m escape"\n', "description", "'\\x1b'"),
        # a name is one line of a listing: no line break or tab in it
        ('name: "line1\\nline2"\n', "name", "'\\n'"),
        ('name: "a\\ttab"\n', "name", "'\\t'"),
    ],
)
def test_control_characters_are_refused(tmp_path, head, field, shown):
    p = tmp_path / "p.yaml"
    p.write_text(head + HOLD)
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    (issue,) = e.value.issues
    assert issue.field == field and issue.line == head.count("\n")
    assert f"must be printable text (found the control character {shown})" in issue.message


def test_line_breaks_tabs_and_other_scripts_are_text(tmp_path):
    p = tmp_path / "p.yaml"
    p.write_text('name: "Größe µε 测试"\ndescription: "two\\nlines\\tand a tab"\n' + HOLD)
    assert check_protocol(p).name == "Größe µε 测试"


@pytest.mark.parametrize(("volts", "name"), [(-0.0, "hold_0V_0p1s"), (0.0, "hold_0V_0p1s"),
                                             (-10.0, "hold_m10V_0p1s")])  # fmt: skip
def test_minus_zero_is_named_as_zero(tmp_path, volts, name):
    p = tmp_path / "p.yaml"
    p.write_text(f"name: z\nrate_hz: 500\nsteps:\n  - {{kind: hold, voltage_V: {volts!r}, "
                 "duration_s: 0.1}\n")  # fmt: skip
    assert [s.name for s in check_protocol(p).steps] == [name]


def test_an_unquoted_date_is_named_as_a_date(tmp_path):
    """YAML reads ``2026-01-01`` as a date: the refusal says so (it printed Python's
    ``datetime.date(2026, 1, 1)``), in protocol and rig files alike."""
    p = tmp_path / "p.yaml"
    p.write_text("name: 2026-01-01\n" + HOLD)
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    said = "(got 2026-01-01, which YAML reads as a date: quote it if it is text)"
    assert said in str(e.value) and "datetime" not in str(e.value)
    rig = tmp_path / "rig.yaml"
    rig.write_text(DEFAULT_RIG_YAML.replace("\nname: sim\n", "\nname: 2026-01-01\n"))
    with pytest.raises(InputFileError) as e:
        load_rig(rig)
    assert said in str(e.value)
    p.write_text('name: "2026-01-01"\n' + HOLD)
    assert check_protocol(p).name == "2026-01-01"


def test_a_bad_shared_params_file_is_said_once_and_a_rig_folder_is_named(tmp_path):
    """Every strain step reads the protocol's ``params:``: a broken file is one issue, not one
    per step; ``rig:`` naming a folder says so (not "not found")."""
    (tmp_path / "bad.json").write_text("{not json")
    steps = "".join(
        f"  - {{kind: strain_sine, amplitude_ue: 100, frequency_hz: {f}, cycles: 2, "
        "control: direct}\n"
        for f in (1, 2, 3)
    )
    p = tmp_path / "p.yaml"
    p.write_text("name: c\nrate_hz: 1000\nparams: bad.json\nsteps:\n" + steps)
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    texts = [str(i) for i in e.value.issues]
    assert len(texts) == 1 and "bad.json is not valid JSON" in texts[0], texts
    (tmp_path / "rigdir").mkdir()
    p.write_text("name: r\nrig: rigdir\n" + HOLD)
    with pytest.raises(InputFileError, match="not a file"):
        check_protocol(p)
