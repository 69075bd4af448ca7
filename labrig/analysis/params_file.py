"""Parameter files given to ``labrig report --params`` and ``labrig diagnose --params``: the one
reader of them.

A parameter file is what ``labrig fit --json`` / ``--out`` writes: an object with ``params``
(the dynamic model's :class:`~labrig.model.ModelParams`), ``method``, the scores, and with
``--effect`` the ``effects`` fitted with the model and the ``effects_context`` they were
configured with. ``diagnose`` also takes a bare ``ModelParams`` object. A baseline's file
(``labrig fit --model prandtl_ishlinskii``) holds no model parameters and is refused.

Every problem is an :class:`~labrig.core.errors.InputFileError` (exit code 2) naming the file, the
field and what would be valid; the file is read within bounds (:data:`MAX_PARAMS_BYTES`,
:func:`labrig.core.jsonsafe.loads_bounded`: nesting, digits).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from labrig.analysis.baselines import KINDS
from labrig.analysis.records import Record
from labrig.core.errors import InputFileError, InputIssue
from labrig.core.jsonsafe import loads_bounded
from labrig.core.textfile import read_text_bounded
from labrig.model import ModelParams
from labrig.model.effects import Effect, RunContext

#: the largest parameter file read (``labrig fit`` writes a few kB)
MAX_PARAMS_BYTES = 10_000_000

#: the types of ``effects_context`` (how the effects were configured when they were fitted)
CONTEXT_TYPES: dict[str, type] = RunContext.types()
#: ``effects_context`` fields added after files were first written: a file may lack them (the
#: effects then take :class:`RunContext`'s default)
CONTEXT_ADDED_LATER: frozenset[str] = frozenset({"rate_hz"})


def file_issue(path: Path, message: str, field: str = "") -> InputFileError:
    """One problem with the file ``path`` (no line: JSON files are read whole)."""
    return InputFileError([InputIssue(str(path), None, field, message)])


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
    except (OSError, UnicodeDecodeError, ValueError) as e:  # JSONDecodeError is a ValueError
        raise file_issue(path, f"not a JSON parameter file ({e})") from None
    if isinstance(raw, dict) and isinstance(raw.get("params"), dict):
        refuse_baseline(raw, path, who)
        return ParamsFile(path, raw, _model_params(raw["params"], path, "params"))
    if not bare_ok:
        raise file_issue(path, "no 'params' object (expected the output of labrig fit --json)")
    return ParamsFile(path, None, _model_params(raw, path, ""))


def _model_params(raw: Any, path: Path, field: str) -> ModelParams:
    try:
        return ModelParams.model_validate(raw)
    except ValidationError as e:
        why = "; ".join(f"{'.'.join(map(str, x['loc']))}: {x['msg']}" for x in e.errors())
        raise file_issue(path, f"invalid model parameters: {why}", field) from None


def read_fit_output(path: Path) -> dict[str, Any]:
    """The ``labrig fit --json`` output in ``path`` for ``labrig report --params``: the model's
    parameters checked, and the names of the effects fitted with them (their parameters are
    checked with the records, :func:`fitted_effects`)."""
    doc = read_params_file(path, "the report").doc
    assert doc is not None  # bare_ok=False
    fitted_effects(doc, path, check_params=False)
    return doc


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
    for eff, item in zip(effects, listed, strict=True):
        want = [q.name for q in eff.params]
        p = item["params"]
        if sorted(p) != sorted(want) or not all(
            isinstance(p[k], int | float) and math.isfinite(p[k]) for k in want
        ):
            raise file_issue(path, f"{eff.name} needs numeric params {', '.join(want)}", "effects")
        values[eff.name] = {k: float(p[k]) for k in want}
    return effects, values


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
