"""Who ran what on which actuator: a run's metadata, from a protocol's ``metadata:`` mapping and
the options ``--meta KEY=VALUE``, ``--operator NAME`` and ``--sample ID`` of ``labrig run`` and
``labrig import`` (the options win over the protocol, key by key).

Every key is kept (``/run/metadata`` in the run file, one scalar each); a few keys also fill the
NeXus base classes of each entry (docs/runfile.md, "Metadata"):

- ``operator`` -> ``/<entry>/user`` (NXuser) ``name``;
- ``sample`` -> ``/<entry>/sample`` (NXsample) ``name`` (the sample id, e.g. ``P-888 #3``);
- ``actuator_model`` -> ``sample/model``, ``actuator_serial`` -> ``sample/serial_number``.

Values are text, whole numbers, finite numbers or booleans. On the command line a value that
reads as a number (``23.5``, ``-4``, ``1e3``) is a number, ``true``/``false`` a boolean, anything
else text; the identity keys above are always text (a serial ``00123`` keeps its zeros). A key
that is not given is absent: nothing is stored for it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

#: a metadata key: an HDF5 dataset name that every tool handles
KEY_PATTERN = r"[A-Za-z][A-Za-z0-9_]{0,62}"
#: at most this many keys, and text values of at most this many characters
MAX_KEYS = 100
MAX_TEXT = 200

OPERATOR = "operator"
SAMPLE = "sample"
ACTUATOR_MODEL = "actuator_model"
ACTUATOR_SERIAL = "actuator_serial"
#: keys that are names or identifiers: kept as text whatever they look like
TEXT_KEYS = frozenset({OPERATOR, SAMPLE, ACTUATOR_MODEL, ACTUATOR_SERIAL})

MetaValue = str | bool | int | float

_INT = re.compile(r"[-+]?(0|[1-9][0-9]*)")
_FLOAT = re.compile(r"[-+]?([0-9]+\.[0-9]*|\.[0-9]+|[0-9]+)([eE][-+]?[0-9]{1,3})?")


class MetadataError(ValueError):
    """A key or value that cannot be metadata; the message names it and says what is valid."""


@dataclass(frozen=True)
class RunMetadata:
    """The metadata of a run: every key with its value, in the order given."""

    values: dict[str, MetaValue] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.values)

    def text(self, key: str) -> str | None:
        v = self.values.get(key)
        return None if v is None else str(v)

    @property
    def operator(self) -> str | None:
        return self.text(OPERATOR)

    @property
    def sample(self) -> str | None:
        return self.text(SAMPLE)

    def user_fields(self) -> dict[str, str]:
        """The NXuser group's fields (empty: no group)."""
        return {"name": self.operator} if self.operator is not None else {}

    def sample_fields(self) -> dict[str, str]:
        """The NXsample group's fields (empty: no group)."""
        fields = {
            "name": self.sample,
            "model": self.text(ACTUATOR_MODEL),
            "serial_number": self.text(ACTUATOR_SERIAL),
        }
        return {k: v for k, v in fields.items() if v is not None}

    def over(self, base: RunMetadata) -> RunMetadata:
        """``base``'s keys with this one's values put over them."""
        return RunMetadata({**base.values, **self.values})


def check_key(key: str) -> str:
    if not isinstance(key, str) or not re.fullmatch(KEY_PATTERN, key):
        raise MetadataError(
            f"key {str(key)[:70]!r}: use a letter, then letters, digits or underscores "
            "(at most 63 characters)"
        )
    return key


def check_value(key: str, value: object) -> MetaValue:
    """``value`` as stored for ``key`` (identity keys as text); :class:`MetadataError` if it is
    not a simple value."""
    if isinstance(value, bool | str):
        pass
    elif isinstance(value, int):
        if not -(2**63) <= value < 2**63:
            raise MetadataError(f"{key}: whole numbers must fit in 64 bits")
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise MetadataError(f"{key}: numbers must be finite (not {value})")
    else:
        raise MetadataError(
            f"{key}: expected text, a number or true/false, not {type(value).__name__}"
        )
    if key in TEXT_KEYS and not isinstance(value, str):
        value = str(value).lower() if isinstance(value, bool) else str(value)
    if isinstance(value, str) and (len(value) > MAX_TEXT or not value.isprintable()):
        raise MetadataError(
            f"{key}: text must be printable and at most {MAX_TEXT} characters (found {len(value)})"
        )
    return value


def parse_value(key: str, text: str) -> MetaValue:
    """A command-line value: a number, ``true``/``false`` or text (module docstring)."""
    if key not in TEXT_KEYS:
        digits = text.lstrip("+-")
        if digits.isdigit() and (len(digits) > 19 or (len(digits) > 1 and digits[0] == "0")):
            return check_value(key, text)  # a barcode, a lot "007": an identifier, kept as text
        if _INT.fullmatch(text):  # never a float: 99999999999999999999999 is no 1e+23
            if not -(2**63) <= int(text) < 2**63:
                return check_value(key, text)  # 20 digits: an identifier, not a number
            return check_value(key, int(text))
        if _FLOAT.fullmatch(text):
            return check_value(key, float(text))
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
    return check_value(key, text)


def parse_assignment(text: str) -> tuple[str, MetaValue]:
    """``KEY=VALUE`` (``--meta``) as a key and its value."""
    key, eq, value = text.partition("=")
    key = key.strip()
    if not eq or not key:
        raise MetadataError(f"{text[:70]!r}: expected KEY=VALUE, e.g. actuator_serial=123")
    return check_key(key), parse_value(key, value.strip())


def from_options(
    meta: Iterable[str] = (), operator: str | None = None, sample: str | None = None
) -> RunMetadata:
    """The metadata the options give: ``--meta`` in order (a key given twice keeps the last),
    then ``--operator`` and ``--sample``."""
    values: dict[str, MetaValue] = {}
    for item in meta:
        key, value = parse_assignment(item)
        values[key] = value
    for key, given in ((OPERATOR, operator), (SAMPLE, sample)):
        if given is not None:
            values[key] = check_value(key, given.strip())
    return checked(values)


def checked(values: Mapping[str, object]) -> RunMetadata:
    """Every key and value checked (:func:`check_key`, :func:`check_value`), at most
    :data:`MAX_KEYS` keys."""
    if len(values) > MAX_KEYS:
        raise MetadataError(f"at most {MAX_KEYS} metadata keys (found {len(values)})")
    return RunMetadata({check_key(k): check_value(k, v) for k, v in values.items()})


def combine(protocol: Mapping[str, object] | None, options: RunMetadata | None) -> RunMetadata:
    """A protocol's ``metadata:`` with the options' values over it."""
    base = checked(dict(protocol or {}))
    return (options or RunMetadata()).over(base) if options else base
