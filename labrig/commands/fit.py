"""Fitting a prepared run file (:class:`~labrig.commands.prepare.Setup`) as ``labrig fit`` and
``labrig report`` ask: our model (:func:`fit_dynamic`), a rate-independent baseline
(:func:`fit_base`), the model with library effects (:func:`fit_with_effects`), and the whole
``fit`` command (:func:`fit_run_file`).

A fit that cannot be done is an :class:`~labrig.commands.prepare.AnalysisError` (exit code 2)
naming the file. What a command shows while it works goes through a :class:`CommandUI` (the
command line draws progress bars; :class:`QuietUI` shows nothing).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from labrig.analysis.baselines import KINDS, BaselineResult, fit_baseline
from labrig.analysis.fit import FitResult, fit_model
from labrig.commands.prepare import AnalysisError, Setup, prepare
from labrig.model.effects import Effect
from labrig.store import RunFile

if TYPE_CHECKING:  # the effect library (and scipy.signal) only when --effect asks for it
    from labrig.analysis.fit_effects import EffectsFit

#: ``progress(stage, done, total)``; stages: ``model:fit``, ``model:<heldout stage>``, a
#: baseline's kind, ``effects:<stage>`` of :func:`labrig.analysis.fit_effects.fit_effects`
Progress = Callable[[str, int, int], None]
#: what ``fit --model`` accepts: our model, then the baselines
MODELS: tuple[str, ...] = ("dynamic", *KINDS)
BASELINE_LABELS = {
    "prandtl_ishlinskii": "Prandtl-Ishlinskii",
    "bouc_wen": "Bouc-Wen",
    "sindy": "SINDy",
}


class CommandUI(Protocol):
    """What an analysis command shows while it works."""

    def announce(self, setup: Setup) -> None:
        """The records are read: how they will be fitted (before any fit)."""

    def fitting(self) -> AbstractContextManager[Progress]:
        """A context around the fits, giving the ``progress`` callback they report to."""

    def busy(self, what: str) -> AbstractContextManager[None]:
        """A context around a slow step without progress of its own (``what`` names it)."""


class QuietUI:
    """A :class:`CommandUI` that shows nothing."""

    def announce(self, setup: Setup) -> None:
        pass

    @contextmanager
    def fitting(self) -> Iterator[Progress]:
        yield lambda stage, done, total: None

    @contextmanager
    def busy(self, what: str) -> Iterator[None]:
        yield


def fit_dynamic(
    setup: Setup,
    method: str,
    heldout: bool,
    progress: Progress | None,
    memory: str = "return_point",
) -> FitResult:
    """Our model fitted to ``setup`` (:func:`labrig.analysis.fit.fit_model`)."""

    def cb(stage: str, done: int, total: int) -> None:
        if progress is not None:
            progress(f"model:{stage}", done, total)

    try:
        return fit_model(
            setup.records,
            method=method,
            memory=memory,
            heldout=heldout,
            warmup_s=setup.warmup_s,
            progress=cb if progress is not None else None,
            chain=setup.chain,
            scored=setup.scored,
            offset=setup.offset,
        )
    except (ValueError, RuntimeError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the model: {e}") from None


def fit_base(setup: Setup, kind: str, heldout: bool, progress: Progress | None) -> BaselineResult:
    """The baseline ``kind`` (:data:`~labrig.analysis.baselines.KINDS`) fitted to ``setup``."""
    label = BASELINE_LABELS[kind]
    if progress is not None:
        progress(kind, 0, 1)
    try:
        res = fit_baseline(
            setup.records,
            kind,
            heldout=heldout,
            warmup_s=setup.warmup_s,
            chain=setup.chain,
            scored=setup.scored,
            offset=setup.offset,
        )
    except (ValueError, RuntimeError, FloatingPointError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the {label} baseline: {e}") from None
    if progress is not None:
        progress(kind, 1, 1)
    return res


def fit_with_effects(
    setup: Setup,
    base: FitResult,
    effects: Sequence[str | Effect],
    heldout: bool,
    progress: Progress | None,
) -> EffectsFit:
    """``--effect``: the base fit refitted with the named effects (or effects given as
    objects: :func:`labrig.analysis.fit_effects.fit_effects`)."""
    from labrig.analysis.fit_effects import fit_effects

    def cb(stage: str, done: int, total: int) -> None:
        if progress is not None:
            progress(f"effects:{stage}", done, total)

    try:
        return fit_effects(
            setup.records,
            base,
            effects,
            chain=setup.chain,
            scored=setup.scored,
            warmup_s=setup.warmup_s,
            offset=setup.offset,
            heldout=heldout,
            progress=cb if progress is not None else None,
        )
    except (ValueError, RuntimeError) as e:
        raise AnalysisError(f"{setup.path}: cannot fit the model with effects: {e}") from None


@dataclass
class FitOutcome:
    """What ``labrig fit`` found: the records as fitted and the result."""

    setup: Setup
    result: FitResult | BaselineResult | EffectsFit


def fit_run_file(
    path: Path,
    *,
    entries: list[str] | None = None,
    method: str = "global",
    model: str = "dynamic",
    memory: str = "return_point",
    effects: Sequence[str] = (),
    warmup_s: float | None = None,
    heldout: bool = True,
    offset: bool | None = None,
    ui: CommandUI | None = None,
    run: RunFile | None = None,
) -> FitOutcome:
    """``labrig fit``: read the run file (:func:`~labrig.commands.prepare.prepare`; ``run``:
    as already read) and fit ``model`` (one of :data:`MODELS`) to it; with ``effects`` our
    model is fitted first, then refitted with them (held-out scores only for the refit)."""
    ui = ui or QuietUI()
    if model not in MODELS:
        raise AnalysisError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    if effects and model != "dynamic":
        raise AnalysisError(f"--effect applies to the dynamic model, not to --model {model}")
    if effects:  # the effect library is imported only when asked for (scipy.signal: ~1.5 s)
        from labrig.analysis.fit_effects import resolve_effects

        try:
            resolve_effects(effects)  # before any fitting
        except ValueError as e:
            raise AnalysisError(f"--effect {e}") from None
    setup = prepare(path, entries, warmup_s, offset, run=run)
    ui.announce(setup)
    with ui.fitting() as progress:
        if model == "dynamic":
            res: FitResult | BaselineResult | EffectsFit = fit_dynamic(
                setup, method, heldout and not effects, progress, memory
            )
            if effects:
                res = fit_with_effects(setup, res, effects, heldout, progress)
        else:
            res = fit_base(setup, model, heldout, progress)
    if not isinstance(res, BaselineResult):  # our model, with or without effects
        res.train_files = [str(Path(path).resolve())]
    return FitOutcome(setup, res)
