"""Parameter files given to ``labrig report --params`` and ``labrig diagnose --params``: the one
reader of them.

A parameter file is what ``labrig fit --json`` / ``--out`` writes: an object with ``params``
(the dynamic model's :class:`~labrig.model.ModelParams`), ``method``, the scores, and with
``--effect`` the ``effects`` fitted with the model and the ``effects_context`` they were
configured with. ``diagnose`` also takes a bare ``ModelParams`` object. A baseline's file
(``labrig fit --model prandtl_ishlinskii``) holds no model parameters and is refused.

Every problem is an :class:`~labrig.core.errors.InputFileError` (exit code 2) naming the file, the
field and what would be valid; the file is read within bounds (:data:`MAX_PARAMS_BYTES`,
:func:`labrig.core.jsonsafe.loads_bounded`: nesting, digits). For ``report --params``
(:func:`read_fit_output`) every other section the report uses is checked too, every problem at
once (:func:`fit_output_issues`): ``uncertainty``, ``correlation``, ``identifiability``,
``heldout_nrmse_pct``, ``method``, ``entries``, ``train_files``; and the fitted effects'
parameters against the bounds each effect declares (:func:`fitted_effects`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from labrig.analysis.baselines import KINDS
from labrig.analysis.records import Record
from labrig.core.errors import InputFileError, InputIssue
from labrig.core.jsonsafe import JSONLimitError, loads_bounded
from labrig.core.textfile import read_text_bounded
from labrig.model import ModelParams
from labrig.model.effects import Effect, Param, RunContext

#: the largest parameter file read (``labrig fit`` writes a few kB)
MAX_PARAMS_BYTES = 10_000_000

#: the types of ``effects_context`` (how the effects were configured when they were fitted)
CONTEXT_TYPES: dict[str, type] = RunContext.types()
#: ``effects_context`` fields added after files were first written: a file may lack them (the
#: effects then take :class:`RunContext`'s default)
CONTEXT_ADDED_LATER: frozenset[str] = frozenset({"rate_hz"})
#: an effect's parameter this far (relative to ``max(1, |bound|)``) past a bound is rounding
#: (a fit in log coordinates ends on ``exp(log(bound))``)
BOUND_SLACK = 1e-9


def file_issue(path: Path, message: str, field: str = "") -> InputFileError:
    """One problem with the file ``path`` (no line: JSON files are read whole)."""
    return InputFileError([InputIssue(str(path), None, field, message)])


def is_number(value: Any) -> bool:
    """A finite JSON number (``true`` and ``false`` are not numbers)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _cut(text: str) -> str:
    """``text`` cut to 40 characters (the last three ``...``)."""
    return text if len(text) <= 40 else text[:37] + "..."


def _shown(value: Any) -> str:
    """A JSON value in a message, cut to 40 characters."""
    return _cut(repr(value))


@dataclass
class ParamsFile:
    """A parameter file as read: the ``labrig fit`` output (``doc``; ``None`` for a bare
    ``ModelParams`` object) and the model parameters it holds, validated."""

    path: Path
    doc: dict[str, Any] | None
    params: ModelParams


def refuse_baseline(doc: dict[str, Any], path: Path, who: str) -> None:
    """An :class:`InputFileError` when the ``labrig fit`` output ``doc`` is a baseline's."""
    if doc.get("method") in KINDS:
        raise file_issue(
            path,
            f"holds a {doc['method']} baseline; {who} needs the model's parameters "
            "(labrig fit without --model)",
            "method",
        )


def read_params_file(path: Path, who: str, *, bare_ok: bool = False) -> ParamsFile:
    """Read and check a parameter file for the command ``who`` (named in the messages).

    ``bare_ok``: a bare ``ModelParams`` object is accepted too (else only ``labrig fit``
    output)."""
    try:
        if path.stat().st_size > MAX_PARAMS_BYTES:
            raise file_issue(
                path, f"larger than {MAX_PARAMS_BYTES // 1_000_000} MB: not a parameter file"
            )
        raw = loads_bounded(read_text_bounded(path, MAX_PARAMS_BYTES))
    except FileNotFoundError:
        raise file_issue(path, "parameter file not found") from None
    except JSONLimitError as e:  # a number no parameter file holds, named where it is
        raise file_issue(
            path,
            f"{e.what} ({e.limit}): no parameter file holds such a number; expected a number "
            "as labrig fit writes it (a damaged or edited file?)",
            e.where,
        ) from None
    except (OSError, UnicodeDecodeError, ValueError) as e:  # JSONDecodeError is a ValueError
        raise file_issue(path, f"not a JSON parameter file ({e})") from None
    expected = "the output of labrig fit --json: an object whose 'params' is an object of the "
    expected += "model's parameters"
    if bare_ok:
        expected += " (or that object of parameters itself)"
    if not isinstance(raw, dict):
        raise file_issue(
            path, f"the file holds {_json_what(raw)}, not an object; expected {expected}"
        )
    if "params" in raw and not isinstance(raw["params"], dict):
        raise file_issue(
            path,
            f"{_json_what(raw['params'])}, not an object; expected "
            "the model's parameters by name ({'alpha0_ue_per_V': ..., 'vc_V': ...}, as labrig "
            "fit --json writes them)",
            "params",
        )
    if isinstance(raw.get("params"), dict):
        refuse_baseline(raw, path, who)
        return ParamsFile(path, raw, _model_params(raw["params"], path, "params"))
    if not bare_ok:
        raise file_issue(path, f"no 'params' object; expected {expected}")
    return ParamsFile(path, None, _model_params(raw, path, ""))


def _json_what(value: Any) -> str:
    """What a JSON value that is not an object is, in words, with the value as JSON spells it
    (cut to 40 characters): ``a list ([1, 2])``, ``null``."""
    if value is None:
        return "null"
    kind = {list: "a list", str: "a string", bool: "a boolean"}.get(type(value), "a number")
    text = json.dumps(value)
    return f"{kind} ({_cut(text)})"


def _model_params(raw: Any, path: Path, field: str) -> ModelParams:
    try:
        return ModelParams.model_validate(raw)
    except ValidationError as e:
        why = "; ".join(
            f"{'.'.join(map(str, x['loc'])) or field or 'the parameters'}: {x['msg']}"
            for x in e.errors()
        )
        raise file_issue(path, f"invalid model parameters: {why}", field) from None


def read_fit_output(path: Path) -> dict[str, Any]:
    """The ``labrig fit --json`` output in ``path`` for ``labrig report --params``: the model's
    parameters checked, every other section the report uses (:func:`fit_output_issues`), and
    the names of the effects fitted with them (their parameters are checked with the records,
    :func:`fitted_effects`)."""
    doc = read_params_file(path, "the report").doc
    assert doc is not None  # bare_ok=False
    issues = fit_output_issues(doc, path)
    if issues:
        raise InputFileError(issues)
    fitted_effects(doc, path, check_params=False)
    return doc


def fit_output_issues(doc: dict[str, Any], path: Path) -> list[InputIssue]:
    """What in the sections of a ``labrig fit`` output besides ``params`` and ``effects`` the
    report cannot use, each problem naming its field and what would be valid. Every section may
    be absent or ``null`` (a baseline's or an effects fit's file has no ``correlation`` nor
    ``identifiability``; a file written by hand may hold ``params`` alone)."""
    found: list[tuple[str, str]] = []
    for key, check in _SECTIONS.items():
        if doc.get(key) is not None:
            found += check(doc[key], key)
    return [InputIssue(str(path), None, fld, msg) for fld, msg in found]


def _uncertainty(value: Any, key: str) -> list[tuple[str, str]]:
    """``uncertainty``: parameter -> its 1 sigma (>= 0; ``null``: held fixed or not
    determined). The names are not checked: the report shows the model's and ignores others."""
    if not isinstance(value, dict):
        return [_not_a(key, value, "{parameter: 1 sigma}", "is not an object")]
    expected = (
        "a standard uncertainty >= 0, in the parameter's unit (null for one held fixed or not "
        "determined)"
    )
    return [
        _not_a(f"{key}.{name}", sd, expected, "is negative" if is_number(sd) else "")
        for name, sd in value.items()
        if sd is not None and not (is_number(sd) and sd >= 0)
    ]


def _not_a(field: str, value: Any, expected: str, what: str = "") -> tuple[str, str]:
    """The issue of a field whose ``value`` is not what it should be: ``(field, "VALUE is not
    a number; expected EXPECTED")`` (``what`` in place of "is not a number")."""
    return field, f"{_shown(value)} {what or 'is not a number'}; expected {expected}"


def _correlation(value: Any, key: str) -> list[tuple[str, str]]:
    """``correlation``: parameter -> parameter -> a number (-1 to 1 but for rounding)."""
    if not isinstance(value, dict):
        return [_not_a(key, value, "{parameter: {parameter: r}}", "is not an object")]
    out = []
    for name, row in value.items():
        if not isinstance(row, dict):
            out.append((f"{key}.{name}", f"{_shown(row)} is not an object of correlations"))
            continue
        for other, r in row.items():
            # not bounded to +-1: on data that barely determine a parameter, files of earlier
            # labrig fits hold up to 1.04 (rounding); the report flags any |r| over 0.99
            if not is_number(r):
                out.append(
                    _not_a(
                        f"{key}.{name}.{other}", r, "the correlation of the two estimates (-1 to 1)"
                    )
                )
    return out


def _identifiability(value: Any, key: str) -> list[tuple[str, str]]:
    """``identifiability``: an object whose ``unidentifiable`` maps parameters to texts (the
    fit's judgement) and whose ``loop`` (``null`` for the linear shape) holds numbers (``*_sd``
    may be ``null``), its stroke ``span_V`` above 0 V."""
    if not isinstance(value, dict):
        return [_not_a(key, value, "{rule, unidentifiable, loop}", "is not an object")]
    judged = value.get("unidentifiable", {})
    if not isinstance(judged, dict) or not all(isinstance(v, str) for v in judged.values()):
        return [
            (
                f"{key}.unidentifiable",
                f"{_shown(judged)} is not an object of texts; expected parameter -> why it is "
                "unidentifiable (labrig fit writes it)",
            )
        ]
    loop = value.get("loop")
    if loop is None:
        return []
    if not isinstance(loop, dict):
        expected = "span_V (V), loop_width_ue and loop_curvature with their *_sd, or null"
        return [_not_a(f"{key}.loop", loop, expected, "is not an object")]
    out = []
    for name, v in loop.items():
        if v is None and name != "span_V":
            continue
        if not is_number(v) or (name == "span_V" and v <= 0):
            out.append(
                (
                    f"{key}.loop.{name}",
                    f"{_shown(v)} is not a "
                    + ("voltage above 0 V (the loop's stroke)" if name == "span_V" else "number"),
                )
            )
    return out


def _nrmse(value: Any, key: str) -> list[tuple[str, str]]:
    """An NRMSE: a number >= 0 (%)."""
    if is_number(value) and value >= 0:
        return []
    return [(key, f"{_shown(value)} is not an NRMSE; expected a number >= 0 (%) or null")]


def _text(value: Any, key: str) -> list[tuple[str, str]]:
    """A string (``method``: how the parameters were fitted)."""
    if isinstance(value, str):
        return []
    return [(key, f"{_shown(value)} is not a string; expected the fit's method, e.g. 'global'")]


def _names(value: Any, key: str) -> list[tuple[str, str]]:
    """A non-empty list of distinct non-empty strings (``entries``, ``train_files``)."""
    what = "entry names" if key == "entries" else "run file paths"
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(v, str) and v for v in value)
        or len(set(value)) != len(value)
    ):
        return [(key, f"{_shown(value)}: expected a list of distinct {what}, each a string")]
    return []


_SECTIONS: dict[str, Callable[[Any, str], list[tuple[str, str]]]] = {
    "uncertainty": _uncertainty,
    "correlation": _correlation,
    "identifiability": _identifiability,
    "heldout_nrmse_pct": _nrmse,
    "method": _text,
    "entries": _names,
    "train_files": _names,
}


def start_params(path: Path, say: Callable[[str], None] = print) -> ModelParams:
    """``labrig diagnose --params``: the start parameters of a ``ModelParams`` object or of a
    ``labrig fit --json`` file.

    Only the dynamic model's parameters are used: effects fitted with ``labrig fit --effect``
    are announced through ``say`` as not used (diagnose starts from the base and tests every
    effect itself, so it can say whether each one pays)."""
    pf = read_params_file(path, "diagnose", bare_ok=True)
    effects = (pf.doc or {}).get("effects") or []
    if effects:
        names = [e.get("effect", "?") if isinstance(e, dict) else str(e) for e in effects]
        say(
            f"{path}: using the base parameters only; its effects ({', '.join(names)}) "
            "are tested again, not assumed"
        )
    return pf.params


def fitted_effects(
    doc: dict[str, Any], path: Path, records: Sequence[Record] = (), check_params: bool = True
) -> tuple[list[Effect], dict[str, dict[str, float]]]:
    """The library effects of a ``labrig fit --effect`` file and their parameters (checked),
    configured as when they were fitted (the file's ``effects_context``; else from ``records``;
    a file without either can only have its names checked: ``check_params=False``)."""
    from labrig.analysis.extended import effect_context
    from labrig.analysis.fit_effects import resolve_effects

    listed = doc.get("effects") or []
    if not isinstance(listed, list) or not all(
        isinstance(e, dict) and isinstance(e.get("params"), dict) for e in listed
    ):
        raise file_issue(path, "'effects' must be a list of {effect, params} objects", "effects")
    context = doc.get("effects_context")
    if context is None and records:
        context = effect_context(records)
    if context is not None and not _is_context(context):
        raise file_issue(
            path,
            f"'effects_context' must have {', '.join(CONTEXT_TYPES)} (as labrig fit writes it)",
            "effects_context",
        )
    try:
        effects = resolve_effects([str(e.get("effect")) for e in listed], context)
    except ValueError as e:
        raise file_issue(path, str(e), "effects") from None
    values: dict[str, dict[str, float]] = {}
    if not check_params:
        return effects, values
    issues: list[InputIssue] = []
    for i, (eff, item) in enumerate(zip(effects, listed, strict=True)):
        want = [q.name for q in eff.params]
        p = item["params"]
        if sorted(p) != sorted(want) or not all(is_number(p[k]) for k in want):
            raise file_issue(
                path, f"{eff.name} needs numeric params {', '.join(want)}", f"effects[{i}].params"
            )
        issues += [
            InputIssue(str(path), None, f"effects[{i}].params.{q.name}", why)
            for q in eff.params
            if (why := _outside(eff.name, q, p[q.name]))
        ]
        values[eff.name] = {k: float(p[k]) for k in want}
    if issues:
        raise InputFileError(issues)
    return effects, values


def _outside(effect: str, q: Param, value: float) -> str:
    """Why ``value`` is not a value of the effect's parameter ``q`` (outside the bounds it
    declares, which its fit keeps to), or ``""``."""
    lo = q.lo - BOUND_SLACK * max(1.0, abs(q.lo))
    hi = q.hi + BOUND_SLACK * max(1.0, abs(q.hi))
    if lo <= value <= hi:
        return ""
    unit = f" {q.unit}" if q.unit else ""
    return (
        f"{value:g} is outside {effect}'s range for {q.name}: {q.lo:g} to {q.hi:g}{unit} "
        "(the bounds its fit keeps to)"
    )


def _is_context(context: Any) -> bool:
    """``effects_context`` as ``labrig fit`` writes it (an int is a float here)."""
    return (
        isinstance(context, dict)
        and set(CONTEXT_TYPES) - CONTEXT_ADDED_LATER <= set(context) <= set(CONTEXT_TYPES)
        and all(
            isinstance(context[k], t) or (t is float and isinstance(context[k], int))
            for k, t in CONTEXT_TYPES.items()
            if k in context
        )
    )
