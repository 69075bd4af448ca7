"""``labrig validate TRAIN... --on TEST...`` as one library call (:func:`validate_runs`), for the
command line and the Python API (``labrig.validate``).

Every model is identified on the **training** records and predicts the **test** records, which
no fit has seen:

- ``dynamic``: our model (:func:`~labrig.commands.fit.fit_dynamic`);
- ``dynamic+effects``: our model refitted on the training records with the effects
  ``labrig diagnose`` accepted on them (a ``diagnosis.json`` given with ``effects_from``, or
  a diagnosis run now with ``run_diagnosis``; :func:`~labrig.commands.fit.fit_with_effects`);
  when the diagnosis adopted its empirical sparse ODE (``sparse_ode``, an alternative base in
  place of the model), that ODE with its coefficients, run free from rest as the diagnosis runs
  it, and labelled EMPIRICAL (:func:`sparse_ode_row`);
- the peers Prandtl-Ishlinskii, Bouc-Wen and SINDy (:func:`~labrig.commands.fit.fit_base`),
  on the same training records with the same chain, warm-up and offsets.

**One scoring rule for every model** (:func:`score_entry`), on each scored test entry after its
warm-up: the model's own strain ``p`` (:func:`~labrig.commands.report.predict_entries` with
``raw``, :meth:`~labrig.analysis.baselines.BaselineResult.simulate`) plus its per-entry nuisance
terms ``C c`` (a constant offset when the test data get one, as ``labrig fit`` decides, and the
columns of any nuisance effect diagnose accepted) fitted by least squares:

- **whole record**: ``c`` fitted on every scored sample, ``NRMSE = 100 RMS(m - p - C c) /
  (max m - min m)``;
- **second half**: ``c`` fitted on the first half only, the error taken on the second half,
  in percent of the whole entry's span (:func:`~labrig.analysis.metrics.second_half_nrmse_pct`;
  the held-out score of ``labrig diagnose``).

The noise floor (the NRMSE of a perfect model) is the period-to-period scatter of our model's
residual on the test records (:func:`~labrig.analysis.noise_floor.noise_floor`, the estimator
of every command).

Several training files are fitted together when each entry is simulated on its own (imported
data); a recorded run is one chain and is the only training (or test) file of its side. A file
given both as training and as test data, or twice, is refused (exit code 2), and so is a test
record whose samples are contained in a training record, or contain one (:func:`check_unseen`;
with ``--leave-one-out``, two of the files that share a record, before any fit:
:func:`check_distinct_records`).

**Leave one record out** (:func:`validate_leave_one_out`, ``--leave-one-out FILE...``): of N
files, each in turn is the test file and the other N - 1 are the training files; every model
is identified anew in each fold, so each record is predicted by models that never saw it. The
summary per model is the mean over the folds (every file weighs the same).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.baselines import KINDS, BaselineResult
from labrig.analysis.diagnose.sparse_ode import NAME as SPARSE_ODE
from labrig.analysis.diagnose.sparse_ode import (
    SparseOdeEffect,
    equation_text,
    model_from_params,
)
from labrig.analysis.metrics import nrmse_pct, second_half_nrmse_pct
from labrig.analysis.records import Record
from labrig.commands.fit import (
    BASELINE_LABELS,
    CommandUI,
    QuietUI,
    fit_base,
    fit_dynamic,
    fit_with_effects,
)
from labrig.commands.prepare import (
    AnalysisError,
    Setup,
    prepare,
    training_setup,
    unit_issues,
)
from labrig.core.errors import InputFileError, InputIssue
from labrig.core.jsonsafe import json_safe
from labrig.core.outputs import same_file
from labrig.core.samples import EXPORT_ROUNDING, contained_at
from labrig.model import ModelParams
from labrig.model.effects import Effect

__all__ = [
    "MODEL_LABELS",
    "SCORING",
    "LeaveOneOut",
    "ValidatedModel",
    "Validation",
    "accepted_effects",
    "score_entry",
    "sparse_ode_row",
    "validate_leave_one_out",
    "validate_runs",
]

#: the models ``validate`` scores, in the order it shows them, with their labels
MODEL_LABELS: dict[str, str] = {
    "dynamic": "ours",
    "dynamic+effects": "ours + diagnose's effects",
    **BASELINE_LABELS,
}
#: the scoring rule, in words (the JSON's ``scoring``, the page's)
SCORING = (
    "identified on the training records only; each test entry predicted from rest (a recorded "
    "run: its entries chained with their rests), its warm-up not scored; per-entry nuisance "
    "terms (a constant offset where the data get one, and any nuisance effect diagnose "
    "accepted) fitted by least squares on the whole scored record (whole) or on its first half "
    "(second half: error on the second half); NRMSE in % of the entry's measured span"
)
#: a diagnosis' parameter names of empirical terms start with this
_TERM_PREFIX = "c_"
#: how far a training rate may be from a whole multiple of a sparse ODE's working rate (relative)
RATE_TOLERANCE = 1e-9
#: the tolerance of :func:`check_unseen`, in words
_ROUNDING_WORDS = (
    f"voltage and strain equal to within the rounding of `labrig export`, {EXPORT_ROUNDING:.1g} "
    "of each value"
)


@dataclass
class EntryScore:
    """One test entry scored for one model: NRMSE (%) on the whole record and on its second
    half (nuisance terms from the first half)."""

    file: str
    entry: str
    whole_nrmse_pct: float
    second_half_nrmse_pct: float


@dataclass
class ValidatedModel:
    """A model identified on the training records and scored on the test records.

    ``predictions``: ``(test file, entry) -> strain`` (ue) over the whole record, the model's
    own strain without any offset or nuisance term (what :func:`score_entry` scores);
    ``note``: why it could not be fitted (then no scores)."""

    key: str
    label: str
    params: dict[str, Any] = field(default_factory=dict)
    scores: list[EntryScore] = field(default_factory=list)
    predictions: dict[tuple[str, str], NDArray[np.float64]] = field(
        default_factory=dict, repr=False
    )
    nuisance: list[Effect] = field(default_factory=list, repr=False)
    note: str | None = None

    def mean(self, which: str) -> float | None:
        """The mean over the test entries of ``whole_nrmse_pct`` or ``second_half_nrmse_pct``."""
        vals = [getattr(s, which) for s in self.scores]
        return float(np.mean(vals)) if vals else None

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "whole_nrmse_pct": self.mean("whole_nrmse_pct"),
            "second_half_nrmse_pct": self.mean("second_half_nrmse_pct"),
            "per_entry": [dataclasses.asdict(s) for s in self.scores],
            "params": self.params,
            "note": self.note,
        }


@dataclass
class Validation:
    """What ``labrig validate`` found (module docstring); :meth:`to_json` is ``--json``."""

    train: list[Path]
    test: list[Path]
    train_setup: Setup
    tests: list[Setup]
    models: dict[str, ValidatedModel]
    noise_floor_pct: float | None
    noise_source: str
    effects: list[str] | None  # what diagnose accepted (None: not asked for)
    effects_source: str
    notes: list[str] = field(default_factory=list)
    page: str = ""

    def to_json(self) -> dict[str, Any]:
        return json_safe(
            {
                "train": [str(p) for p in self.train],
                "test": [str(p) for p in self.test],
                "train_entries": list(self.train_setup.scored),
                "scoring": SCORING,
                "noise_floor_pct": self.noise_floor_pct,
                "noise_floor_source": self.noise_source,
                "effects": self.effects,
                "effects_source": self.effects_source or None,
                "models": {k: m.to_json() for k, m in self.models.items()},
                "notes": list(self.notes),
            }
        )


def _issue(path: Path | str, message: str, fld: str = "") -> InputFileError:
    return InputFileError([InputIssue(str(path), None, fld, message)])


def check_files(train: Sequence[Path], test: Sequence[Path]) -> None:
    """At least one file on each side, and no file twice (the same file on both sides, or twice
    on one side, whatever its spelling: :func:`~labrig.core.outputs.same_file`)."""
    if not train:
        raise _issue("TRAIN", "no training file given", "TRAIN")
    if not test:
        raise _issue("--on", "no test file given (--on TEST)", "--on")
    seen: list[tuple[Path, str]] = []
    for p, side in [*((p, "TRAIN") for p in train), *((p, "--on") for p in test)]:
        for q, other in seen:
            if same_file(Path(p), Path(q)):
                if side != other:
                    msg = "given both as training and as test data; a model is validated on "
                    msg += "records it was not identified on: give another file to --on"
                else:
                    msg = f"given twice as {'training' if side == 'TRAIN' else 'test'} data"
                raise _issue(p, msg, side)
        seen.append((Path(p), side))


def with_nuisance(
    measured: NDArray[np.float64],
    predicted: NDArray[np.float64],
    C: NDArray[np.float64],
    upto: int | None = None,
) -> NDArray[np.float64]:
    """``predicted`` plus the nuisance columns ``C`` (samples x k) fitted by least squares to
    ``measured - predicted`` over the first ``upto`` samples (all when ``None``)."""
    p = np.asarray(predicted, dtype=float)
    if not C.shape[1]:
        return p
    n = p.size if upto is None else upto
    coef, *_ = np.linalg.lstsq(C[:n], np.asarray(measured, dtype=float)[:n] - p[:n], rcond=None)
    return p + C @ coef


def score_entry(
    measured: NDArray[np.float64], predicted: NDArray[np.float64], C: NDArray[np.float64]
) -> tuple[float, float]:
    """The scoring rule (module docstring) of one entry's scored samples: ``measured`` and
    ``predicted`` (ue), the nuisance columns ``C`` (samples x k, k may be 0). Returns the
    whole-record and the second-half NRMSE (%)."""
    m = np.asarray(measured, dtype=float)
    whole = with_nuisance(m, predicted, C)
    second = with_nuisance(m, predicted, C, m.size // 2)
    return nrmse_pct(m, whole), second_half_nrmse_pct(m, second)


def nuisance_columns(record: Record, i0: int, offset: bool, effects: Sequence[Effect]) -> NDArray:
    """The per-entry nuisance regressors of ``record`` from sample ``i0``: a constant (offset)
    and the columns of the nuisance ``effects``."""
    t = record.time_s[i0:]
    cols = [np.ones((t.size, 1))] if offset else []
    cols += [e.columns(t, record.rate_hz) for e in effects]
    return np.hstack(cols) if cols else np.zeros((t.size, 0))


def fitted_prediction(model: ValidatedModel, s: Setup, r: Record) -> NDArray[np.float64]:
    """``model``'s prediction of the test entry ``r`` of ``s`` with its nuisance terms fitted on
    the whole scored record (what the whole-record NRMSE scores; the warm-up as simulated)."""
    p = model.predictions[(str(s.path), r.name)]
    i0 = round(max(s.warmup_s, 0.0) * r.rate_hz)
    C = nuisance_columns(r, i0, s.offset, model.nuisance)
    out = np.array(p, dtype=float)
    out[i0:] = with_nuisance(r.strain_ue[i0:], p[i0:], C)
    if i0 and C.shape[1]:
        out[:i0] += out[i0] - p[i0]  # the offset carried into the warm-up, for the figure
    return out


def _score(
    model: ValidatedModel, tests: Sequence[Setup], raw: dict[Path, dict[str, NDArray]]
) -> None:
    """Score ``model``'s raw predictions ``raw`` (test file -> entry -> strain) of every test
    entry by :func:`score_entry`."""
    for s in tests:
        for r in s.scored_records:
            p = raw[s.path][r.name]
            model.predictions[(str(s.path), r.name)] = p
            i0 = round(max(s.warmup_s, 0.0) * r.rate_hz)
            C = nuisance_columns(r, i0, s.offset, model.nuisance)
            w, h = score_entry(r.strain_ue[i0:], p[i0:], C)
            model.scores.append(EntryScore(str(s.path), r.name, w, h))


# -- what diagnose accepted ---------------------------------------------------------------------


def accepted_effects(doc: Any, path: Path | str, records: Sequence[Record]) -> list[Effect]:
    """The effects of a diagnosis (``diagnosis.json``'s ``effects_added``, or
    :meth:`labrig.analysis.diagnose.Diagnosis.to_json`) configured for the training
    ``records``: library effects by name, empirical terms rebuilt from their parameter names
    (``c_<term>``) with the training records' scales, the adopted sparse ODE (at most one) from
    its terms and coefficients (:func:`~labrig.analysis.diagnose.sparse_ode.model_from_params`).
    Anything else is an :class:`~labrig.core.errors.InputFileError` naming the file and the
    field."""
    from labrig.analysis.extended import effect_context
    from labrig.analysis.terms import TermScales, empirical_effect
    from labrig.model.effects import library

    if not isinstance(doc, dict) or not isinstance(doc.get("effects_added"), list):
        raise _issue(
            path,
            "no 'effects_added' list (expected diagnosis.json, as labrig diagnose --out writes it)",
            "effects_added",
        )
    lib = library(**effect_context(records))
    out: list[Effect] = []
    for k, item in enumerate(doc["effects_added"]):
        fld = f"effects_added[{k}]"
        name = item.get("effect") if isinstance(item, dict) else None
        params = item.get("params") if isinstance(item, dict) else None
        if not isinstance(name, str) or not isinstance(params, dict):
            raise _issue(path, "each effect needs an 'effect' name and a 'params' object", fld)
        if name == "empirical_terms":
            keys = [
                p.removeprefix(_TERM_PREFIX)
                for p in params
                if p.startswith(_TERM_PREFIX) and not p.endswith("_sd")
            ]
            try:
                out.append(empirical_effect(keys, TermScales.from_records(records)))
            except ValueError as e:
                raise _issue(path, f"empirical terms: {e}", fld) from None
        elif name == SPARSE_ODE:
            if any(isinstance(e, SparseOdeEffect) for e in out):
                raise _issue(path, f"{SPARSE_ODE} given twice (a diagnosis adopts one)", fld)
            try:
                out.append(SparseOdeEffect(model_from_params(params)))
            except ValueError as e:
                raise _issue(path, f"{SPARSE_ODE}: {e}", fld) from None
        elif name in lib:
            out.append(lib[name])
        else:
            raise _issue(
                path,
                f"{name!r} is not an effect of the library; known: {', '.join(lib)}, "
                f"empirical_terms, {SPARSE_ODE}",
                fld,
            )
    return out


def _read_diagnosis(path: Path) -> Any:
    from labrig.core.jsonsafe import MAX_JSON_BYTES, loads_bounded
    from labrig.core.textfile import read_text_bounded

    try:
        return loads_bounded(read_text_bounded(path, MAX_JSON_BYTES))
    except FileNotFoundError:
        raise _issue(path, "diagnosis file not found", "--effects-from") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise _issue(path, f"not a JSON diagnosis ({e})", "--effects-from") from None


def _diagnose_now(setup: Setup, ui: CommandUI) -> dict[str, Any]:
    """``labrig diagnose`` of the training records (one entry cut into parts, as the command
    does): its JSON."""
    from labrig.analysis import diagnose as diagnosis
    from labrig.analysis.split import split_entries
    from labrig.commands.prepare import DIAGNOSE_SPLIT, MIN_DIAGNOSE_ENTRIES
    from labrig.model.effects import EFFECT_NAMES

    records = setup.scored_records if not setup.chain else list(setup.records)
    if len(records) == 1:
        records = split_entries(records, DIAGNOSE_SPLIT)
    if len(records) < MIN_DIAGNOSE_ENTRIES:
        raise _issue(
            setup.path,
            f"--diagnose needs at least {MIN_DIAGNOSE_ENTRIES} training entries "
            f"(leave-one-entry-out), found {len(records)}",
            "--diagnose",
        )
    with ui.busy("diagnosing the training records"):
        d = diagnosis.diagnose(records, None, offset=setup.offset, effects=EFFECT_NAMES)
    return d.to_json()


# -- the command --------------------------------------------------------------------------------


def _floor(tests: Sequence[Setup], ours: ValidatedModel) -> tuple[float | None, str]:
    """The noise floor of the test records from our model's residual (module docstring) and
    where it comes from."""
    from labrig.analysis.noise_floor import SOURCE, noise_floor

    vals = []
    for s in tests:
        preds = {}
        for r in s.scored_records:
            p = ours.predictions.get((str(s.path), r.name))
            if p is None:
                continue
            i0 = round(max(s.warmup_s, 0.0) * r.rate_hz)
            offset = float(np.mean(r.strain_ue[i0:] - p[i0:])) if s.offset else 0.0
            preds[r.name] = p + offset
        nf = noise_floor(s.scored_records, preds, s.warmup_s)
        if nf is not None:
            vals += [nf.nrmse_pct] * len(preds)
    if not vals:
        return None, "unknown"
    return float(np.mean(vals)), f"{SOURCE} (our model on the test records)"


def _constant(r: Record) -> bool:
    """A record whose voltage and strain are each one value throughout (it holds nothing a
    model could have learnt: such stretches are common to every record at rest)."""
    return r.n > 0 and np.ptp(r.voltage_V) == 0 and np.ptp(r.strain_ue) == 0


def _identical(a: Record, b: Record) -> bool:
    """The same voltage and strain samples, bit for bit."""
    return np.array_equal(a.voltage_V, b.voltage_V) and np.array_equal(a.strain_ue, b.strain_ue)


def _shared(train: Record, test: Record) -> tuple[str, str] | None:
    """How the ``test`` record shares the ``train`` record's samples, in words (a verb and the
    detail in brackets), or ``None``: the same samples (bit for bit, or to within ``labrig
    export``'s rounding), contained in it, or containing it
    (:func:`~labrig.core.samples.contained_at`, voltage and strain together)."""
    a, b = (train.voltage_V, train.strain_ue), (test.voltage_V, test.strain_ue)
    if _identical(train, test):
        return "holds the same samples as", ""
    if not _constant(test) and (k := contained_at(a, b)) is not None:
        if train.n == test.n:
            return "holds the same samples as", f" ({_ROUNDING_WORDS})"
        where = f"its samples are that record's samples {k} to {k + test.n - 1} of {train.n}"
        return "is contained in", f" ({where}, {_ROUNDING_WORDS})"
    if not _constant(train) and (k := contained_at(b, a)) is not None:
        return (
            "contains",
            f" (as its samples {k} to {k + train.n - 1} of {test.n}, {_ROUNDING_WORDS})",
        )
    return None


def _training_file(train: Setup, record: Record, files: Sequence[Path]) -> str:
    """The training file that holds ``record`` of ``train`` (the one file, or among several
    the one whose records include its very samples; read again: only when one is refused)."""
    files = list(files) or [train.path]
    if len(files) > 1:
        for p in files:
            if any(_identical(r, record) for r in prepare(p).records):
                return str(p)
    return ", ".join(str(p) for p in files)


def check_unseen(
    train: Setup,
    tests: Sequence[Setup],
    train_files: Sequence[Path] = (),
) -> None:
    """No test record shares its samples with a training record: the same capture imported
    twice under two names, a slice of it (``labrig import --window``), either written out by
    ``labrig export`` and imported again, or a file gathering several captures one of which is
    also tested, would score a model on data it was identified on (:func:`check_files` catches
    the same file only). A test record is refused when its voltage and strain together are
    contained in a training record, or contain one, as a contiguous stretch equal to within the
    rounding of ``labrig export`` (:func:`~labrig.core.samples.contained_at`: 5e-10 of each
    value, far below any capture's noise); records constant throughout are not compared.
    ``train_files``: the training files, to name the one holding the record (default: the
    setup's own file). Raises :class:`~labrig.core.errors.InputFileError` naming the test file,
    its record, the training record and its file (the files of a leave-one-out are compared
    with each other before its first fold: :func:`check_distinct_records`)."""
    issues = []
    for s in tests:
        for r in s.records:
            for a in train.records:
                how = _shared(a, r)
                if how is None:
                    continue
                where = _training_file(train, a, train_files)
                verb, detail = how
                msg = f"its record {r.name!r} {verb} the training record {a.name!r} of "
                msg += f"{where}{detail}: a model would be scored on data it was identified "
                msg += "on; test on a record that no training file holds"
                issues.append(InputIssue(str(s.path), None, "--on", msg))
                break
    if issues:
        raise InputFileError(issues)


def check_distinct_records(setups: Sequence[Setup]) -> None:
    """``--leave-one-out``: no two of the files share a record's samples (a copy of a file under
    another name, the same capture imported twice, a slice of another file's record: the fold
    that tests one would train on the other; compared as :func:`check_unseen` compares). Raises
    :class:`~labrig.core.errors.InputFileError` naming, for each file that shares a record with
    an earlier one, its record, the earlier file and its record, and the option."""
    issues = []
    for k, s in enumerate(setups):
        found = next(
            (
                (r, e, a, how)
                for e in setups[:k]
                for r in s.records
                for a in e.records
                if (how := _shared(a, r)) is not None
            ),
            None,
        )
        if found is None:
            continue
        r, e, a, (verb, detail) = found
        msg = f"its record {r.name!r} {verb} the record {a.name!r} of {e.path}{detail}: the "
        msg += "fold that tests either file would train on the other, scoring the models on data "
        msg += "they were identified on; give each record to --leave-one-out once"
        issues.append(InputIssue(str(s.path), None, "--leave-one-out", msg))
    if issues:
        raise InputFileError(issues)


def validate_runs(
    train: Sequence[Path | str],
    on: Sequence[Path | str],
    *,
    effects_from: Path | str | None = None,
    run_diagnosis: bool = False,
    method: str = "global",
    warmup_s: float | None = None,
    offset: bool | None = None,
    ui: CommandUI | None = None,
    page: bool = False,
    out: Path | str | None = None,
    overwrite: bool = False,
    distinct_files: Sequence[Path | str] = (),
) -> Validation:
    """``labrig validate`` (module docstring): identify every model on the files ``train``,
    score each on the files ``on``. ``effects_from``: a ``diagnosis.json`` whose accepted
    effects are added to our model; ``run_diagnosis``: diagnose the training records now
    instead; ``page``: also draw the HTML page (:attr:`Validation.page`); ``out``: write it
    there (checked before any work by :func:`labrig.core.outputs.check_outputs`: never an
    input, an existing file only with ``overwrite``; written beside, then renamed);
    ``distinct_files``: files no two of which may
    share a record (:func:`check_distinct_records`, before any fit: the files of a
    leave-one-out, given to its first fold)."""
    from labrig.core.outputs import check_writable, write_text_output
    from labrig.store.reader import being_written

    ui = ui or QuietUI()
    train_p, test_p = [Path(p) for p in train], [Path(p) for p in on]
    check_files(train_p, test_p)
    target = Path(out) if out is not None else None
    if target is not None:
        inputs = [*train_p, *test_p, Path(effects_from) if effects_from is not None else None]
        check_writable([target], inputs=inputs, overwrite=overwrite, being_written=being_written)
        page = True
    if effects_from is not None and run_diagnosis:
        raise _issue(effects_from, "give --effects-from or --diagnose, not both", "--diagnose")
    doc = _read_diagnosis(Path(effects_from)) if effects_from is not None else None
    if distinct_files:
        check_distinct_records([prepare(Path(p), None, warmup_s, offset) for p in distinct_files])
    tr = training_setup(train_p, warmup_s, offset)
    tests = [prepare(p, None, warmup_s, offset) for p in test_p]
    check_unseen(tr, tests, train_p)
    mixed = unit_issues(
        [(Path(s.path), r) for s in (tr, *tests) for r in s.scored_records]
    )  # each file is checked alone by prepare; here the training and test files together
    if mixed:
        raise InputFileError(mixed)
    ui.announce(tr)
    notes = [f"training: {n}" for n in tr.notes]
    for s in tests:
        notes += [f"test {s.path.name}: {n}" for n in s.notes]
    effects: list[Effect] | None = None
    source = ""
    if doc is not None:
        effects = accepted_effects(doc, effects_from or "", tr.scored_records)
        source = f"from {effects_from}"
    elif run_diagnosis:
        found = _diagnose_now(tr, ui)
        effects = accepted_effects(found, tr.path, tr.scored_records)
        source = "diagnosed now on the training records"
    models: dict[str, ValidatedModel] = {}
    with ui.fitting() as progress:
        base = fit_dynamic(tr, method, False, progress)
        ours = ValidatedModel("dynamic", MODEL_LABELS["dynamic"], base.to_json()["params"])
        notes += [f"fit: {m}" for m in base.messages]
        _score(ours, tests, {s.path: _predict_ours(base.params, s, None) for s in tests})
        models["dynamic"] = ours
        if effects is not None:
            models["dynamic+effects"] = _with_effects(tr, tests, base, effects, progress)
            notes += [
                f"diagnose adopted an EMPIRICAL sparse ODE: {equation_text(e.model)}"
                for e in effects
                if isinstance(e, SparseOdeEffect)
            ]
        for kind in KINDS:
            models[kind] = _peer(tr, tests, kind, progress)
    floor, floor_source = _floor(tests, ours)
    v = Validation(
        train_p,
        test_p,
        tr,
        tests,
        models,
        floor,
        floor_source,
        None if effects is None else [e.name for e in effects],
        source,
        notes,
    )
    if page:
        from labrig.report.templating import render

        with ui.busy("drawing the figures"):
            v.page = render("validate.html.j2", **page_context(v))
    if target is not None:
        write_text_output(target, v.page, overwrite=overwrite, being_written=being_written)
    return v


@dataclass
class LeaveOneOut:
    """``labrig validate --leave-one-out FILE...``: one :class:`Validation` per held-out file
    (``folds[k]`` predicts ``files[k]`` from the others); :meth:`to_json` is ``--json``."""

    files: list[Path]
    folds: list[Validation]

    def mean(self, key: str, which: str) -> float | None:
        """Model ``key``'s ``whole_nrmse_pct`` or ``second_half_nrmse_pct``, the mean over the
        folds (None when a fold has no score for it)."""
        vals = [v.models[key].mean(which) if key in v.models else None for v in self.folds]
        ok = [x for x in vals if x is not None]
        return float(np.mean(ok)) if ok and len(ok) == len(vals) else None

    def to_json(self) -> dict[str, Any]:
        keys = list(dict.fromkeys(k for v in self.folds for k in v.models))
        floors = [v.noise_floor_pct for v in self.folds if v.noise_floor_pct is not None]
        summary = {
            k: {
                "label": MODEL_LABELS.get(k, k),
                "whole_nrmse_pct": self.mean(k, "whole_nrmse_pct"),
                "second_half_nrmse_pct": self.mean(k, "second_half_nrmse_pct"),
                "per_file": {
                    str(v.test[0]): v.models[k].mean("whole_nrmse_pct") if k in v.models else None
                    for v in self.folds
                },
            }
            for k in keys
        }
        return json_safe(
            {
                "leave_one_out": [str(p) for p in self.files],
                "scoring": SCORING,
                "noise_floor_pct": float(np.mean(floors)) if floors else None,
                "models": summary,
                "folds": [v.to_json() for v in self.folds],
            }
        )


def validate_leave_one_out(
    files: Sequence[Path | str],
    *,
    run_diagnosis: bool = False,
    method: str = "global",
    warmup_s: float | None = None,
    offset: bool | None = None,
    ui: CommandUI | None = None,
) -> LeaveOneOut:
    """Leave one record out (module docstring): for each of ``files`` (at least 3, none
    twice), :func:`validate_runs` with it as the test file and the others as training files;
    the options are :func:`validate_runs`' (``run_diagnosis``: diagnose each fold's training
    records)."""
    paths = [Path(p) for p in files]
    if len(paths) < 3:
        raise _issue(
            paths[0] if paths else "FILES",
            f"--leave-one-out needs at least 3 files (each predicted from at least 2 others), "
            f"got {len(paths)}",
            "--leave-one-out",
        )
    for k, p in enumerate(paths):
        if any(same_file(p, q) for q in paths[:k]):
            raise _issue(p, "given twice to --leave-one-out (every file is one record)", "FILES")
    folds = []
    for k, held in enumerate(paths):
        train = [p for j, p in enumerate(paths) if j != k]
        folds.append(
            validate_runs(
                train,
                [held],
                run_diagnosis=run_diagnosis,
                method=method,
                warmup_s=warmup_s,
                offset=offset,
                ui=ui,
                distinct_files=paths if k == 0 else (),
            )
        )
    return LeaveOneOut(paths, folds)


def page_context(v: Validation) -> dict[str, Any]:
    """Everything ``validate.html.j2`` shows: the scores, one figure per test entry (each
    model's prediction over the measurement, :func:`labrig.report.plots.validation_figure`),
    the parameters."""
    from datetime import datetime

    from labrig.analysis.records import strain_unit
    from labrig.core.version import __version__
    from labrig.report.data import EntryView, drive_of
    from labrig.report.plots import validation_figure

    scored = {k: m for k, m in v.models.items() if m.scores}
    best = {
        w: min((x for m in scored.values() if (x := m.mean(w)) is not None), default=None)
        for w in ("whole_nrmse_pct", "second_half_nrmse_pct")
    }
    rows = [
        {
            "label": m.label,
            "ours": k.startswith("dynamic"),
            "note": m.note,
            "whole": fmt_pct(m.mean("whole_nrmse_pct")),
            "half": fmt_pct(m.mean("second_half_nrmse_pct")),
            "best_whole": m.scores and m.mean("whole_nrmse_pct") == best["whole_nrmse_pct"],
            "best_half": m.scores
            and m.mean("second_half_nrmse_pct") == best["second_half_nrmse_pct"],
        }
        for k, m in v.models.items()
    ]
    entries = []
    for s in v.tests:
        unit = strain_unit(s.scored_records)
        for r in s.scored_records:
            cells, preds = [], {}
            for m in scored.values():
                sc = next(x for x in m.scores if x.file == str(s.path) and x.entry == r.name)
                cells.append(f"{fmt_pct(sc.whole_nrmse_pct)} / {fmt_pct(sc.second_half_nrmse_pct)}")
                preds[m.label] = fitted_prediction(m, s, r)
            f, _periodic, amplitude = drive_of(r)
            view = EntryView(r, f, amplitude, False, str(r.meta.get("kind", "")))
            drive = f"{r.duration_s:.3g} s at {r.rate_hz:g} Hz, {view.amplitude_V:g} V"
            entries.append(
                {
                    "file": s.path.name,
                    "entry": r.name,
                    "cells": cells,
                    "drive": drive + (f", warm-up {s.warmup_s:g} s" if s.warmup_s else ""),
                    "png": validation_figure(view, preds, s.warmup_s, unit),
                }
            )
    params = [
        {"label": m.label, "text": as_text(json_safe(m.params))}
        for m in v.models.values()
        if m.params
    ]
    return {
        "version": __version__,
        "title": "Validation: identified on one set of records, predicting another",
        "train": [p.name for p in v.train],
        "test": [p.name for p in v.test],
        "rows": rows,
        "floor": fmt_pct(v.noise_floor_pct),
        "floor_source": v.noise_source,
        "scoring": SCORING,
        "effects": v.effects,
        "effects_source": v.effects_source,
        "notes": v.notes,
        "heads": [m.label for m in scored.values()],
        "entries": entries,
        "params": params,
        "generated": datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def _predict_ours(
    params: ModelParams, s: Setup, effects: tuple[list[Effect], dict] | None
) -> dict[str, NDArray]:
    from labrig.commands.report import predict_entries

    try:
        return predict_entries(params, s, effects, raw=True)
    except (ValueError, RuntimeError) as e:
        raise AnalysisError(f"{s.path}: cannot simulate the model: {e}") from None


def _with_effects(
    tr: Setup, tests: Sequence[Setup], base: Any, effects: list[Effect], progress: Any
) -> ValidatedModel:
    """Our model refitted on the training records with ``effects`` (nothing accepted: the
    base model again, said in its note); when they hold the sparse ODE diagnose adopted, that
    ODE in place of our model (:func:`sparse_ode_row`)."""
    key = "dynamic+effects"
    ode = next((e for e in effects if isinstance(e, SparseOdeEffect)), None)
    if ode is not None:
        return sparse_ode_row(tr, tests, ode, effects)
    if not effects:
        m = ValidatedModel(key, MODEL_LABELS[key], base.to_json()["params"])
        m.note = "diagnose accepted no effect on the training data: the same as ours"
        _score(m, tests, {s.path: _predict_ours(base.params, s, None) for s in tests})
        return m
    res = fit_with_effects(tr, base, effects, False, progress)
    values = {e["effect"]: e["params"] for e in res.effects}
    m = ValidatedModel(
        key,
        f"ours + {', '.join(e.name for e in effects)}",
        {"params": res.params.model_dump(), "effects": res.effects},
    )
    m.nuisance = [e for e in effects if e.where == "nuisance"]
    glob = [e for e in effects if e.where != "nuisance"]
    vals = {k: v for k, v in values.items() if k in {e.name for e in glob}}
    _score(m, tests, {s.path: _predict_ours(res.params, s, (glob, vals)) for s in tests})
    return m


def _peer(tr: Setup, tests: Sequence[Setup], kind: str, progress: Any) -> ValidatedModel:
    """The baseline ``kind`` fitted on the training records, scored on the test records."""
    m = ValidatedModel(kind, MODEL_LABELS[kind])
    try:
        res: BaselineResult = fit_base(tr, kind, False, progress)
    except AnalysisError as e:
        m.note = str(e)
        return m
    m.params = res.params
    _score_simulated(m, res, tests)
    return m


def _score_simulated(m: ValidatedModel, res: BaselineResult, tests: Sequence[Setup]) -> None:
    """Score ``res``'s model, simulated on every test record as the SINDy peer is
    (:meth:`~labrig.analysis.baselines.BaselineResult.simulate`: chained as a recorded run,
    at each record's own rate), into ``m``; a prediction that is not finite is ``m``'s note
    instead."""
    raw = {}
    for s in tests:
        sim = res.simulate(s.records, s.chain)
        raw[s.path] = {n: sim[n] for n in s.scored}
    if not all(np.all(np.isfinite(p)) for d in raw.values() for p in d.values()):
        m.note = "its prediction of the test records diverges (non-finite)"
        return
    _score(m, tests, raw)


def _not_carried(ode: SparseOdeEffect, tr: Setup) -> str | None:
    """Why the sparse ODE of a diagnosis cannot be scored as identified on the training records
    of ``tr``, or ``None``: its working rate (Hz) must be a training record's rate divided by a
    whole number (the decimation of its identification, :func:`~labrig.analysis.diagnose.
    sparse_ode.decimation`), else it was identified on other records."""
    work = ode.model.rate_hz
    for r in tr.scored_records:
        q = r.rate_hz / work
        if round(q) < 1 or abs(q - round(q)) > RATE_TOLERANCE * q:
            return (
                f"left out: the diagnosis' sparse ODE was identified at {work:.10g} Hz, which "
                f"is not the training record {r.name!r}'s rate ({r.rate_hz:.10g} Hz) divided by "
                "a whole number (the decimation of its identification): it was identified on "
                "other records, and its coefficients, carried as numbers, would not have been "
                "identified on these"
            )
    return None


def sparse_ode_row(
    tr: Setup, tests: Sequence[Setup], ode: SparseOdeEffect, effects: Sequence[Effect]
) -> ValidatedModel:
    """The row of what diagnose accepts when it adopted its sparse ODE: the ODE replaces the
    model (the effects accepted before it other than nuisance ones are not applied), its
    coefficients as identified (not refitted), run free from rest on each test record's
    voltage (:meth:`~labrig.analysis.sindy.SindyBaseline.predict`, as the diagnosis and the
    SINDy peer run it) and scored by the one rule with the nuisance effects accepted before it
    (and the offset). Labelled EMPIRICAL; left out, with the reason as its note, when its
    working rate says it was not identified on these training records (:func:`_not_carried`)."""
    replaced = [e.name for e in effects if e is not ode and e.where != "nuisance"]
    in_place = " + ".join(["ours", *replaced])
    m = ValidatedModel(
        "dynamic+effects",
        f"sparse ODE, EMPIRICAL (diagnose's, in place of {in_place})",
        {**ode.model.params(), "empirical": True, "in_place_of": in_place},
    )
    m.nuisance = [e for e in effects if e.where == "nuisance"]
    m.note = _not_carried(ode, tr)
    if m.note is not None:
        return m
    _score_simulated(m, BaselineResult("sindy", ode.model, math.nan, {}, None, []), tests)
    if m.note is None:
        m.note = "EMPIRICAL: found in the training records, not a mechanism; run free from rest"
    return m


def as_text(doc: dict[str, Any]) -> str:
    """The JSON of ``--json`` as the indented text it prints."""
    return json.dumps(doc, indent=2, allow_nan=False)


def fmt_pct(v: float | None) -> str:
    """A percentage for a table cell (``—`` when undefined)."""
    return "—" if v is None or not math.isfinite(v) else f"{v:.3g}"
