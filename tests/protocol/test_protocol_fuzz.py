"""Property-based fuzzing of the protocol schema and loader.

Random documents must never crash the loader: the only failure allowed is InputFileError (from
files) or pydantic's ValidationError (from dicts). Valid generated protocols must round-trip
(dump -> validate gives the same model; YAML file -> plan with the expected entries).
"""

from __future__ import annotations

import contextlib
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from labrig.core.errors import InputFileError
from labrig.protocol.check import check_protocol
from labrig.protocol.schema import STEP_KINDS, Protocol

FUZZ = settings(
    max_examples=20,  # the default tier's share of generated protocols
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
#: the slow tier's twins of the properties that build whole plans: three times as many inputs
FUZZ_LONG = settings(FUZZ, max_examples=60)

TOP_KEYS = ["name", "description", "rig", "rate_hz", "rest_s", "edge_slew_V_per_s", "steps"]
STEP_KEYS = [
    "kind",
    "name",
    "repeat",
    "rest_s",
    "amplitude_V",
    "frequency_hz",
    "cycles",
    "duration_s",
    "decay_s",
    "shape",
    "tau_s",
    "hold_s",
    "voltage_V",
    "from_V",
    "to_V",
    "path",
    "column",
    "time_column",
    "rate_hz",
    "scale",
    "amplitudes_V",
    "frequencies_hz",
    "min_duration_s",
    "order",
]

# values chosen to hit edges without asking for hours of samples
odd_numbers = st.sampled_from(
    [0, -1, 1, 2, 0.5, 1e-9, 1e3, 1e9, 1e300, -1e300, math.inf, -math.inf, math.nan, 5e-324]
)
small_numbers = st.floats(min_value=-200, max_value=200, allow_nan=False)
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    odd_numbers,
    small_numbers,
    st.text(max_size=12),
    st.sampled_from([*STEP_KINDS, "linear", "exponential", "by_frequency", "x.csv", "1e3"]),
)
json_like = st.recursive(
    scalars,
    lambda kids: (
        st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4)
    ),
    max_leaves=12,
)
steps_like = st.lists(
    st.dictionaries(st.sampled_from(STEP_KEYS), json_like, max_size=8)
    | st.fixed_dictionaries(
        {"kind": st.sampled_from(STEP_KINDS)},
        optional={k: st.one_of(scalars, st.lists(scalars, max_size=3)) for k in STEP_KEYS[1:]},
    ),
    max_size=4,
)
protocol_like = st.fixed_dictionaries(
    {},
    optional={
        "name": st.one_of(st.text(max_size=10), scalars),
        "rate_hz": st.one_of(st.sampled_from([10, 100, 1000, 5000]), scalars),
        "rest_s": scalars,
        "edge_slew_V_per_s": scalars,
        "description": scalars,
        "steps": st.one_of(steps_like, json_like),
        "extra": json_like,
    },
)


def _dump(data) -> str:
    return yaml.safe_dump(data, allow_unicode=True, sort_keys=False)


def _check_file(text: str | bytes):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "fuzz.yaml"
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text, encoding="utf-8")
        try:
            return check_protocol(p)
        except InputFileError as e:
            assert e.issues
            # YAML also breaks lines at \r, \x85, \u2028, \u2029 (as splitlines does)
            n_lines = max(
                1, len(text.splitlines()), text.count("\n" if isinstance(text, str) else b"\n")
            )
            for i in e.issues:
                assert i.file == str(p)
                assert i.line is None or 1 <= i.line <= n_lines + 1
                assert isinstance(i.message, str) and i.message
            return None


@FUZZ
@given(protocol_like)
def test_random_dicts_only_raise_validation_errors(data):
    with contextlib.suppress(ValidationError):
        Protocol.model_validate(data)


@pytest.mark.slow
@FUZZ_LONG
@given(protocol_like)
def test_random_dicts_only_raise_validation_errors_many(data):
    """Random protocol-like dicts, three times as many.

    Fast equivalent in the default tier: tests/protocol/test_protocol_fuzz.py::test_random_dicts_only_raise_validation_errors
    """  # noqa: E501
    with contextlib.suppress(ValidationError):
        Protocol.model_validate(data)


@FUZZ
@given(protocol_like)
def test_random_protocol_files_only_raise_input_file_errors(data):
    _check_file(_dump(data))


@pytest.mark.slow
@FUZZ_LONG
@given(protocol_like)
def test_random_protocol_files_only_raise_input_file_errors_many(data):
    """Random protocol-like files, three times as many.

    Fast equivalent in the default tier: tests/protocol/test_protocol_fuzz.py::test_random_protocol_files_only_raise_input_file_errors
    """  # noqa: E501
    _check_file(_dump(data))


@settings(FUZZ, max_examples=60)
@given(json_like)
def test_random_documents_only_raise_input_file_errors(data):
    _check_file(_dump(data))


@settings(max_examples=100, deadline=None)
@given(st.one_of(st.binary(max_size=200), st.text(max_size=200)))
def test_random_bytes_only_raise_input_file_errors(raw):
    _check_file(raw)


# --- valid protocols --------------------------------------------------------------------------

amp = st.floats(min_value=0.5, max_value=100)
freq = st.floats(min_value=0.5, max_value=20)
dur = st.floats(min_value=0.01, max_value=0.5)
common = {"repeat": st.integers(1, 2), "rest_s": st.floats(0, 5)}


def _step(kind: str, required: dict, optional: dict | None = None):
    return st.fixed_dictionaries(
        {"kind": st.just(kind), **required}, optional={**common, **(optional or {})}
    )


valid_step = st.one_of(
    _step("sine", {"amplitude_V": amp, "frequency_hz": freq, "cycles": st.floats(0.5, 3)}),
    _step("sine", {"amplitude_V": amp, "frequency_hz": freq, "duration_s": dur}),
    _step(
        "vanishing",
        {"amplitude_V": amp, "frequency_hz": freq, "decay_s": st.floats(0.5, 2)},
        {"hold_s": st.floats(0, 0.3), "tau_s": st.floats(0.1, 10)},
    ),
    _step(
        "vanishing",
        {
            "amplitude_V": amp,
            "frequency_hz": freq,
            "decay_s": st.floats(0.5, 2),
            "shape": st.just("linear"),
        },
    ),
    _step(
        "offset_sine",
        {
            "offset_V": st.floats(0, 50),
            "amplitude_V": st.floats(0.5, 20),
            "frequency_hz": freq,
            "cycles": st.floats(0.5, 3),
        },
        {
            "envelope": st.sampled_from(["constant", "growing", "vanishing"]),
            "ramp_s": st.one_of(st.just(0.0), st.floats(0.01, 0.3)),
            "settle_s": st.one_of(st.just(0.0), st.floats(0.01, 0.3)),
        },
    ),
    _step("hold", {"voltage_V": st.floats(-20, 100), "duration_s": dur}),
    _step(
        "ramp",
        {"to_V": st.floats(-20, 100), "duration_s": st.floats(0.2, 1)},
        {"from_V": st.floats(-20, 100)},
    ),
    _step(
        "sweep",
        {
            "amplitudes_V": st.lists(amp, min_size=1, max_size=3),
            "frequencies_hz": st.lists(freq, min_size=1, max_size=3),
            "cycles": st.integers(1, 2),
        },
        {
            "order": st.sampled_from(["by_amplitude", "by_frequency"]),
            "min_duration_s": st.floats(0.01, 0.3),
            "name": st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,8}", fullmatch=True),
        },
    ),
)
#: printable text (Python's ``str.isprintable``: no "Other" or "Separator" character but the
#: space); a description may also break lines and hold tabs
PRINTABLE = st.characters(
    exclude_categories=("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp", "Zs"), include_characters=" "
)
valid_protocol = st.fixed_dictionaries(
    {
        "name": st.text(PRINTABLE, min_size=1, max_size=20),
        "rate_hz": st.sampled_from([1000, 2000, 2500]),
        "steps": st.lists(valid_step, min_size=1, max_size=4),
    },
    optional={
        "rest_s": st.floats(0, 10),
        "description": st.text(st.one_of(PRINTABLE, st.sampled_from("\n\t")), max_size=30),
    },
)


def _expected_entries(d: dict) -> int:
    n = 0
    for s in d["steps"]:
        k = len(s["amplitudes_V"]) * len(s["frequencies_hz"]) if s["kind"] == "sweep" else 1
        n += k * s.get("repeat", 1)
    return n


VALID = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _check_round_trip(d: dict) -> None:
    p = Protocol.model_validate(d)
    again = Protocol.model_validate(p.model_dump(mode="json", exclude_none=True))
    assert again == p
    plan = _check_file(_dump(d))
    assert plan is not None, "a valid protocol within the rig's limits was refused"
    assert len(plan.steps) == _expected_entries(d)
    assert len({s.name for s in plan.steps}) == len(plan.steps)
    for s in plan.steps[:6]:
        v = s.samples()
        assert v[0] == 0.0 and v[-1] == 0.0 and np.all(np.isfinite(v))


@VALID
@given(valid_protocol)
def test_valid_protocols_round_trip(d):
    _check_round_trip(d)


@pytest.mark.slow
@settings(VALID, max_examples=60)
@given(valid_protocol)
def test_valid_protocols_round_trip_many(d):
    """Generated valid protocols, three times as many.

    Fast equivalent in the default tier: tests/protocol/test_protocol_fuzz.py::test_valid_protocols_round_trip
    """  # noqa: E501
    _check_round_trip(d)


PAPER = (Path(__file__).resolve().parents[2] / "experiments" / "paper.yaml").read_text()


PAPER_EDITS = st.lists(
    st.tuples(
        st.integers(0, len(PAPER) - 1),
        st.sampled_from(["delete", "insert", "replace"]),
        st.sampled_from(list(":-[]{}#&*!|>'\"%@` \t\n0123456789.eE-+abc")),
    ),
    min_size=1,
    max_size=4,
)


def _check_mutated_paper(edits) -> None:
    text = PAPER
    for pos, op, ch in edits:
        pos = min(pos, len(text) - 1)
        if op == "delete":
            text = text[:pos] + text[pos + 1 :]
        elif op == "insert":
            text = text[:pos] + ch + text[pos:]
        else:
            text = text[:pos] + ch + text[pos + 1 :]
    _check_file(text)


@settings(max_examples=25, deadline=None)
@given(PAPER_EDITS)
def test_mutated_paper_yaml_only_raises_input_file_errors(edits):
    _check_mutated_paper(edits)


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(PAPER_EDITS)
def test_mutated_paper_yaml_only_raises_input_file_errors_many(edits):
    """Random edits of the paper's protocol, four times as many.

    Fast equivalent in the default tier: tests/protocol/test_protocol_fuzz.py::test_mutated_paper_yaml_only_raises_input_file_errors
    """  # noqa: E501
    _check_mutated_paper(edits)
