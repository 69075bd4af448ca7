"""``labrig diagnose RUN`` as one library call, for the command, the Python API and the batch
tasks: read the run file (:func:`labrig.commands.prepare.prepare_diagnosis`), diagnose it
with the default candidates and the structural effects asked for
(:func:`labrig.analysis.diagnose.diagnose`), and render or write its outputs,
``diagnosis.json`` (the JSON contract, docs/diagnose.md) and ``diagnosis.html``.

Outputs in a folder are checked before the work (an input, an existing file without
``overwrite``, a place that cannot be written: :class:`~labrig.core.errors.InputFileError`) and
written beside their targets, then renamed into place (:mod:`labrig.core.outputs`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labrig.analysis import diagnose as diagnosis
from labrig.analysis.diagnose import Diagnosis
from labrig.analysis.records import Record
from labrig.commands.prepare import prepare_diagnosis
from labrig.core.jsonsafe import json_safe
from labrig.core.outputs import staged_outputs
from labrig.model.effects import EFFECT_NAMES, STRUCTURAL_EFFECT_NAMES
from labrig.store import RunFile

if TYPE_CHECKING:
    from labrig.analysis.fit import FitResult

__all__ = ["OUTPUT_NAMES", "RunDiagnosis", "diagnose_run_file"]

#: what a diagnosis writes in its folder
OUTPUT_NAMES = ("diagnosis.json", "diagnosis.html")

Say = Callable[[str], Any]


def _quiet(_message: str) -> None:
    pass


@dataclass
class RunDiagnosis:
    """A run file's diagnosis: its path, the records diagnosed (after
    :func:`~labrig.commands.prepare.prepare_diagnosis`), the structural effects tried beside the
    defaults, the :class:`~labrig.analysis.diagnose.Diagnosis`, and the folder its outputs
    were written to (``None`` when not written)."""

    path: Path
    records: list[Record]
    also: tuple[str, ...]
    diagnosis: Diagnosis
    written: list[Path] = field(default_factory=list)

    @property
    def document(self) -> dict[str, Any]:
        """The JSON contract (``labrig diagnose --json``; undefined numbers ``None``)."""
        return json_safe(self.diagnosis.to_json())

    @property
    def title(self) -> str:
        return f"labrig diagnose: {self.path.name}"

    def untried(self) -> list[str]:
        """Structural effects that were not tried (neither default candidates nor asked for)."""
        return [n for n in STRUCTURAL_EFFECT_NAMES if n not in self.also and n not in EFFECT_NAMES]

    def hint(self) -> str | None:
        """How to try the untried structural effects, when the verdict leaves room for them."""
        untried = self.untried()
        if not untried or self.diagnosis.classification not in (
            "unexplained",
            "partially_explained",
        ):
            return None
        return (
            f"hint: the structural effects {', '.join(untried)} were not tried; "
            f"`labrig diagnose {self.path.name} "
            + " ".join(f"--also {n}" for n in untried)
            + " --max-effects 3` tries them (slower)"
        )

    def documents(self) -> dict[str, str]:
        """The outputs by file name (:data:`OUTPUT_NAMES`) as text."""
        from labrig.report.diagnose_html import render_diagnosis

        return {
            "diagnosis.json": json.dumps(self.document, indent=2) + "\n",
            "diagnosis.html": render_diagnosis(self.diagnosis, self.records, title=self.title),
        }


def diagnose_run_file(
    path: Path,
    params_file: Path | None = None,
    *,
    also: Sequence[str] = (),
    max_effects: int = 2,
    mains_hz: float | None = None,
    out: Path | None = None,
    overwrite: bool = False,
    say: Say = _quiet,
    progress: Say | None = None,
    workers: int = 1,
    snapshot: RunFile | None = None,
    base_fit: FitResult | None = None,
) -> RunDiagnosis:
    """Diagnose the run file ``path`` (module docstring).

    ``params_file``: start parameters (``ModelParams`` JSON or ``labrig fit`` output);
    ``also``: structural effects tried beside :data:`~labrig.model.effects.EFFECT_NAMES`;
    ``max_effects``: at most this many effects added; ``mains_hz``: the mains frequency (Hz;
    default: the line the strain shows at 50 or 60 Hz); ``out``: a folder for
    :data:`OUTPUT_NAMES` (replaced only with ``overwrite``); ``say``: notes (a file of one
    entry cut into parts, parameters not used); ``progress``: the diagnosis' steps;
    ``workers``: processes for its folds and candidates (the result does not depend on it);
    ``snapshot``: the file as already read (one snapshot for the fit and the diagnosis of
    ``batch``); ``base_fit``: our model already fitted to the same snapshot (``labrig fit``'s
    result), used as the diagnosis' base fit when it was made as the diagnosis would make it
    (:func:`~labrig.analysis.diagnose.procedure.base_fit_reusable`), so ``batch diagnose``
    fits the base once per run; the diagnosis is the same either way."""
    path = Path(path)
    also = tuple(dict.fromkeys(also))

    def run() -> RunDiagnosis:
        setup = prepare_diagnosis(path, params_file, say, snapshot)
        d = diagnosis.diagnose(  # looked up at each call (tests replace it)
            setup.records,
            setup.start,
            offset=setup.offset,
            effects=EFFECT_NAMES + also,
            max_effects=max_effects,
            mains_hz=mains_hz,
            always=also,
            progress=progress,
            workers=workers,
            base_fit=base_fit,
        )
        return RunDiagnosis(path, setup.records, also, d)

    if out is None:
        return run()
    out = Path(out)
    targets = [out / n for n in OUTPUT_NAMES]
    with staged_outputs(targets, inputs=[path, params_file], overwrite=overwrite) as staged:
        result = run()
        for name, text in result.documents().items():
            staged.write_text(out / name, text)
    result.written = targets
    return result
