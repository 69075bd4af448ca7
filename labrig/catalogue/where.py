"""The filter language of ``labrig runs --where`` (docs/catalogue.md is the user's description).

An expression is ``KEY OP VALUE``; several ``--where`` must all hold. Operators: ``=``, ``!=``,
``~`` (contains), ``!~`` (does not contain), ``<``, ``<=``, ``>``, ``>=``. Text compares
ignoring case and spaces (``sample=P-888#3`` finds ``P-888 #3``); numbers compare as numbers
(``=`` within a relative 1e-9; whole numbers exactly: a 63-bit seed is not a float); ordering
needs a number or a date. ``status`` compares with what the listing prints (``incomplete`` for
a file that stores ``running``, which also matches).

Keys, looked up in this order:

- run keys: ``status``, ``protocol``, ``protocol_file``, ``rig``, ``file``, ``seed``,
  ``software_version``, ``entries`` (the number of entries), ``reason``, ``error``;
- dates: ``since=DATE`` (started on or after), ``until=DATE`` (started on or before: a date
  alone includes that whole day), ``date OP DATE``; a DATE is ``YYYY``, ``YYYY-MM``,
  ``YYYY-MM-DD`` or an ISO 8601 time, compared with the run's own local time unless it carries
  a UTC offset;
- entry keys: ``kind``, ``entry`` (its name), ``samples``, ``rate_hz``, ``duration_s`` and any
  key of an entry's step definition (``amplitude_V``, ``frequency_hz``, ``offset_V``, ...;
  ``amplitude`` and ``frequency`` are short for the first two). All entry conditions must hold
  on one same entry;
- anything else is metadata: a key matches the metadata key of that name, or one ending in
  ``/KEY``, or ``KEY/name`` (a NeXus group's name: ``sample`` is ``sample/name``);
  ``operator`` also means ``user`` (NXuser). A run without the key matches only ``!=`` and
  ``!~``.

A bad expression is a :class:`WhereError` (exit 2) naming it and what is valid: no operator, an
operator that is not one (``==``), a value of the wrong type (a status that is not one, a
number or a whole number expected, a date expected), and (:func:`check_keys`, once the runs are
known) a key that no run listed has.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import date, datetime, timedelta
from fractions import Fraction
from typing import Any

from labrig.core.errors import LabrigError

OPERATORS = ("!=", "!~", "<=", ">=", "=", "~", "<", ">")
ORDERING = ("<", "<=", ">", ">=")
RUN_KEYS = (
    "status",
    "protocol",
    "protocol_file",
    "rig",
    "file",
    "seed",
    "software_version",
    "entries",
    "reason",
    "error",
)
DATE_KEYS = ("date", "since", "until")
ENTRY_KEYS = ("kind", "entry", "samples", "rate_hz", "duration_s")
#: keys whose values are numbers: a value that is not one is a bad expression
NUMERIC_KEYS = frozenset(
    {"seed", "entries", "samples", "rate_hz", "duration_s", "amplitude_V", "frequency_hz"}
)
#: keys whose values are whole numbers: ``=`` and ``!=`` need one, and compare exactly (a seed
#: is 63 bits: a float would round it)
INTEGER_KEYS = frozenset({"seed", "entries", "samples"})
#: what ``status`` can equal: the statuses the listing prints (``incomplete``: the writer never
#: finished, stored as ``running``, which is also accepted) and ``unreadable``
STATUS_VALUES = ("complete", "aborted", "failed", "incomplete", "running", "unreadable")
#: the status the listing prints for a stored status
SHOWN_STATUS = {"running": "incomplete"}
ALIASES = {"amplitude": "amplitude_V", "frequency": "frequency_hz"}
#: metadata keys that also answer to another name
METADATA_ALIASES = {"operator": ("operator", "user")}
#: where a record keeps a run key
RUN_FIELD = {"rig": "rig_file", "file": "path"}

#: characters that make a value look like the rest of a mistyped operator (``==``, ``=>``)
_OPERATOR_CHARS = "=<>~!"
_INTEGER = re.compile(r"^[+-]?[0-9]+$")
_EXPR = re.compile(r"^\s*([^!<>=~\s]+)\s*(!=|!~|<=|>=|=|~|<|>)\s*(.*?)\s*$", re.DOTALL)
_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_./#@-]*$")
_PARTIAL_DATE = re.compile(r"^(\d{4})(?:-(\d{2}))?$")

OPERATOR_TEXT = "operators: = != ~ !~ < <= > >="
VALID = (
    "valid: KEY=VALUE, KEY!=VALUE, KEY~TEXT (contains), KEY!~TEXT, KEY<N, KEY<=N, KEY>N, "
    "KEY>=N; since=DATE, until=DATE, date>=DATE (YYYY, YYYY-MM, YYYY-MM-DD or ISO 8601); "
    f"run keys {', '.join(RUN_KEYS)}; entry keys {', '.join(ENTRY_KEYS)}, amplitude_V, "
    "frequency_hz or any step key; any other key is metadata (sample, operator, ...); "
    "docs/catalogue.md"
)


class WhereError(LabrigError):
    """A ``--where`` expression that cannot be used (exit code 2): what is wrong, what is
    valid."""

    exit_code = 2

    def __init__(self, text: str, why: str, valid: str = VALID):
        super().__init__(f"--where {text!r}: {why}; {valid}")


@dataclass(frozen=True)
class Condition:
    """One parsed ``--where``: ``key`` (aliases resolved), ``op``, ``value`` as given, the
    value as a number when it is one, and the time span a date value covers."""

    text: str
    key: str
    op: str
    value: str
    number: float | None
    span: tuple[datetime, datetime] | None
    #: the value as a whole number when it is written as one (compared exactly)
    integer: int | None = None

    @property
    def scope(self) -> str:
        """``run``, ``date`` or ``entry-or-metadata`` (an entry key when it is a built-in entry
        key or a key of a step of the run, else metadata: :func:`matches` decides per run)."""
        if self.key in RUN_KEYS:
            return "run"
        if self.key in DATE_KEYS:
            return "date"
        return "entry-or-metadata"


def _number(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def date_span(text: str) -> tuple[datetime, datetime] | None:
    """The instants ``[start, end)`` a date names: a year, a month, a day, or one instant
    (``end == start``); ``None`` when ``text`` is not a date."""
    m = _PARTIAL_DATE.match(text)
    try:
        if m:
            year, month = int(m.group(1)), int(m.group(2) or 0)
            if month == 0:
                return datetime(year, 1, 1), _or_last(lambda: datetime(year + 1, 1, 1))
            if not 1 <= month <= 12:
                return None
            end = _or_last(lambda: datetime(year + month // 12, month % 12 + 1, 1))
            return datetime(year, month, 1), end
        if len(text) == 10:
            d = date.fromisoformat(text)
            start = datetime(d.year, d.month, d.day)
            return start, _or_last(lambda: start + timedelta(days=1))
        t = datetime.fromisoformat(text)
    except ValueError:  # year 0, a day 31 of a 30-day month
        return None
    return t, t


def _or_last(end: Callable[[], datetime]) -> datetime:
    """The end of a span, or the last instant Python represents when the span is the last
    one (year 9999: its end, year 10000, is past :data:`datetime.max`)."""
    try:
        return end()
    except (ValueError, OverflowError):
        return datetime.max


def parse_where(text: str) -> Condition:
    """One expression (module docstring); :class:`WhereError` when it cannot be used."""
    m = _EXPR.match(text)
    if not m:
        raise WhereError(text, "no operator")
    key, op, value = m.groups()
    if not _KEY.match(key):
        raise WhereError(text, f"{key!r} is not a key (letters, digits, _ . / # @ -)")
    if value and value[0] in _OPERATOR_CHARS:  # status==complete, date=>2026, x<>3
        wrong = op + value[0] + (value[1] if value[1:2] and value[1] in _OPERATOR_CHARS else "")
        raise WhereError(text, f"{wrong!r} is not an operator", f"valid {OPERATOR_TEXT}")
    if not value:
        raise WhereError(text, "no value after the operator")
    key = ALIASES.get(key, key)
    span = date_span(value)
    number = _number(value)
    integer = int(value) if _INTEGER.match(value) else None
    if key == "status" and op in ("=", "!=") and _fold(value) not in STATUS_VALUES:
        raise WhereError(
            text, f"{value!r} is not a status", f"valid statuses: {', '.join(STATUS_VALUES)}"
        )
    if key in INTEGER_KEYS and op in ("=", "!=") and integer is None:
        raise WhereError(text, f"{key} is a whole number; {value!r} is not")
    if key in ("since", "until") and op != "=":
        raise WhereError(text, f"{key} takes '=' (e.g. {key}=2026-03-01)")
    if key in DATE_KEYS and op != "~" and span is None:
        raise WhereError(text, f"{value!r} is not a date")
    if key in NUMERIC_KEYS and op not in ("~", "!~") and number is None:
        raise WhereError(text, f"{key} is a number; {value!r} is not")
    if op in ORDERING and number is None and span is None:
        raise WhereError(text, f"{op} needs a number or a date, not {value!r}")
    return Condition(text, key, op, value, number, span, integer)


def parse_all(texts: Iterable[str]) -> list[Condition]:
    return [parse_where(t) for t in texts]


def _fold(text: str) -> str:
    return "".join(text.split()).casefold()


def _as_time(value: Any) -> datetime | None:
    if not isinstance(value, str) or not value:
        return None
    try:
        return datetime.fromisoformat(value)
    except ValueError:
        return None


def _compare_times(t: datetime, c: Condition) -> bool:
    """``t`` against a date condition: on the run's own wall clock unless the value has an
    offset (then as instants; a run time without offset is taken in the value's offset)."""
    assert c.span is not None
    start, end = c.span
    if start.tzinfo is None:
        t = t.replace(tzinfo=None)
    elif t.tzinfo is None:
        t = t.replace(tzinfo=start.tzinfo)
    op = {"since": ">=", "until": "<="}.get(c.key, c.op)
    instant = start == end
    if op in ("=", "!="):
        inside = t == start if instant else start <= t < end
        return inside if op == "=" else not inside
    if op == ">=":
        return t >= start
    if op == ">":
        return t >= end if not instant else t > start
    if op == "<=":
        return t <= start if instant else t < end
    return t < start  # "<"


def _one(value: Any, c: Condition) -> bool:
    """Whether a stored value satisfies a positive operator (``=``, ``~`` or an ordering)."""
    if isinstance(value, list):
        return any(_one(v, c) for v in value)
    if value is None:
        return False
    op = c.op.lstrip("!")
    if op == "~":
        return _fold(c.value) in _fold(str(value))
    stored = value if isinstance(value, int | float) and not isinstance(value, bool) else None
    if stored is None and isinstance(value, str):
        stored = int(value) if _INTEGER.match(value) else _number(value)
    if c.number is not None and stored is not None:
        if isinstance(stored, int) and c.integer is not None:
            return _order_exact(stored, c.integer, op)
        if isinstance(stored, int) and op != "=":  # seed>=9007199254740992.5: as written
            exact = _fraction(c.value)
            if exact is not None:
                return _order_exact(stored, exact, op)
        return _order(stored, c.number, op)
    if c.span is not None and (t := _as_time(value)) is not None:
        return _compare_times(t, Condition(c.text, "date", op, c.value, None, c.span))
    if op == "=":
        if isinstance(value, bool):
            return _fold(c.value) in (("true", "yes", "1") if value else ("false", "no", "0"))
        return _fold(str(value)) == _fold(c.value)
    return False


def _order(a: float, b: float, op: str) -> bool:
    """Numbers compared as numbers; ``=`` within a relative 1e-9 (a float may carry rounding).
    A whole number against a float is compared exactly by Python (no float conversion)."""
    if op == "=":
        if isinstance(a, int) and not isinstance(b, int) and b.is_integer():
            return a == b
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    return {"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b}[op]


def _fraction(text: str) -> Fraction | None:
    try:
        return Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        return None


def _order_exact(a: int, b: int | Fraction, op: str) -> bool:
    """A whole number against a whole number or a decimal as written, exactly (seeds, counts,
    ids: 64 bits, no tolerance; a decimal is not rounded to a float first)."""
    return {"=": a == b, "<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b}[op]


def holds(values: Sequence[Any], c: Condition) -> bool:
    """Whether the values a key has in one run (or entry) satisfy ``c``: a positive operator
    needs one value that satisfies it, ``!=`` / ``!~`` none that satisfies its positive."""
    found = any(_one(v, c) for v in values)
    return not found if c.op.startswith("!") else found


def metadata_values(metadata: dict[str, Any], key: str) -> list[Any]:
    """The values of the metadata keys ``key`` names (module docstring)."""
    names = [n.casefold() for n in METADATA_ALIASES.get(key, (key,))]
    out = []
    for k, v in metadata.items():
        kf = k.casefold()
        for n in names:
            if kf in (n, n + "/name") or kf.endswith(("/" + n, "/" + n + "/name")):
                out.append(v)
                break
    return out


def _entry_values(entry: dict[str, Any], key: str) -> list[Any]:
    """An entry's values of ``key`` (none when the entry has no such key)."""
    if key == "entry":
        return [entry.get("name")]
    if key in ENTRY_KEYS:
        return [entry.get(key)]
    step = entry.get("step", {})
    return [step[key]] if key in step else []


def _run_values(record: dict[str, Any], c: Condition) -> list[Any]:
    if c.key == "entries":
        return [len(record.get("entries", []))]
    if c.key == "protocol":
        return [record.get("protocol"), record.get("protocol_file")]
    if c.key == "file":  # as listed, and as an absolute path; file=PATH in any spelling
        path = record.get("path")
        if not isinstance(path, str):
            return []
        if c.op.lstrip("!") == "=" and os.path.abspath(c.value) == os.path.abspath(path):
            return [c.value]
        return [path, os.path.abspath(path)]
    if c.key == "status":  # as the listing prints it (incomplete), and as the file stores it
        status = record.get("status")
        return [SHOWN_STATUS.get(str(status), status), status]
    return [record.get(RUN_FIELD.get(c.key, c.key))]


def matches(record: dict[str, Any], conditions: Sequence[Condition]) -> tuple[bool, list[str]]:
    """Whether a run's record satisfies every condition, and the names of the entries that
    satisfy all the entry conditions (every entry when there are none)."""
    entries = record.get("entries", [])
    step_keys = {k for e in entries for k in e.get("step", {})}
    entry_conditions = []
    for c in conditions:
        if c.scope == "run":
            ok = holds(_run_values(record, c), c)
        elif c.scope == "date":
            t = _as_time(record.get("start_time"))
            ok = t is not None and (
                holds([record.get("start_time")], c)
                if c.op in ("~", "!~")
                else _compare_times(t, c)
            )
        elif c.key in ENTRY_KEYS or c.key in step_keys:
            entry_conditions.append(c)
            continue
        else:
            ok = holds(metadata_values(record.get("metadata", {}), c.key), c)
        if not ok:
            return False, []
    chosen = [
        e["name"]
        for e in entries
        if all(holds(_entry_values(e, c.key), c) for c in entry_conditions)
    ]
    if entry_conditions and not chosen:
        return False, []
    return True, chosen


def _shown_key(key: str) -> str:
    """A metadata key as a ``--where`` key most simply names it (``sample/name`` -> ``sample``,
    ``metadata/operator`` -> ``operator``)."""
    return key.removeprefix("metadata/").removesuffix("/name")


def check_keys(
    conditions: Sequence[Condition],
    records: Sequence[dict[str, Any]],
    more_metadata_keys: Iterable[str] = (),
) -> None:
    """Raise :class:`WhereError` for a condition whose key is none of the built-in keys and
    that no listed run has (as a step key or a metadata key): ``freq<20`` would otherwise match
    nothing without a word. The message lists the keys the listed runs have. Nothing is checked
    when no readable run is listed (there is nothing to know the keys from).
    ``more_metadata_keys``: metadata keys the records do not hold themselves (the index's
    instrument keys, :meth:`~labrig.catalogue.index.FolderIndex.detail_keys`)."""
    readable = [r for r in records if r.get("readable")]
    wanted = [c for c in conditions if c.scope == "entry-or-metadata"]
    if not readable or not wanted:
        return
    step_keys = {k for r in readable for e in r.get("entries", []) for k in e.get("step", {})}
    meta = dict.fromkeys(more_metadata_keys)
    for r in readable:
        meta.update(dict.fromkeys(r.get("metadata", {})))
    builtin = set(ENTRY_KEYS) | NUMERIC_KEYS
    for c in wanted:
        if c.key in builtin or c.key in step_keys or metadata_values(meta, c.key):
            continue
        raise WhereError(
            c.text,
            f"no run listed has the key {c.key!r}{_did_you_mean(c.key, step_keys, meta)}",
            _valid_keys(step_keys, list(meta)),
        )


def _did_you_mean(key: str, step_keys: set[str], meta: dict[str, Any]) -> str:
    import difflib

    names = sorted(
        {*RUN_KEYS, *DATE_KEYS, *ENTRY_KEYS, *NUMERIC_KEYS, *step_keys}
        | {_shown_key(k) for k in meta}
        | {k.rsplit("/", 1)[-1] for k in meta}
    )
    fold = key.casefold()
    close = [n for n in names if n.casefold().startswith(fold)]
    close += [n for n in difflib.get_close_matches(key, names, n=3) if n not in close]
    return f" (did you mean {' or '.join(close[:3])}?)" if close else ""


#: how many metadata keys a message lists (an instrument has hundreds)
_MAX_LISTED = 30


def _valid_keys(step_keys: set[str], metadata_keys: list[str]) -> str:
    meta = sorted({_shown_key(k) for k in metadata_keys if not k.startswith("instrument/")})
    n_instrument = sum(1 for k in metadata_keys if k.startswith("instrument/"))
    if len(meta) > _MAX_LISTED:
        meta = [*meta[:_MAX_LISTED], f"... ({len(meta) - _MAX_LISTED} more)"]
    if n_instrument:
        meta.append(f"{n_instrument} instrument keys (instrument/..., --json lists them)")
    steps = sorted(step_keys | {"amplitude_V", "frequency_hz"})
    return (
        f"valid keys: run keys {', '.join(RUN_KEYS)}; dates {', '.join(DATE_KEYS)}; entry keys "
        f"{', '.join(ENTRY_KEYS)}; step keys {', '.join(steps)}; metadata keys of the runs "
        f"listed: {', '.join(meta) or 'none'}; docs/catalogue.md"
    )
