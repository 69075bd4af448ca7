"""Entry points for the CLI: read a protocol file into a plan, preflight it, show it.

``labrig check PROTOCOL`` is ``format_plan(check_protocol(path, limits))``; ``labrig run``
calls :func:`load_plan`, resolves the rig (``--rig``, else ``plan.rig_path``, else the built-in
simulated rig), then the preflight (:mod:`labrig.protocol.preflight`) with that rig's limits.
Every problem is an :class:`InputFileError` (exit 2) naming file, line and field.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError
from rich.markup import escape
from rich.table import Table

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.yamlio import read_yaml, what_was_given
from labrig.protocol.expand import build_plan
from labrig.protocol.plan import Plan, PlannedStep, field_name, line_of
from labrig.protocol.preflight import preflight_checks
from labrig.protocol.schema import STEP_KINDS, Protocol
from labrig.rig.limits import RigLimits


def _clean_loc(loc: tuple) -> tuple:
    """Drop pydantic's bookkeeping from an error location (union tags, validator names)."""
    out = []
    for i, x in enumerate(loc):
        if isinstance(x, str) and x.startswith("function-"):
            continue
        # discriminated unions put the tag after the list index: steps, 0, 'sine', field
        if i == 2 and loc[0] == "steps" and isinstance(loc[1], int) and x in STEP_KINDS:
            continue
        out.append(x)
    return tuple(out)


def _looks_numeric(x: object) -> bool:
    if not isinstance(x, str):
        return False
    try:
        float(x)
    except ValueError:
        return False
    return True


def validation_issues(file: str, err: ValidationError, lines: dict) -> list[InputIssue]:
    """pydantic errors -> file:line issues with readable messages."""
    issues = []
    for e in err.errors():
        loc = _clean_loc(tuple(e["loc"]))
        msg = e["msg"]
        typ = e["type"]
        if typ == "extra_forbidden":
            msg = "unknown key (not part of the schema; check the spelling)"
        elif typ == "missing":
            msg = "required key is missing"
        elif typ == "union_tag_invalid":
            msg = f"unknown step kind; valid kinds: {', '.join(STEP_KINDS)}"
        elif typ == "union_tag_not_found":
            msg = f"each step needs a 'kind': one of {', '.join(STEP_KINDS)}"
        elif typ == "string_pattern_mismatch":
            msg = "use a letter, then letters, digits or underscores (at most 60 characters)"
        elif typ.startswith("value_error"):
            msg = msg.removeprefix("Value error, ")
        if "input" in e and typ not in ("missing", "extra_forbidden", "union_tag_not_found"):
            inp = e["input"]
            if not isinstance(inp, dict | list):
                msg += what_was_given(inp)
            if _looks_numeric(inp):
                msg += "; write numbers without quotes"
                if "e" in inp.lower():
                    msg += " (YAML reads 1e3 as text: write 1000 or 1.0e+3)"
        issues.append(InputIssue(file, line_of(loc, lines), field_name(loc), msg))
    return sorted(issues, key=lambda i: i.line or 0)


def load_protocol(path: Path | str) -> tuple[Protocol, dict, str]:
    """Read and validate a protocol file: ``(protocol, line index, text)``."""
    file = str(path)
    data, lines, text = read_yaml(path)  # also refuses keys given twice
    if data is None:
        raise InputFileError(
            [InputIssue(file, 1, "", "file is empty; expected a protocol (name, rate_hz, steps)")]
        )
    if not isinstance(data, dict):
        kind = type(data).__name__
        msg = f"expected a YAML mapping (name:, rate_hz:, steps:) at the top, got {kind}"
        line = lines.get((), 1)
        raise InputFileError([InputIssue(file, line, "", msg)])
    bad_keys = [k for k in data if not isinstance(k, str)]
    if bad_keys:
        msg = f"keys must be names, got {bad_keys[0]!r}"
        raise InputFileError([InputIssue(file, lines.get((), 1), "", msg)])
    try:
        protocol = Protocol.model_validate(data)
    except ValidationError as e:
        raise InputFileError(validation_issues(file, e, lines)) from None
    except (TypeError, ValueError, RecursionError) as e:  # pragma: no cover - defensive
        raise InputFileError([InputIssue(file, 1, "", f"cannot read protocol: {e}")]) from None
    return protocol, lines, text


def load_plan(path: Path | str) -> Plan:
    """Validate and expand a protocol file (no limits checked yet)."""
    protocol, lines, text = load_protocol(path)
    return build_plan(protocol, path=path, text=text, lines=lines)


def check_protocol(path: Path | str, limits: RigLimits | None = None) -> Plan:
    """Validate, expand and preflight ``path`` against ``limits`` (default: built-in rig).

    Returns the plan with the preflight's results (``plan.checks``, ``plan.limits``); raises
    :class:`InputFileError`.
    """
    plan = load_plan(path)
    lim = limits if limits is not None else RigLimits()
    plan.take_checks(preflight_checks(plan, lim), lim)
    return plan


def _fmt(x: float | None, spec: str = "g") -> str:
    return "-" if x is None else format(x, spec)


def _volts(step: PlannedStep) -> str:
    """The table's voltage column: the amplitude, or ``offset+-amplitude`` around a bias."""
    around = ("offset_sine", "triangle", "prbs", "multisine")
    offset = step.definition.get("offset_V") if step.kind in around else None
    if offset is None:
        return _fmt(step.amplitude_V)
    return f"{offset:g}+-{step.amplitude_V:g}"


def format_plan(plan: Plan) -> Table:
    """The plan summary: one row per entry (peak current once preflight has run)."""
    checks = {c.name: c for c in plan.checks or []}
    lim = plan.limits
    n = len(plan.steps)
    table = Table(
        title=f"{escape(plan.name)}: {n} {'entry' if n == 1 else 'entries'} at {plan.rate_hz:g} Hz",
        caption=(
            "V: amplitude (around a bias: offset +- amplitude); Hz: frequency; s: duration; "
            "peak A: peak current into the stack; rest s: 0 V after the entry\n"
            f"recorded {plan.recorded_duration_s:.1f} s, total with rests "
            f"{plan.total_duration_s:.1f} s"
            + (
                f"; limits {lim.v_min_V:g}..{lim.v_max_V:g} V, {lim.i_peak_A:g} A peak, "
                f"{lim.i_avg_A:g} A average"
                if lim is not None
                else ""
            )
        ),
    )
    table.add_column("#", justify="right")
    table.add_column("entry", no_wrap=True)
    table.add_column("kind", no_wrap=True)
    for col in ("V", "Hz", "s", "peak A", "rest s"):
        table.add_column(col, justify="right")
    for s in plan.steps:
        c = checks.get(s.name)
        table.add_row(
            str(s.index + 1),
            s.name,
            s.kind,
            _volts(s),
            _fmt(s.frequency_hz),
            f"{s.duration_s:.3f}",
            "-" if c is None else f"{c.peak_current_A:.3f}",
            _fmt(s.rest_after_s),
        )
    return table
