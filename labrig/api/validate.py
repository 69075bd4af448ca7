"""``labrig.validate(train, on=test)``: ``labrig validate`` from Python
(:func:`labrig.commands.validate.validate_runs`, the call the command makes)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from labrig.commands.validate import Validation

PathLike = str | os.PathLike[str]

__all__ = ["validate"]


def _paths(files: Any) -> list[Path]:
    """One file or several: paths, or runs opened by :func:`labrig.open` (their ``path``)."""
    if isinstance(files, str | os.PathLike) or hasattr(files, "path"):
        files = [files]
    return [Path(getattr(f, "path", f)) for f in files]


def validate(
    train: PathLike | Sequence[PathLike] | Any,
    on: PathLike | Sequence[PathLike] | Any,
    *,
    effects_from: PathLike | None = None,
    diagnose: bool = False,
    method: str = "global",
    warmup_s: float | None = None,
    offset: bool | None = None,
    out: PathLike | None = None,
    overwrite: bool = False,
    page: bool = False,
    progress: bool = False,
) -> Validation:
    """``labrig validate TRAIN... --on TEST...``: every model identified on ``train`` (run
    files, or runs from :func:`labrig.open`), scored on ``on`` by one rule. ``as_json(result)``
    is what ``labrig validate --json`` prints; ``result.models[key].predictions`` each model's
    strain for each ``(test file, entry)``; ``out``: the HTML page (``page``: draw it into
    ``result.page`` without writing it). The options are the command's (docs/validate.md).

    Parameters
    ----------
    train, on : path, run, or a sequence of them
        The training records and the test records (run files, or runs from
        :func:`labrig.open`); a file in both is refused.
    effects_from : path, optional
        A ``labrig diagnose`` JSON whose accepted effects are refitted on ``train``.
    diagnose : bool
        Diagnose ``train`` first and use what it accepts (not with ``effects_from``).
    method : str
        Our model's fit method: ``"global"`` or ``"staged"``.
    warmup_s : float, optional
        Seconds left out at the start of each entry (s); default: the command's.
    offset : bool, optional
        Fit one strain offset per entry (default: for imported data).
    out : path, optional
        Where to write the HTML page.
    overwrite : bool
        Replace an existing ``out``.
    page : bool
        Draw the page into ``result.page`` without writing it.
    progress : bool
        Progress bars on stderr.

    Returns
    -------
    Validation
        Every model's scores (whole record and second half, NRMSE %) and predictions.
    """
    from labrig.api.runs import command_ui
    from labrig.commands.validate import validate_runs

    return validate_runs(
        _paths(train),
        _paths(on),
        effects_from=None if effects_from is None else Path(effects_from),
        run_diagnosis=diagnose,
        method=method,
        warmup_s=warmup_s,
        offset=offset,
        ui=command_ui(progress),
        page=page,
        out=None if out is None else Path(out),
        overwrite=overwrite,
    )
