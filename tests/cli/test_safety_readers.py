"""YAML and JSON readers bound what they read: exit 2 with file and line, never a traceback.

The issue's cases through the command line (typer's CliRunner): a protocol and a rig file
nested 20 000 deep, a 5000-digit YAML integer, YAML 1.1's base-60 ``1:30`` (read as 90 by
PyYAML), a double-quoted ``\\U`` escape of many digits (PyYAML's scanner raised OverflowError);
parameter files for ``report --params`` and ``diagnose --params`` nested 100 000 deep, with a
5000-digit integer, or larger than the bound. Then the bounds themselves at their edges.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from labrig.analysis.params_file import MAX_PARAMS_BYTES, read_params_file
from labrig.core.errors import InputFileError
from labrig.core.jsonsafe import MAX_JSON_DEPTH, json_depth, loads_bounded
from labrig.core.yamlio import MAX_DEPTH, MAX_INT_DIGITS, BoundedLoader, PythonLoader, read_yaml

from helpers import invoke

ROOT = Path(__file__).resolve().parents[2]
GOOD_PROTOCOL = ROOT / "experiments" / "envelope.yaml"
HOLD = "name: x\nrate_hz: 1000\nsteps:\n  - kind: hold\n    voltage_V: 10\n    duration_s: {}\n"


def refused(res, where: str, message: str) -> None:
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.stderr.startswith(f"error: {where}"), res.stderr
    assert message in res.stderr, res.stderr
    assert "Traceback" not in res.output
    assert "9" * 50 not in res.output  # no number printed with hundreds of digits


#: a ``\U`` escape of 400 digits: libyaml's parser refuses it as a syntax error; PyYAML's parser
#: in Python fails on it converting the number (the loader's own message)
UNREADABLE_ESCAPE = (
    "YAML error: cannot read this"
    if BoundedLoader is PythonLoader
    else "YAML syntax error: found invalid Unicode character escape code"
)


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("name: x\nsteps: " + "[" * 20_000 + "]" * 20_000 + "\n", 2, "nested more than 64"),
        ("name: x\nrate_hz: " + "9" * 5000 + "\nsteps: []\n", 2, "a number with 5000 digits"),
        (HOLD.format("1:30"), 6, "'1:30' is a base-60 number"),
        (HOLD.format("-1:30:00.5"), 6, "base-60 number"),
        (HOLD.format("017"), 6, "'017' is an octal number in YAML 1.1 (read as 15)"),
        (HOLD.format("-0_17"), 6, "octal number in YAML 1.1 (read as -15)"),
        (HOLD.format("00"), 6, "octal number"),
        (HOLD.format("0x10"), 6, "'0x10' is a hexadecimal number in YAML 1.1 (read as 16)"),
        (HOLD.format("0b11"), 6, "'0b11' is a binary number in YAML 1.1 (read as 3)"),
        (
            "name: x\nrate_hz: 500\nsteps:\n  - &s {kind: hold, voltage_V: 10, duration_s: 1}\n"
            "  - {<<: [*s, {voltage_V: 5}], duration_s: 2}\n",
            5,
            "a merge of several mappings (<<: [...])",
        ),
        ('name: "\\U' + "9" * 400 + '"\nsteps: []\n', 1, UNREADABLE_ESCAPE),
    ],
)
def test_hostile_yaml_is_refused_at_its_line(tmp_path: Path, text: str, line: int, message: str):
    proto = tmp_path / "p.yaml"
    proto.write_text(text)
    refused(invoke("check", proto), f"{proto}:{line}:", message)
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    refused(invoke("check", GOOD_PROTOCOL, "--rig", rig), f"{rig}:{line}:", message)


def test_quoted_base_60_is_text_and_a_plain_number_is_read(tmp_path: Path):
    p = tmp_path / "p.yaml"
    p.write_text('name: "1:30"\nrate_hz: 1000\nsteps:\n  - kind: hold\n    voltage_V: 10\n'
                 "    duration_s: 90\n")  # fmt: skip
    data, _, _ = read_yaml(p)
    assert data["name"] == "1:30" and data["steps"][0]["duration_s"] == 90


def test_decimal_numbers_and_one_merged_mapping_are_read(tmp_path: Path):
    """Just inside the refusals above: a zero, a decimal with underscores, a float with a
    leading zero, an octal-looking quoted text, and a merge of one mapping (as a list too)."""
    p = tmp_path / "p.yaml"
    p.write_text(
        "a: 0\nb: -0\nc: 1_000\nd: 0.5\ne: 00.5\nf: '017'\ng: 10\n"
        "base: &s {v: 10, t: 1}\nm: {<<: *s, t: 2}\nn: {<<: [*s], t: 3}\n"
    )
    data, _, _ = read_yaml(p)
    assert (data["a"], data["b"], data["c"], data["g"]) == (0, 0, 1000, 10)
    assert (data["d"], data["e"], data["f"]) == (0.5, 0.5, "017")
    assert data["m"] == {"v": 10, "t": 2} and data["n"] == {"v": 10, "t": 3}


@pytest.mark.parametrize(("depth", "ok"), [(MAX_DEPTH, True), (MAX_DEPTH + 1, False)])
def test_the_yaml_depth_bound(tmp_path: Path, depth: int, ok: bool):
    p = tmp_path / "d.yaml"
    p.write_text("a: " + "[" * (depth - 1) + "]" * (depth - 1) + "\n")  # the mapping is 1 level
    if ok:
        read_yaml(p)
    else:
        with pytest.raises(InputFileError, match="nested more than"):
            read_yaml(p)


@pytest.mark.parametrize(("digits", "ok"), [(MAX_INT_DIGITS, True), (MAX_INT_DIGITS + 1, False)])
def test_the_yaml_digits_bound(tmp_path: Path, digits: int, ok: bool):
    p = tmp_path / "n.yaml"
    p.write_text("a: " + "9" * digits + "\n")
    if ok:
        assert read_yaml(p)[0]["a"] == int("9" * digits)
    else:
        with pytest.raises(InputFileError, match=f"{digits} digits"):
            read_yaml(p)


# -- parameter files -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("run")
    (tmp / "p.yaml").write_text(
        "name: p\nrate_hz: 500\nsteps:\n  - kind: sine\n    amplitude_V: 60\n"
        "    frequency_hz: 2\n    cycles: 2\n"
    )
    res = invoke("run", tmp / "p.yaml", "--out", tmp / "run.h5", "--seed", 1)
    assert res.exit_code == 0, res.output
    return tmp / "run.h5"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[" * 100_000 + "]" * 100_000, "nested 100000 deep"),
        ('{"params": {"alpha0_ue_per_V": ' + "9" * 5000 + "}}", "an integer with 5000 digits"),
        ('{"params": ' * 70 + "{}" + "}" * 70, "nested 71 deep"),
        ('{"params": {"alpha0_ue_per_V": 1e999}}', "invalid model parameters"),
        ('{"params": {"alpha0_ue_per_V": NaN}}', "alpha0_ue_per_V: Input should be a finite"),
        ('{"params": {"tau_d_s": Infinity}}', "tau_d_s: Input should be a finite number"),
        ('{"params": {"vc_V": 70, "vc_V": 0}}', "the key 'vc_V' is given twice in one object"),
    ],
)
@pytest.mark.parametrize("command", ["report", "diagnose"])
def test_hostile_parameter_files_are_refused(
    run_file: Path, tmp_path: Path, text: str, message: str, command: str
):
    params = tmp_path / "params.json"
    params.write_text(text)
    extra = ["--out", tmp_path / "r.html"] if command == "report" else []
    refused(invoke(command, run_file, "--params", params, *extra), f"{params}:", message)


def test_a_parameter_file_larger_than_the_bound_is_not_read(tmp_path: Path):
    p = tmp_path / "big.json"
    with p.open("w") as f:
        f.write('{"params": {}, "pad": "')
        f.write("x" * (MAX_PARAMS_BYTES + 10))
        f.write('"}')
    with pytest.raises(InputFileError, match="larger than"):
        read_params_file(p, "the test")


def test_loads_bounded_at_its_edges():
    assert loads_bounded("[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH) is not None
    with pytest.raises(ValueError, match="nested"):
        loads_bounded("[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1))
    with pytest.raises(ValueError, match="longer than"):
        loads_bounded("[1]", max_bytes=2)
    assert loads_bounded("9" * 100) == int("9" * 100)
    with pytest.raises(ValueError, match="101 digits"):
        loads_bounded("9" * 101)
    with pytest.raises(json.JSONDecodeError):
        loads_bounded("{")
    # a key twice in one object, at any depth, is refused; the same key in two objects is not
    assert loads_bounded('[{"a": 1}, {"a": 2, "b": {"a": 3}}]') == [
        {"a": 1},
        {"a": 2, "b": {"a": 3}},
    ]
    for text in ('{"a": 1, "a": 1}', '[{"b": {"a": 1, "a": 2}}]'):
        with pytest.raises(ValueError, match="the key 'a' is given twice in one object"):
            loads_bounded(text)


def test_json_depth_ignores_brackets_in_strings():
    assert json_depth('{"a": "[[[[{{{{", "b": ["\\"]]]"]}') == 2
    assert json_depth("[[], [[]]]") == 3
