"""One simulated sequence of the dynamic model with effects, and its forward sensitivities.

The chain (the paper's Fig. 2 with the effect library's four places, :mod:`labrig.model.effects`):

    V' = voltage effects (V)                      (amplifier and input effects)
    x_t = r + G_t (V' - r),  V* = r + G_d (x_t - r)    (relaxors at rest at r before the sequence)
    S = H[V*] + operator effects (V*)             (the quasi-static operator, held at r)
    y = output effects (S)                        (operator gain, creep, measuring chain)

``r`` is the voltage the actuator is held at before the sequence (0 V for a run; a held start's
voltage, through the voltage effects). The relaxors are realised on their modal banks padded to
whole blocks (:func:`~labrig.analysis.simulate.relaxor_output`).

The derivative of ``y`` with respect to each free coordinate (:class:`~labrig.analysis.engine
.Coordinate`) comes out of the same pass: ``alpha0``, ``gamma``, ``vc`` from the operator's own
sensitivities; the relaxors' ``tau`` and ``lam`` from the banks' sensitivities, carried through
``G_d`` (linear) and the operator's tangent with its branch structure held fixed (with the
``"last_reversal"`` memory a tiny wiggle of ``V*`` changes the structure, so differences of the
operator itself are no derivative there); a voltage effect's parameters by a difference of the
effect alone, then through the (linear) relaxors; an operator or output effect's parameters by a
difference of that effect alone. Every column is then passed through the output effects' tangents
(:meth:`~labrig.model.effects.Effect.tangent`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.simulate import (
    LRUCache,
    OperatorFamily,
    SimSequence,
    pad_to_block,
    relaxor_output,
    relaxor_sensitivities,
)
from labrig.model import QuasiStaticHysteresis
from labrig.model.effects import Effect

__all__ = [
    "OPERATOR_PARAMS",
    "RELAXOR_PARAMS",
    "Forward",
    "operator_sensitivities",
    "simulate_sequence",
]

#: the operator's parameters, in the order of its sensitivities
OPERATOR_PARAMS = ("alpha0_ue_per_V", "gamma_ue_per_V", "vc_V")
#: each relaxor's (order, time constant)
RELAXOR_PARAMS = {"t": ("lam_t", "tau_t_s"), "d": ("lam_d", "tau_d_s")}

#: a directional step (relative to the size of V*) for an operator effect's derivative
_DIRECTIONAL = 1e-6


@dataclass
class Forward:
    """A sequence simulated: the strain ``y`` (ue, before nuisance terms) and, when asked,
    ``J[:, j] = dy / dz_j`` for the coordinates ``names`` (``(who, parameter)`` pairs)."""

    y: NDArray[np.float64]
    J: NDArray[np.float64] | None
    names: tuple[tuple[str, str], ...]


def operator_sensitivities(
    op: QuasiStaticHysteresis, u: NDArray, held_V: float, du: NDArray | None, params: bool
) -> tuple[NDArray, NDArray | None, NDArray | None]:
    """``S = op.apply(u, op.held_state(held_V))``; with ``params`` its derivatives with respect to
    ``alpha0``, ``gamma`` and ``vc`` (N x 3), and its tangents along the columns of ``du``
    (N x k) with the branch structure held fixed."""
    fn = getattr(op, "sensitivities", None)
    if fn is not None:
        return fn(u, held_V, du, params=params)
    S = op.apply(u, op.held_state(held_V))
    dP = None
    if params:
        dP = np.empty((u.size, 3))
        # S = alpha0 u + gamma G_vc(u) for a fixed branch structure (the structure depends on u
        # only, F being increasing)
        dP[:, 0] = u
        unit = QuasiStaticHysteresis(1.0, 1.0, op.vc, op.shape, op.memory)
        dP[:, 1] = unit.apply(u, unit.held_state(held_V)) - u
        if op._shape.name == "linear":
            dP[:, 2] = 0.0
        else:
            h = 1e-5
            hi = QuasiStaticHysteresis(1.0, 1.0, op.vc * np.exp(h), op.shape, op.memory)
            lo = QuasiStaticHysteresis(1.0, 1.0, op.vc * np.exp(-h), op.shape, op.memory)
            d = hi.apply(u, hi.held_state(held_V)) - lo.apply(u, lo.held_state(held_V))
            dP[:, 2] = op.gamma * d / (2 * h) / op.vc
    dU = None
    if du is not None:
        dU = np.column_stack([op.tangent(u, du[:, i], held_V) for i in range(du.shape[1])])
    return S, dP, dU


def _effect_difference(e: Effect, c, x: NDArray, ctx, p: Mapping[str, float]) -> NDArray:
    """d e.apply(x) / dz for the effect's own coordinate ``c`` (``x`` held fixed)."""
    return _difference(c, c.coordinate(p[c.name]), lambda v: e.apply(x, ctx, {**p, c.name: v}))


def _own_columns(
    e: Effect, coords: Sequence, x: NDArray, ctx, p: Mapping[str, float], J: NDArray, filled
) -> None:
    """Fill the Jacobian's columns of effect ``e``'s own coordinates: ``d e.apply(x) / dz``,
    in closed form when the effect gives it (times ``dvalue/dz`` on a log scale), else by
    differences."""
    mine = [(j, c) for j, c in enumerate(coords) if c.who == e.name]
    if not mine:
        return
    closed = e.parameter_derivatives(x, ctx, p)
    for j, c in mine:
        if closed is not None and c.name in closed:
            d = closed[c.name]
            J[:, j] = d * p[c.name] if c.kind == "log" else d
        else:
            J[:, j] = _effect_difference(e, c, x, ctx, p)
        filled[j] = True


def _voltage(v: NDArray, effects: Sequence[Effect], ctx, eff) -> NDArray:
    for e in effects:
        v = e.apply(v, ctx, eff.get(e.name, {}))
    return v


def _rest(seq: SimSequence, v: NDArray, through_effects: bool) -> float:
    """The voltage the actuator is held at before the sequence: its first record's rest voltage,
    or, through voltage effects, the effects' first sample (a held start)."""
    if seq.rest_V == 0.0:
        return 0.0
    return float(v[0]) if through_effects else float(seq.rest_V)


def _shifted(eff, who: str, name: str, value: float) -> dict:
    out = {k: dict(v) for k, v in eff.items()}
    out.setdefault(who, {})[name] = value
    return out


def _difference(c, z: float, f) -> NDArray:
    """``df/dz`` at ``z`` for the coordinate ``c`` (``f`` of the parameter's value): central
    differences with the coordinate's step, one-sided within ``step`` of a bound."""
    h = c.step if c.step is not None else 1e-6 * max(1.0, abs(z))
    if z - h >= c.lo and z + h <= c.hi:
        return (f(c.value(z + h)) - f(c.value(z - h))) / (2 * h)
    if z + h > c.hi:
        h = -h
    return (f(c.value(z + h)) - f(c.value(z))) / h


@dataclass
class Relaxed:
    """``V*`` over a sequence (ue of the operator's input, V), the rest voltage before it, and
    ``dV*/dz`` for the coordinates that move it, by ``(who, parameter)``."""

    x: NDArray[np.float64]
    rest: float
    dx: dict[tuple[str, str], NDArray[np.float64]]


def _effects_key(effects: Sequence[Effect], eff: Mapping[str, Mapping[str, float]]) -> tuple:
    """The effects ``effects`` and their parameter values, as a hashable key."""
    return tuple(
        (e.name, tuple(sorted((k, float(v)) for k, v in eff.get(e.name, {}).items())))
        for e in effects
    )


def _direct(_key: Hashable, make: Callable[[], Any]) -> Any:
    return make()


def _about_rest(
    tau: float, lam: float, rate_hz: float, hold: str, dx: NDArray, drest: float
) -> NDArray:
    """A column ``dx`` through a relaxor (linear), its rest ``drest`` held before the sequence."""
    return drest + relaxor_output(tau, lam, rate_hz, hold, dx - drest)


def relaxed_input(
    seq: SimSequence,
    base: Mapping[str, float],
    eff: Mapping[str, Mapping[str, float]],
    vol: Sequence[Effect],
    coords: Sequence,
    with_gd: bool = True,
    memo: LRUCache | None = None,
) -> Relaxed:
    """Steps 1-3 of the chain (module docstring): the voltage effects and the two relaxors, and
    the derivatives of ``V*`` with respect to the coordinates among ``coords`` that move it
    (the relaxors' parameters, the voltage effects' parameters).

    ``memo``: a cache of the passes over the sequence (each relaxor's output or sensitivities,
    each column's difference or tangent), keyed by what each pass depends on (the sequence,
    the voltage effects' values, the relaxors' parameters up to that pass, the column's
    coordinate): a pass already made for another evaluation (the same relaxors with other
    operator or effect parameters, the residual before its Jacobian, another start or fold) is
    taken from it instead of being run again, the very same numbers."""
    ctx = seq.context
    n = seq.n
    vol_names = {e.name for e in vol}
    relax = {name: key for key, names in RELAXOR_PARAMS.items() for name in names}
    run = memo.get if memo is not None else _direct
    vkey = (id(seq), _effects_key(vol, eff))

    # 1. the voltage, and each voltage-effect coordinate's change of it
    def voltage() -> tuple[float, NDArray]:
        v = _voltage(seq.voltage_V, vol, ctx, eff)
        return _rest(seq, v, bool(vol)), (pad_to_block(v) if vol else seq.padded)

    rest, vin = run(("voltage", vkey), voltage)
    dv: dict[int, tuple[NDArray, float]] = {}  # j -> (dV'/dz_j padded, d rest / dz_j)
    for j, c in enumerate(coords):
        if c.who in vol_names:

            def shifted(x: float, c=c) -> NDArray:
                vp = _voltage(seq.voltage_V, vol, ctx, _shifted(eff, c.who, c.name, x))
                return np.append(pad_to_block(vp), _rest(seq, vp, True))

            def column(c=c, shifted=shifted) -> tuple[NDArray, float]:
                d = _difference(c, c.coordinate(eff[c.who][c.name]), shifted)
                return d[:-1], float(d[-1])

            dv[j] = run(("dv", vkey, c), column)

    # 2. G_t, its sensitivities, and the voltage columns through it (linear)
    lam_t, tau_t = base["lam_t"], base["tau_t_s"]
    gt = (float(tau_t), float(lam_t))
    want_t = [j for j, c in enumerate(coords) if c.who == "base" and relax.get(c.name) == "t"]
    dx: dict[int, NDArray] = {}
    rate, hold = seq.rate_hz, seq.hold
    if want_t:
        xkey: tuple = ("gt_sens", vkey, gt)
        xt, d_logtau, d_lam = run(
            xkey, lambda: relaxor_sensitivities(tau_t, lam_t, rate, hold, vin, rest)
        )
        for j in want_t:
            dx[j] = d_lam if coords[j].name == "lam_t" else d_logtau
    else:
        xkey = ("gt", vkey, gt)
        xt = run(xkey, lambda: relaxor_output(tau_t, lam_t, rate, hold, vin, rest))
    for j, (dvin, drest) in dv.items():
        dx[j] = run(
            ("gt_col", vkey, gt, coords[j]),
            partial(_about_rest, tau_t, lam_t, rate, hold, dvin, drest),
        )

    # 3. G_d (linear hold: its input is G_t's smooth output), the columns so far through it
    if with_gd:
        lam_d, tau_d = base["lam_d"], base["tau_d_s"]
        gd = (float(tau_d), float(lam_d))
        want_d = [j for j, c in enumerate(coords) if c.who == "base" and relax.get(c.name) == "d"]
        for j in list(dx):
            drest = dv[j][1] if j in dv else 0.0
            dx[j] = run(
                ("gd_col", xkey, gd, coords[j]),
                partial(_about_rest, tau_d, lam_d, rate, "linear", dx[j], drest),
            )
        if want_d:
            xd, d_logtau, d_lam = run(
                ("gd_sens", xkey, gd),
                lambda: relaxor_sensitivities(tau_d, lam_d, rate, "linear", xt, rest),
            )
            for j in want_d:
                dx[j] = d_lam if coords[j].name == "lam_d" else d_logtau
        else:
            xd = run(
                ("gd", xkey, gd), lambda: relaxor_output(tau_d, lam_d, rate, "linear", xt, rest)
            )
    else:
        xd = xt
    return Relaxed(xd[:n], rest, {(coords[j].who, coords[j].name): dx[j][:n] for j in sorted(dx)})


def moves_input(c, vol: Sequence[Effect]) -> bool:
    """Whether coordinate ``c`` moves ``V*`` (a relaxor's or a voltage effect's parameter)."""
    if c.who == "base":
        return c.name in RELAXOR_PARAMS["t"] or c.name in RELAXOR_PARAMS["d"]
    return any(e.name == c.who for e in vol)


def simulate_sequence(
    seq: SimSequence,
    family: OperatorFamily,
    base: Mapping[str, float],
    eff: Mapping[str, Mapping[str, float]],
    effects: Sequence[Effect],
    coords: Sequence,
    with_gd: bool = True,
    relaxed: Relaxed | None = None,
    operator_map: tuple[list[int], NDArray] | None = None,
) -> Forward:
    """``seq`` simulated with ``effects`` (module docstring); the derivatives with respect to
    the coordinates ``coords`` (none: the strain only). ``relaxed``: steps 1-3 already done
    (:func:`relaxed_input` for the same parameters and coordinates); ``operator_map``: the
    operator's coordinates and ``d(alpha0, gamma, vc) / dz`` for them
    (:meth:`~labrig.analysis.engine.Coordinates.operator_map`)."""
    ctx = seq.context
    vol = [e for e in effects if e.where == "voltage"]
    opr = [e for e in effects if e.where == "operator"]
    out = [e for e in effects if e.where == "output"]
    n, k = seq.n, len(coords)
    if relaxed is None:
        relaxed = relaxed_input(seq, base, eff, vol, coords, with_gd)
    xd, rest = relaxed.x, relaxed.rest
    index = {(c.who, c.name): j for j, c in enumerate(coords)}
    order = [index[key] for key in relaxed.dx]
    du = np.column_stack(list(relaxed.dx.values())) if order else None
    # 4. the operator and its sensitivities
    op = family.operator(base["alpha0_ue_per_V"], base["gamma_ue_per_V"], base["vc_V"])
    op_idx, op_M = operator_map if operator_map is not None else ([], np.zeros((3, 0)))
    S, dP, dU = operator_sensitivities(op, xd, rest, du if k else None, bool(op_idx) and k > 0)
    J = np.zeros((n, k), order="F") if k else None
    filled = np.zeros(k, dtype=bool)
    if J is not None:
        if op_idx and dP is not None:
            J[:, op_idx] = dP @ op_M
            filled[op_idx] = True
        for i, j in enumerate(order):
            J[:, j] = dU[:, i]
            filled[j] = True

    # 5. operator effects: a strain term beside the operator, from V*
    scale = _DIRECTIONAL * max(float(np.max(np.abs(xd))) if n else 0.0, 1.0)
    for e in opr:
        p = eff.get(e.name, {})
        b = e.apply(xd, ctx, p)
        S += b
        if J is None:
            continue
        for i, j in enumerate(order):
            size = float(np.max(np.abs(du[:, i]))) if du is not None else 0.0
            if size > 0:
                h = scale / size
                J[:, j] += (e.apply(xd + h * du[:, i], ctx, p) - b) / h
        _own_columns(e, coords, xd, ctx, p, J, filled)

    # 6. output effects: each column through their tangents, their own parameters in closed
    # form where the effect gives them, else by differences
    y = S
    for e in out:
        p = eff.get(e.name, {})
        y_next = e.apply(y, ctx, p)
        if J is not None:
            cols = np.flatnonzero(filled)
            if cols.size:
                J[:, cols] = e.tangent_columns(y, J[:, cols], ctx, p)
            _own_columns(e, coords, y, ctx, p, J, filled)
        y = y_next
    names = tuple((c.who, c.name) for c in coords)
    return Forward(np.asarray(y, dtype=float), J, names)
