"""The empirical step's sparse-ODE candidate: an alternative base found in the data.

When no named effect brings the model to the noise floor, the strain may still follow a small
differential equation of the voltage that the model's structure (an operator and relaxors) does
not contain. The empirical step then also identifies a **sparse ODE of Duhem form**,

    dS/dt = sum_k xi_k theta_k(S, V, V'),      V' = dV/dt,

over the library of :mod:`labrig.analysis.sindy` (``1``, ``S``, ``V``, ``V'``, ``|V'|``,
``V' S``, ``V' V``, ``|V'| S``, ``|V'| V``, ``S|S|``: the six terms of a Duhem / Bouc-Wen model,
``1, S, V, V', |V'|, |V'| S``, are among them), identified with pysindy's STLSQ from
:func:`~labrig.analysis.sindy.fit_sindy`'s start on a band-limited resampling of the records,
every support of the threshold path refined by output error, the one chosen among those that
contract under the drive by how they predict training parts left out of their refit
(:func:`identify`), and simulated forward from rest (free run, never fed the measured strain;
a record sampled faster than the identification's working rate through the same band limit).
One that grows under the records' own drive (:func:`growth_rate`) is refused whatever its
score.

It is scored **exactly as the model's candidates are** (:meth:`labrig.analysis.extended.
ExtendedProblem.score_second_half`): leave-one-entry-out, the ODE identified without the held-out
entry (which stays in a chained run as history), the current model's per-entry nuisance terms
(offset, and hum or drift when added) fitted on the first half of the held-out entry, NRMSE on
the second half. It is judged by the same acceptance rule (:func:`~.acceptance.accept`) against
the current model (the base and whatever was added): at least 15 % held-out gain and the fold
rule. When it passes it **replaces** the model as the description of the records (an
alternative base, not a correction on top of it): ``after`` holds its scores, ``effects_added``
ends with ``sparse_ode`` and its terms and coefficients, the verdict says EMPIRICAL, and the
class is at best "partially explained" (it is not a physical attribution). When it is refused,
the verdict says why.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.band_limit import band_limit
from labrig.analysis.diagnose.acceptance import ROUNDING, WORSE, Acceptance, Candidate, accept
from labrig.analysis.diagnose.contraction import (
    REFINE_NFEV,
    contraction_margin,
    critical_rate,
    least_squares_jacobian,
    long_run_growth,
    mean_abs_rate,
    output_residual,
    refine_contracting,
    scored_runs,
    segment_mean,
    training_score,
)
from labrig.analysis.diagnose.evidence import Evidence, collect_evidence
from labrig.analysis.diagnose.state import Model, Settings, Setup
from labrig.analysis.diagnose.verdict import AT_FLOOR, headline
from labrig.analysis.extended import FitOutcome
from labrig.analysis.metrics import drive_frequency_hz, nrmse_pct, second_half_nrmse_pct
from labrig.analysis.parallel import map_tasks
from labrig.analysis.records import Record
from labrig.analysis.simulate import Scored, scored_sequences
from labrig.analysis.sindy import (
    LIBRARY,
    TOLERANCE,
    SindyBaseline,
    SindyCache,
    equilibrium,
    fit_sindy,
    threshold_path,
)
from labrig.core.blas import single_thread_blas
from labrig.model.effects import Effect
from labrig.model.effects.empirical import EMPIRICAL_NOTE


class DiagnosisLike(Protocol):
    """What :func:`adopt` reads and sets of a :class:`~.procedure.Diagnosis` (no import: the
    procedure imports this module)."""

    before: dict[str, Any]
    after: dict[str, Any]
    effects_added: list[dict[str, Any]]
    candidates: list[dict[str, Any]]
    verdict: str
    classification: str
    headline: str
    evidence_after: Evidence
    predictions_after: dict[str, NDArray]
    rounds: list[list[Candidate]]
    messages: list[str]


__all__ = [
    "CONTRACTING_TRIES",
    "FINALISTS",
    "IDLE_FRACTION",
    "INNER_FOLDS",
    "NAME",
    "PASSES",
    "REFINE_NFEV",
    "SAMPLES_PER_PERIOD",
    "CrossValidation",
    "SparseOdeEffect",
    "SparseOdeTrial",
    "adopt",
    "contracts",
    "cross_validate",
    "decimation",
    "drive_range",
    "driven_items",
    "entry_score",
    "growth_rate",
    "identify",
    "inner_folds",
    "inner_score",
    "model_from_params",
    "offset_columns",
    "refine",
    "settles",
    "sparse_ode_trial",
    "working_records",
]

#: the candidate's name in ``candidates`` and ``effects_added``
NAME = "sparse_ode"
_TERMS = [t.name for t in LIBRARY]
#: where the ``S|S|`` coefficient is in a model's coefficients
_SS = _TERMS.index("S|S|")

Progress = Callable[[str], Any]


class SparseOdeEffect(Effect):
    """The sparse ODE as the acceptance rule sees a candidate: no parameter of the model's
    (its coefficients are identified by sparse regression, not refitted), the empirical
    caveat. It is an alternative base, never applied on top of the model."""

    name = NAME
    where = "output"
    acts_on = "the whole strain (an alternative base)"
    params_doc = "one coefficient per selected library term (sparse regression)"
    form = "`dS/dt = sum_k xi_k theta_k(S, V, dV/dt)`, free run from rest"
    physics = EMPIRICAL_NOTE
    signature = "a strain that a small Duhem-type ODE of the voltage follows better"
    confusable = ()
    tell_apart = "a drive the ODE was not identified on (other amplitudes, rates, a step)"
    params = ()

    def __init__(self, model: SindyBaseline):
        self.model = model

    def apply(self, x: NDArray, ctx: Any, p: Mapping[str, float]) -> NDArray:
        raise NotImplementedError("the sparse ODE is an alternative base, not a correction")

    def caveats(self, p: Mapping[str, float], span_s: float) -> list[str]:
        return [f"{EMPIRICAL_NOTE}: an ODE identified from these records, not a mechanism"]

    def physical(self, p: Mapping[str, float]) -> dict[str, Any]:
        return dict(self.model.params())

    def describe(self, p: Mapping[str, float], sd: Mapping[str, float | None]) -> str:
        return f"{EMPIRICAL_NOTE}: {equation_text(self.model)}"


def _finite(x: Any, what: str) -> float:
    """``x`` as a float when it is a finite number (not a bool), else a ``ValueError``."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        raise ValueError(f"{what} is not a finite number: {x!r}")
    return float(x)


def model_from_params(params: Mapping[str, Any]) -> SindyBaseline:
    """The sparse ODE that ``effects_added``'s ``sparse_ode`` describes (its ``params``, as
    :func:`adopt` writes them: ``terms``, ``coefficients`` and ``rate_hz``, the working rate it
    was identified at, Hz; ``threshold`` optional), to run free as the diagnosis ran it
    (:meth:`~labrig.analysis.sindy.SindyBaseline.predict`). Raises ``ValueError`` saying what is
    wrong: a term not of :data:`~labrig.analysis.sindy.LIBRARY` or given twice, a coefficient
    that is not a finite number or one too many or too few, a rate that is not a positive
    number."""
    terms, coefs = params.get("terms"), params.get("coefficients")
    if not isinstance(terms, list) or not isinstance(coefs, list) or len(terms) != len(coefs):
        raise ValueError("'terms' and 'coefficients' must be two lists of the same length")
    xi = [0.0] * len(_TERMS)
    for k, (t, c) in enumerate(zip(terms, coefs, strict=True)):
        if t not in _TERMS or t in terms[:k]:
            raise ValueError(f"term {t!r} is not one of {', '.join(_TERMS)} or is given twice")
        xi[_TERMS.index(t)] = _finite(c, f"the coefficient of {t!r}")
    rate = _finite(params.get("rate_hz"), "'rate_hz'")
    if rate <= 0.0:
        raise ValueError(f"'rate_hz' must be positive, got {rate!r}")
    return SindyBaseline(tuple(xi), rate, _finite(params.get("threshold", 0.0), "'threshold'"))


def equation_text(model: SindyBaseline) -> str:
    """``dS/dt = -0.2562 S + 0.08243 V + ...`` (four significant digits; t in s, V in V, S in
    the records' strain unit, ue or the raw numbers of an import)."""
    parts = []
    for x, t in zip(model.coefficients, LIBRARY, strict=True):
        if x != 0:
            parts.append(f"{x:+.4g}" + ("" if t.name == "1" else f" {t.name}"))
    body = " ".join(parts).lstrip("+") if parts else "0"
    return f"dS/dt = {body} (t in s, V in V, V' = dV/dt)"


def readings(model: SindyBaseline) -> str:
    """What each selected term reads as (:data:`~labrig.analysis.sindy.LIBRARY`)."""
    return "; ".join(
        f"{t.name}: {t.physics}" for x, t in zip(model.coefficients, LIBRARY, strict=True) if x != 0
    )


@dataclass
class SparseOdeTrial:
    """What the sparse-ODE candidate did: the ODE identified on every entry, its in-sample and
    held-out NRMSE per entry (%), its predictions (entry -> strain over the record, nuisance
    fitted), the acceptance rule's verdict against the current model and the candidate row."""

    model: SindyBaseline
    per_entry: dict[str, float]
    heldout_per_entry: dict[str, float]
    predictions: dict[str, NDArray]
    acceptance: Acceptance
    candidate: Candidate
    #: the model it is judged against, in words ("the model with sensor_lowpass")
    replaced: str = "the model"

    @property
    def heldout_pct(self) -> float:
        return float(np.mean(list(self.heldout_per_entry.values())))

    @property
    def nrmse_pct(self) -> float:
        return float(np.mean(list(self.per_entry.values())))


def _items(scored: Sequence[Scored], leave_out: str | None = None) -> list[tuple[Any, list]]:
    return [(s.seq, [g for g in s.segments if g.name != leave_out]) for s in scored]


#: a segment whose voltage spans less than this fraction of the widest segment's is idle: it
#: stays in its chained run (history) and is scored, but is not used to identify the ODE
IDLE_FRACTION = 0.01
#: the identification works on the records resampled to at least this many samples per drive
#: period (an integer decimation, band-limited: :func:`working_records`)
SAMPLES_PER_PERIOD = 250
#: at most this many passes of the threshold path (the first from ``fit_sindy``'s zeros, each
#: further one from the best-scoring and the picked candidates' zeros, while the best training
#: score still falls by 1 %)
PASSES = 4
#: at most this many of the candidates that grow under the drive (the best-scoring first) are
#: refined again with their long-run growth rate bounded below zero
#: (:func:`~.contraction.refine_contracting`)
CONTRACTING_TRIES = 4


def decimation(records: Sequence[Record]) -> int:
    """The integer factor ``q`` by which the records' sample rate exceeds what the drive needs:
    the largest that keeps :data:`SAMPLES_PER_PERIOD` samples per period of every record's
    drive (:func:`~labrig.analysis.metrics.drive_frequency_hz`); 1 when a driven record has no
    drive frequency (a PRBS, a step: its content is not bounded by one) or the rate is already at
    most that. An idle record (voltage span below :data:`IDLE_FRACTION` of the widest) has no
    drive to keep and does not count."""
    widest = max((float(np.ptp(r.voltage_V)) for r in records if r.n), default=0.0)
    q = math.inf
    for r in records:
        if r.n == 0 or float(np.ptp(r.voltage_V)) < IDLE_FRACTION * widest:
            continue
        f = drive_frequency_hz(r)
        if not f:
            return 1
        q = min(q, math.floor(r.rate_hz / (SAMPLES_PER_PERIOD * f)))
    return max(int(q), 1) if math.isfinite(q) else 1


def working_records(records: Sequence[Record], q: int) -> list[Record]:
    """The records resampled to ``1/q`` of their rate for the identification: strain and
    voltage through the same anti-aliasing low-pass (:func:`~labrig.analysis.band_limit.
    band_limit`: zero phase, a Kaiser-windowed FIR with its cutoff at the new Nyquist
    frequency, each record's ends extended by a line; ``scipy.signal.resample_poly`` to
    rounding), every ``q``-th sample and time stamp; the auxiliary channels every ``q``-th
    sample. White noise of RMS ``sigma`` comes out at about ``sigma / sqrt q``. The identified
    ODE predicts a record at its own rate through the same low-pass
    (:meth:`~labrig.analysis.sindy.SindyBaseline.predict`)."""
    if q <= 1:
        return list(records)

    def down(x: NDArray) -> NDArray:
        return band_limit(x, 1.0 / q)[::q]

    out = []
    for r in records:
        meta = dict(r.meta)
        meta.setdefault("rest_V", r.rest_V)
        out.append(
            Record(
                r.name,
                r.rate_hz / q,
                r.time_s[::q],
                down(r.voltage_V),
                down(r.strain_ue),
                {n: x[::q] for n, x in r.aux.items()},
                r.hold,
                meta,
            )
        )
    return out


def driven_items(items: Sequence[tuple[Any, list]]) -> list[tuple[Any, list]]:
    """``items`` without their idle segments (voltage span below :data:`IDLE_FRACTION` of the
    widest segment's): a stretch at rest carries the ODE's equilibrium only, and its noise's
    derivative would weigh as much as a driven segment's in the regression. All of them when
    every segment is idle."""

    def span(seq: Any, g: Any) -> float:
        return float(np.ptp(seq.voltage_V[g.lo : g.hi])) if g.hi > g.lo else 0.0

    widest = max((span(seq, g) for seq, segs in items for g in segs), default=0.0)
    out = [
        (seq, [g for g in segs if span(seq, g) >= IDLE_FRACTION * widest]) for seq, segs in items
    ]
    out = [(seq, segs) for seq, segs in out if segs]
    return out if out and widest > 0 else [(seq, list(segs)) for seq, segs in items]


def refine(
    items: Sequence[tuple[Any, list]], model: SindyBaseline, offset: bool
) -> tuple[SindyBaseline, float]:
    """``model``'s coefficients refined on its support by **output error**, and the refined
    model's training score: the RMS over segments of their NRMSE (%).

    The free run's residual on the scored segments of ``items``, each segment's divided by
    ``span_e sqrt(n_e)`` (so the cost is the sum of the segments' squared NRMSE) and, with
    ``offset``, less its mean, is minimised by ``scipy.optimize.least_squares`` (trust region,
    at most :data:`REFINE_NFEV` runs) in the coefficients' ratios to ``model``'s, on the exact
    Jacobian (the free run's forward sensitivities,
    :func:`~labrig.analysis.diagnose.contraction.output_jacobian`; forward differences
    without numba). The regression that found ``model`` fits a derivative estimated from noisy
    samples; the free run does not differentiate the data, so the refined coefficients do not
    depend on how the derivative was estimated. ``model`` itself when refining does not lower
    the cost; ``inf`` for a free run that diverges."""
    from scipy.optimize import least_squares

    xi0 = np.asarray(model.coefficients, dtype=float)
    sup = np.flatnonzero(xi0)
    runs = scored_runs(items)
    count = sum(len(c) for *_, c in runs) or 1

    def unpack(z: NDArray) -> NDArray:
        xi = xi0.copy()
        xi[sup] = z * xi0[sup]
        return xi

    def residual(z: NDArray) -> NDArray:
        return output_residual(runs, unpack(z), offset, model.limit_ue)

    with np.errstate(over="ignore", invalid="ignore"):
        s0 = training_score(residual(np.ones(sup.size)), count)
        if sup.size == 0 or not math.isfinite(s0):
            return model, s0
        sol = least_squares(
            residual,
            np.ones(sup.size),
            jac=least_squares_jacobian(runs, offset, model.limit_ue, unpack, sup.size),
            method="trf",
            diff_step=1e-6,
            max_nfev=REFINE_NFEV,
        )
        s1 = training_score(sol.fun, count)
    if not s1 < s0:
        return model, s0
    xi = xi0.copy()
    xi[sup] = sol.x * xi0[sup]
    return SindyBaseline(
        tuple(float(x) for x in xi), model.rate_hz, model.threshold, model.limit_ue
    ), s1


def settles(model: SindyBaseline, v_lo: float, v_hi: float) -> bool:
    """Whether ``model`` brings the strain to rest at every voltage held in ``[v_lo, v_hi]``
    (nine voltages checked): with ``V' = 0`` the equation reads ``dS/dt = a(V) + b S + c S|S|``
    (``a`` of the terms ``1`` and ``V``, ``b`` of ``S``, ``c`` of ``S|S|``) and must have a
    stable rest strain (``a + b S + c S|S| = 0`` with ``b + 2 c |S| < 0``), or be 0 for every
    strain (a hold changes nothing). An ODE without one runs away (or drifts without end)
    after any step to a held voltage, which an actuator at rest does not."""
    xi = dict(zip((t.name for t in LIBRARY), model.coefficients, strict=True))
    b, c = xi["S"], xi["S|S|"]
    for v in np.linspace(v_lo, v_hi, 9):
        a = xi["1"] + xi["V"] * v
        if a == 0.0 and b == 0.0 and c == 0.0:
            continue
        s = equilibrium(model.coefficients, float(v))
        if not (
            b + 2.0 * c * abs(s) < 0 and abs(a + b * s + c * s * abs(s)) <= 1e-9 * (abs(a) + 1)
        ):
            return False
    return True


def growth_rate(model: SindyBaseline, items: Sequence[tuple[Any, list]]) -> float:
    """How fast a disturbance of ``model``'s strain grows (1/s, > 0) or decays (< 0) under a
    sustained drive like that of ``items`` (their driven segments): the mean over the driven
    samples of ``df/dS = b(V') + 2 c |S|`` along the free run (``b`` of the terms ``S``,
    ``V' S``, ``|V'| S``; ``c`` of ``S|S|``), the ``V' S`` term left out. For one state variable
    two runs a little apart separate as ``exp(int df/dS dt)``; the ``V' S`` term's part of that
    integral is ``xi_{V'S} (V_end - V_start)``, bounded however long the drive lasts (on a record
    of one and a half periods it still weighs ``xi_{V'S}`` times the mean ``V'``, which a
    sustained drive does not have), so what is left is the free run's Lyapunov exponent. An ODE
    that settles at every held voltage (:func:`settles`) may still grow under a sustained drive
    (a Bouc-Wen-like ``|V'| S`` with a positive coefficient outweighing the lag): its prediction
    then wanders off from period to period, which the per-entry offsets of a short record do
    not show."""
    xi = np.asarray(model.coefficients, dtype=float)
    c = sum(float(x) for x, t in zip(xi, LIBRARY, strict=True) if t.kind == "c")
    b_terms = [
        (float(x), t)
        for x, t in zip(xi, LIBRARY, strict=True)
        if t.kind == "b" and t.name != "V' S" and x != 0
    ]

    def dfds(seq: Any, v: NDArray) -> NDArray:
        y = model.predict(v, seq.rest_V, seq.rate_hz)
        d = np.diff(np.concatenate(([float(seq.rest_V)], v))) * seq.rate_hz  # the free run's V'
        return sum((x * t.factor(v, d) for x, t in b_terms), np.zeros(v.size)) + 2.0 * c * np.abs(y)

    return segment_mean(driven_items(items), dfds)


def contracts(
    model: SindyBaseline,
    items: Sequence[tuple[Any, list]],
    margin: float,
    rate_abs: float,
    along_run: bool = True,
) -> bool:
    """Whether ``model`` contracts under the drive of ``items`` (their driven segments): its
    growth rate there (:func:`growth_rate`, the check of :func:`sparse_ode_trial`) is negative
    and its long-run growth rate's bound under a sustained drive of mean ``|V'|`` ``rate_abs``
    (V/s) is at most ``-margin`` (1/s; :func:`~.contraction.long_run_growth`, to a relative
    1e-9: a refinement that ends on the bound counts). A positive ``S|S|`` coefficient has no
    such bound: with ``along_run`` it is judged along its free run over the driven samples
    (``g + 2 c mean|S|``), without it such an ODE never contracts."""
    c = model.coefficients[_SS]
    strain_abs = _mean_abs_strain(model, items) if c > 0 and along_run else math.inf
    if not long_run_growth(model, rate_abs, strain_abs) <= -margin * (1.0 - 1e-9):
        return False
    return growth_rate(model, items) < 0.0


def _mean_abs_strain(model: SindyBaseline, items: Sequence[tuple[Any, list]]) -> float:
    """The mean ``|S|`` (ue) of ``model``'s free run over the driven scored samples of
    ``items``."""
    return segment_mean(
        driven_items(items), lambda seq, v: np.abs(model.predict(v, seq.rest_V, seq.rate_hz))
    )


def identify(
    items: Sequence[tuple[Any, list]], offset: bool, cache: SindyCache | None = None
) -> SindyBaseline:
    """The sparse ODE of the scored segments of ``items`` (their driven segments,
    :func:`driven_items`). Candidates: :func:`~labrig.analysis.sindy.fit_sindy`'s model and
    every support of the STLSQ threshold path
    (:func:`~labrig.analysis.sindy.threshold_path`) with the segments' zeros from that
    model's free run, then up to ``PASSES - 1`` more paths from the best-scoring and the picked
    candidates' zeros (the pick: of those that settle at a held voltage, :func:`settles`, the
    sparsest whose training score is within :data:`~labrig.analysis.sindy.TOLERANCE`, 5 %, of
    the best) while the best training score falls by 1 %; each refined by output error
    (:func:`refine`).

    When the pick **contracts** under the drive (:func:`contracts`, with the margin of
    :func:`~.contraction.contraction_margin`; a positive ``S|S|`` judged along its free run) it
    is returned. Otherwise the choice is among the candidates that contract and settle, and the
    :data:`CONTRACTING_TRIES` best-scoring ones that do not contract (a positive ``S|S|``, which
    has no long-run bound, counted among them) refined again with their long-run growth rate
    bounded (:func:`~.contraction.refine_contracting`). Of these, the best training
    score of each number of terms (at most :data:`FINALISTS`) are judged by how they predict
    training parts they were not refitted on (:func:`inner_score` over :func:`inner_folds`),
    and the sparsest within 5 % of the best inner score is returned: the training score alone
    cannot choose here (on one and a half periods every support of 6 to 10 terms follows the
    training parts to the noise, and which of them was "sparsest within 5 %" hung on the last
    digits of the data). With one finalist or a single driven segment, the sparsest within 5 %
    of the best training score; when none contracts and settles, the growing pick
    (:func:`sparse_ode_trial` refuses it)."""
    driven = driven_items(items)
    volts = np.concatenate([seq.voltage_V[g.lo : g.hi] for seq, segs in driven for g in segs])
    v_lo, v_hi = float(np.min(volts)), float(np.max(volts))
    cache = SindyCache() if cache is None else cache
    start = fit_sindy(driven, offset, cache=cache)
    cands: dict[tuple[int, ...], tuple[SindyBaseline, float, bool]] = {}

    def sparsest(pool: Sequence[tuple[SindyBaseline, float, bool]]) -> tuple[SindyBaseline, float]:
        best = min(c[1] for c in pool)
        ok = [c for c in pool if c[1] <= (1.0 + TOLERANCE) * best]
        pick = min(ok, key=lambda c: (len(c[0].support), c[1]))
        return pick[0], pick[1]

    refined_from: set[tuple[tuple[float, ...], float]] = set()

    def add(models: Sequence[SindyBaseline]) -> tuple[SindyBaseline, float]:
        for m in models:
            if (m.coefficients, m.limit_ue) in refined_from:
                continue  # the same start refines to the same model and score: no change
            refined_from.add((m.coefficients, m.limit_ue))
            key = tuple(int(k) for k in np.flatnonzero(m.coefficients))
            refined, score = refine(driven, m, offset)
            if key not in cands or score < cands[key][1]:
                cands[key] = (refined, score, settles(refined, v_lo, v_hi))
        return sparsest([c for c in cands.values() if c[2]] or list(cands.values()))

    pick, score = add([start, *threshold_path(driven, start, offset, cache)])
    if not math.isfinite(score):
        return start
    for _ in range(PASSES - 1):
        best = min(cands.values(), key=lambda c: c[1])[0]
        before = min(c[1] for c in cands.values())
        pick, score = add(
            [
                *threshold_path(driven, best, offset, cache),
                *threshold_path(driven, pick, offset, cache),
            ]
        )
        if not min(c[1] for c in cands.values()) < (1.0 - 0.01) * before:
            break
    margin, rate_abs = contraction_margin(driven), mean_abs_rate(driven)
    if contracts(pick, driven, margin, rate_abs):
        return pick
    # the pick grows: the candidates that contract and settle, and the best growing ones
    # refitted bounded
    pool: list[tuple[SindyBaseline, float, bool]] = []
    growing = []
    for c in cands.values():
        if not math.isfinite(c[1]):
            continue
        contracting = contracts(c[0], driven, margin, rate_abs)  # a positive S|S| along its run
        if c[2] and contracting:
            pool.append(c)
        if not contracting or c[0].coefficients[_SS] > 0:
            growing.append(c)  # a positive S|S| too: bounded, it may settle where it does not
    for m, _, _ in sorted(growing, key=lambda c: c[1])[:CONTRACTING_TRIES]:
        bounded, score = refine_contracting(driven, m, offset, margin)
        ok = math.isfinite(score) and contracts(bounded, driven, margin, rate_abs)
        if ok and settles(bounded, v_lo, v_hi):
            pool.append((bounded, score, True))
    if not pool:
        return pick
    front: dict[int, tuple[SindyBaseline, float, bool]] = {}
    for c in pool:  # the best training score of each number of terms
        k = len(c[0].support)
        if k not in front or c[1] < front[k][1]:
            front[k] = c
    finalists = sorted(front.values(), key=lambda c: (c[1], len(c[0].support)))[:FINALISTS]
    groups = inner_folds(driven)
    if len(finalists) == 1 or len(groups) < 2:
        return sparsest(pool)[0]
    inner = [inner_score(driven, c[0], groups, offset, margin) for c in finalists]
    lowest = min(inner)
    near = [i for i in range(len(finalists)) if inner[i] <= (1.0 + TOLERANCE) * lowest]
    return finalists[min(near, key=lambda i: (len(finalists[i][0].support), inner[i]))][0]


#: the contracting candidates with the best training scores judged by :func:`inner_score`
FINALISTS = 10
#: at most this many inner folds (groups of consecutive driven segments)
INNER_FOLDS = 4


def inner_folds(driven: Sequence[tuple[Any, list]]) -> list[list[str]]:
    """The inner folds of an identification on ``driven`` (driven segments only): the
    segments' names in at most :data:`INNER_FOLDS` groups of consecutive segments."""
    names = [g.name for _, segs in driven for g in segs]
    k = min(INNER_FOLDS, len(names))
    return [list(a) for a in np.array_split(np.array(names, dtype=object), k) if len(a)]


def inner_score(
    driven: Sequence[tuple[Any, list]],
    model: SindyBaseline,
    groups: Sequence[Sequence[str]],
    offset: bool,
    margin: float,
) -> float:
    """How well ``model``'s support predicts data it was not refitted on, within the training
    segments ``driven``: for each group of :func:`inner_folds`, the coefficients refitted on
    the other segments from ``model``'s (:func:`~.contraction.refine_contracting`, so the
    refit contracts too), the free run through the whole chained sequence, each held segment's
    offset (with ``offset``) fitted on its first half and its NRMSE (%) taken on the second
    (the outer folds' rule); the median over the groups of each group's mean (a group whose
    training segments lack what it must predict, e.g. a rising half-period predicted from two
    falling ones, says nothing of the support). ``inf`` when a refit diverges."""
    per_group = []
    for group in groups:
        held = set(group)
        train = [(seq, [g for g in segs if g.name not in held]) for seq, segs in driven]
        train = [(seq, segs) for seq, segs in train if segs]
        refit, score = refine_contracting(train, model, offset, margin)
        if not math.isfinite(score):
            return math.inf
        scores: list[float] = []
        for seq, segs in driven:
            mine = [g for g in segs if g.name in held]
            if not mine:
                continue
            end = max(g.hi for g in mine)
            y = refit.predict(seq.voltage_V[:end], seq.rest_V, seq.rate_hz)
            scores.extend(
                second_half_nrmse_pct(g.measured_ue, y[g.lo : g.hi], offset) for g in mine
            )
        per_group.append(float(np.mean(scores)))
    out = float(np.median(per_group)) if per_group else math.inf
    return out if math.isfinite(out) else math.inf


def _entry(
    scored: Sequence[Scored], model: SindyBaseline, name: str
) -> tuple[Any, Any, NDArray, NDArray]:
    """``(record, segment, prediction over the record, measured)``: the free run of the
    sequence holding ``name`` up to its end, cut to the entry."""
    for s in scored:
        for g in s.segments:
            if g.name != name:
                continue
            seq = s.seq
            rec = next(r for r in seq.records if r.name == name)
            a = seq.entries[name].start
            y = model.predict(seq.voltage_V[: a + rec.n], seq.rest_V, seq.rate_hz)
            return rec, g, y[a : a + rec.n], rec.strain_ue
    raise KeyError(name)


def entry_score(
    scored: Sequence[Scored],
    model: SindyBaseline,
    name: str,
    columns: Callable[[NDArray, float], NDArray],
    held: bool,
) -> tuple[float, NDArray]:
    """NRMSE (%) of entry ``name`` by ``model``'s free run with the nuisance ``columns``: held
    out (fitted on the first half of the scored samples, scored on the second) or in-sample
    (fitted and scored on all of them); and the prediction over the record."""
    rec, g, p, m = _entry(scored, model, name)
    i0 = g.i0
    pm, mm, t = p[i0:], m[i0:], rec.time_s[i0:]
    C = columns(t, rec.rate_hz)
    fit_to = mm.size // 2 if held else mm.size
    if C.shape[1] and np.all(np.isfinite(pm)):
        coef, *_ = np.linalg.lstsq(C[:fit_to], mm[:fit_to] - pm[:fit_to], rcond=None)
        pm = pm + C @ coef
    out = p.copy()
    out[i0:] = pm
    if not np.all(np.isfinite(pm)):
        return math.inf, out
    return (second_half_nrmse_pct(mm, pm) if held else nrmse_pct(mm, pm)), out


Columns = Callable[[NDArray, float], NDArray]


def offset_columns(t: NDArray, _rate_hz: float) -> NDArray:
    """The nuisance columns of a sensor with no fixed zero and nothing else: one offset."""
    return np.ones((t.size, 1))


@dataclass
class CrossValidation:
    """The sparse ODE of :func:`cross_validate`: identified on every entry, its in-sample NRMSE
    (%) and prediction per entry, each entry's held-out NRMSE (%) by the ODE identified without
    it, and the working records' scored segments (``(sequence, segments)``, the identification's
    data)."""

    model: SindyBaseline
    per_entry: dict[str, float]
    predictions: dict[str, NDArray]
    heldout: dict[str, float]
    work: list[tuple[Any, list]]


def cross_validate(
    records: Sequence[Record],
    names: Sequence[str],
    warmup_s: float,
    chain: bool,
    offset: bool,
    columns: Columns = offset_columns,
    workers: int = 1,
) -> CrossValidation:
    """The sparse ODE of ``records`` scored as the model's candidates are (module docstring):
    identified (:func:`identify`) on the working records (:func:`working_records`) of every
    entry of ``names`` and again without each, each entry's nuisance ``columns`` fitted on the
    first half of its scored samples and its NRMSE taken on the second (:func:`entry_score`).
    The identifications run on ``workers`` processes (:func:`~labrig.analysis.parallel.
    map_tasks`); the result does not depend on it. Raises ``ValueError`` when the records
    cannot be differentiated (too short) or differ in sample rate."""
    names = list(names)
    if len(names) < 2:
        raise ValueError(f"cross-validation needs at least two entries, got {len(names)}")
    scored = scored_sequences(records, names, warmup_s, chain)
    work = scored_sequences(working_records(records, decimation(records)), names, warmup_s, chain)
    cache = SindyCache()

    def task(k: int) -> tuple[SindyBaseline, Any]:
        leave = None if k == 0 else names[k - 1]
        with single_thread_blas(), np.errstate(over="ignore", invalid="ignore"):
            model = identify(_items(work, leave_out=leave), offset, cache)
            if leave is None:
                return model, {n: entry_score(scored, model, n, columns, held=False) for n in names}
            return model, entry_score(scored, model, leave, columns, held=True)[0]

    out = map_tasks(task, len(names) + 1, workers)
    model, whole = out[0]
    return CrossValidation(
        model,
        {n: float(whole[n][0]) for n in names},
        {n: whole[n][1] for n in names},
        {n: float(h) for n, (_, h) in zip(names, out[1:], strict=True)},
        _items(work),
    )


def sparse_ode_trial(
    setup: Setup, settings: Settings, current: Model, rnd: int, say: Progress
) -> SparseOdeTrial:
    """Identify the sparse ODE, cross-validate it and judge it against ``current`` (module
    docstring). Raises ``ValueError`` when the records cannot be differentiated (too short)
    or differ in sample rate."""
    say(f"round {rnd + 1}: sparse ODE of the strain (Duhem library, STLSQ), cross-validated")
    cv = cross_validate(
        list(setup.records),
        list(current.heldout),
        settings.warmup_s,
        settings.chain,
        settings.offset,
        current.problem.nuisance_columns,
        settings.workers,
    )
    model, per_entry, held, work = cv.model, cv.per_entry, cv.heldout, cv.work
    eff = SparseOdeEffect(model)
    fo = FitOutcome({}, {NAME: {}}, {}, {}, per_entry, math.nan)
    a = accept(
        eff,
        fo,
        held,
        dict(current.heldout),
        settings.min_gain,
        setup.span_s,
        current.evidence.floor_pct,
    )
    c = Candidate(NAME, rnd, 0.0, tried=True)
    c.heldout_per_entry = held
    c.heldout_nrmse_pct = float(np.mean(list(held.values())))
    c.insample_gain = 1.0 - float(np.mean(list(per_entry.values()))) / current.fit.nrmse_pct
    c.judged(a)
    if not c.heldout_nrmse_pct < (current.heldout_pct or math.inf):
        # say what happened to the free run instead of the rule's reason for no gain
        c.reasons = [
            f"it predicts held-out data worse than {_what(current)}"
            if math.isfinite(c.heldout_nrmse_pct)
            else "its free run diverges on held-out data",
            *[r for r in a.reasons if not r.startswith((ROUNDING, WORSE))],
        ]
    grow = growth_rate(model, work)
    # whatever its score: a model that runs away under its own drive explains nothing
    if grow > 0.0:
        c.accepted = False
        c.reasons.append(
            f"its free run grows under the records' own drive (a disturbance grows as "
            f"exp({grow:.2g} t), t in s; the per-entry offsets hide the drift on short entries)"
        )
    what = _what(current)
    verb = "predicts" if math.isfinite(c.heldout_nrmse_pct) else "diverges on"
    c.evidence = (
        f"a sparse ODE of Duhem form identified by STLSQ and refined by output error, "
        f"{equation_text(model)}, {verb} "
        f"held-out entries at {c.heldout_nrmse_pct:.3g} % against {current.heldout_pct:.3g} % "
        f"for {what} (better in {a.wins}, worse in {a.losses} of {len(held)} folds)"
        + (
            f"; its free run contracts under the records' own drive (a disturbance decays as "
            f"exp({grow:.2g} t), t in s)" + drive_range(model, work)
            if grow < 0.0
            else ""
        )
        + ("; refused: " + "; ".join(c.reasons) if c.reasons else "")
    )
    return SparseOdeTrial(model, per_entry, held, cv.predictions, a, c, what)


def drive_range(model: SindyBaseline, items: Sequence[tuple[Any, list]]) -> str:
    """Where the contraction holds, in words, from the long-run bound ``g = xi_S +
    xi_{|V'|S} mean|V'|`` (:func:`~.contraction.long_run_growth`): empty when ``g < 0`` under
    any drive (a negative lag and a non-positive ``|V'| S``) or there is no bound (a positive
    ``S|S|``); "only while mean |V'| stays below" the critical rate (:func:`~.contraction.
    critical_rate`) for a negative lag and a positive ``|V'| S``; "above" ``-xi_S /
    xi_{|V'|S}`` for a non-negative lag and a negative ``|V'| S`` (slower drives and holds then
    rest on ``S|S|``); and when neither term holds it back, that its ``S|S|`` term does, at the
    strain the records reach. The drive's own mean ``|V'|`` is given for scale: over the driven
    samples, the step from the rest voltage to a record's first sample left out (a record cut
    in mid-swing starts with a jump that is not part of its drive)."""
    crit = critical_rate(model)
    if not math.isfinite(crit):
        return ""
    lag = model.coefficients[_TERMS.index("S")]
    rate_term = model.coefficients[_TERMS.index("|V'| S")]
    held = ", held back only by its S|S| term at the strain these records reach"
    if lag == 0.0 and rate_term < 0.0:  # no lag term: a threshold of 0 V/s says nothing
        return (
            ", but only while the drive moves (its |V'| S term holds it back; it has no lag "
            f"term S: holds are{held[1:]})"
        )
    if lag > 0.0 and rate_term < 0.0:
        return (
            f", but only while a sustained drive's mean |V'| stays above {-lag / rate_term:.3g} "
            f"V/s{_scale(-lag / rate_term, items)} (its |V'| S term holds it back, its lag S does "
            f"not: slower drives and holds are{held[1:]})"
        )
    if crit <= 0.0:
        return f"{held} (its lag S and |V'| S terms alone do not hold it back under any drive)"
    return (
        f", but only while a sustained drive's mean |V'| stays below {crit:.3g} V/s"
        f"{_scale(crit, items)} (its |V'| S term then outweighs the lag S and a disturbance grows)"
    )


def _scale(rate: float, items: Sequence[tuple[Any, list]]) -> str:
    """``", 1.16x the records' 600 V/s"``: ``rate`` against the drive's own mean ``|V'|`` over
    the driven samples (each sequence's first sample counted as a step of 0, not the jump from
    its rest voltage)."""
    own = segment_mean(
        driven_items(items),
        lambda seq, v: np.abs(np.diff(v, prepend=v[:1])) * seq.rate_hz,
    )
    return f", {rate / own:.3g}x the records' {own:.3g} V/s" if own > 0 else ""


def _what(current: Model) -> str:
    """The current model in words: "the model" or "the model with X and Y"."""
    if not current.effects:
        return "the model"
    return "the model with " + " and ".join(e.name for e in current.effects)


#: how the verdict of a model left unexplained by its candidates begins
UNEXPLAINED = "Unexplained: "


def refused_sentence(trial: SparseOdeTrial) -> str:
    """The verdict's sentence for a sparse ODE that the acceptance rule refused, with why."""
    c = trial.candidate
    why = "" if "refused:" in c.evidence else "; refused: " + "; ".join(c.reasons)
    return (
        f" Empirical step: {c.evidence}{why}; so the model stays the description of these records."
    )


def adopted_sentence(trial: SparseOdeTrial, before_pct: float | None) -> str:
    """The verdict's paragraph for an adopted sparse ODE."""
    c = trial.candidate
    base = f" (the base model's: {before_pct:.3g} %)" if before_pct is not None else ""
    return (
        f" EMPIRICAL alternative base: {c.evidence}{base}. It replaces the model as the "
        f"description of these records ({EMPIRICAL_NOTE}): the model's operator and relaxors "
        f"miss a dynamics that its terms describe ({readings(trial.model)}); a drive it was "
        "not identified on (other amplitudes and rates, a step) tells whether it holds."
    )


D = TypeVar("D", bound=DiagnosisLike)


def adopt(
    d: D,
    trial: SparseOdeTrial,
    setup: Setup,
    settings: Settings,
    before: Evidence,
) -> D:
    """``d`` with the sparse ODE recorded: a candidate row in a round of its own, and when
    accepted, as the alternative base (``after``, ``effects_added``, class, headline, verdict,
    predictions and the residual's evidence)."""
    c = trial.candidate
    d.rounds.append([c])
    d.candidates.append(
        {
            "effect": NAME,
            "round": c.round + 1,
            "heldout_nrmse_pct": c.heldout_nrmse_pct
            if math.isfinite(c.heldout_nrmse_pct or 0)
            else None,
            "evidence": c.evidence,
        }
    )
    if not c.accepted:
        d.verdict += refused_sentence(trial)
        return d
    ev = collect_evidence(list(setup.records), trial.predictions, settings.warmup_s)
    d.after = {
        "nrmse_pct": trial.nrmse_pct,
        "heldout_nrmse_pct": trial.heldout_pct,
        "per_entry": dict(trial.per_entry),
    }
    params = trial.model.params()
    params["empirical"] = True
    d.effects_added.append({"effect": NAME, "params": params, "evidence": c.evidence})
    d.classification = "partially_explained"
    if d.verdict.startswith(UNEXPLAINED):
        d.verdict = (
            "Partially explained by an EMPIRICAL alternative base (the sparse ODE below); of "
            "the model's candidates: " + d.verdict[len(UNEXPLAINED) :]
        )
    d.verdict += adopted_sentence(trial, d.before.get("heldout_nrmse_pct"))
    added = [f"{NAME} (EMPIRICAL alternative base, in place of {trial.replaced})"]
    d.headline = headline(d.classification, before, ev, d.before, d.after, added)
    d.evidence_after = ev
    d.predictions_after = dict(trial.predictions)
    return d


def sparse_ode_step(
    d: D,
    setup: Setup,
    settings: Settings,
    before: Model,
    current: Model,
    rnd: int,
    say: Progress,
) -> D:
    """The sparse-ODE candidate of the empirical step (module docstring), tried when the
    final model is still above :data:`~.verdict.AT_FLOOR` times the noise floor."""
    if current.evidence.ratio <= AT_FLOOR:
        return d
    try:
        trial = sparse_ode_trial(setup, settings, current, rnd, say)
    except ValueError as exc:
        d.messages.append(f"sparse ODE not identified: {exc}")
        d.verdict += f" Empirical step: no sparse ODE could be identified ({exc})."
        return d
    return adopt(d, trial, setup, settings, before.evidence)
