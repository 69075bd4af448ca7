"""Quasi-static hysteresis operator (the paper's Eq. 1, 2, 10).

    dS = alpha(u, u_s) du,     alpha = alpha0 + h(|u - u_s|),     h(0) = 0

``u`` is the (equivalent static) voltage in V, ``S`` the strain in ue, ``alpha0`` and ``h`` in
ue/V. The memory ``u_s`` is the voltage at a reversal (local extremum of ``u``); the strain there
is ``S_s``. Between reversals the branch has the closed form

    S = S_s + sign(u - u_s) F(|u - u_s|),     F(x) = alpha0 x + int_0^x h(y) dy,

so no integration error is made. Initial state: the actuator rests at 0 V with zero strain
(``u_s = 0``, ``S_s = 0``); a record that begins at a held voltage ``u0`` starts as an actuator
brought there from that rest and held (:meth:`QuasiStaticHysteresis.held_state`).

Which reversal is the memory (``memory``):

- ``"return_point"`` (default): return-point memory (Madelung's rules, the wiping-out property of
  ferroelectric and Preisach hysteresis). The turning points form a stack; a new reversal pushes
  one, and when the input travels past the turning point where the current minor loop began, that
  loop is closed and forgotten (its two turning points are popped) and the branch that was
  interrupted continues. Because a branch from ``(u_s, S_s)`` and back closes exactly at
  ``(u_s, S_s)`` (``S_s + F(x) - F(x)``), the strain is continuous there and the operator is
  continuous in its input: a tiny wiggle of ``u`` makes a tiny minor loop and nothing else.
- ``"last_reversal"``: the spec's literal single memory, ``u_s`` = the last extremum. It agrees
  with ``"return_point"`` whenever no extremum passes an earlier turning point (steady sines,
  vanishing envelopes), but a reversal of any size, even 1e-7 V, forgets the whole history: a
  relaxor's 0.3 mV overshoot in ``V*`` during a rest then moves the strain by up to 30 ue, which
  makes identification from campaigns with rests ill-posed (docs/analysis.md, "memory").

Shapes of ``h`` (``gamma`` in ue/V, ``vc`` in V):

- ``"exponential"`` (fitted in the paper): ``h(x) = gamma (1 - exp(-x/vc))``
- ``"linear"`` (a differential Rayleigh law): ``h(x) = gamma x`` (``vc`` unused)
- ``"gaussian"``: ``h(x) = gamma (1 - exp(-(x/vc)^2))``
- any callable ``h(x)`` with ``h(0) = 0`` via :class:`Shape` (its integral is then evaluated by
  48-point Gauss-Legendre quadrature, exact for polynomials up to degree 95).

Inversion (strain to voltage) solves ``F(x) = y`` on each branch: Lambert W for the exponential
shape, the quadratic formula for the linear one, and safeguarded Newton iterations otherwise,
finished by Newton steps to machine precision.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

SHAPES = ("exponential", "linear", "gaussian")
MEMORY_RULES = ("return_point", "last_reversal")
_GL48_X, _GL48_W = np.polynomial.legendre.leggauss(48)


@dataclass(frozen=True)
class Shape:
    """A hysteretic slope ``h(x; gamma, vc)`` and (optionally) its integral ``H(x) = int_0^x h``."""

    name: str
    h: Callable[[NDArray, float, float], NDArray]
    H: Callable[[NDArray, float, float], NDArray] | None = None

    def integral(self, x: NDArray, gamma: float, vc: float) -> NDArray:
        if self.H is not None:
            return self.H(x, gamma, vc)
        x = np.asarray(x, dtype=float)
        nodes = 0.5 * x[..., None] * (_GL48_X + 1.0)
        return 0.5 * x * np.sum(_GL48_W * self.h(nodes, gamma, vc), axis=-1)


def _exp_H(x, g, vc):
    return g * (x + vc * np.expm1(-x / vc))


def _gauss_H(x, g, vc):
    return g * (x - vc * np.sqrt(np.pi) / 2 * special.erf(x / vc))


BUILTIN_SHAPES: dict[str, Shape] = {
    "exponential": Shape("exponential", lambda x, g, vc: -g * np.expm1(-x / vc), _exp_H),
    "linear": Shape("linear", lambda x, g, vc: g * x, lambda x, g, vc: 0.5 * g * x * x),
    "gaussian": Shape("gaussian", lambda x, g, vc: -g * np.expm1(-((x / vc) ** 2)), _gauss_H),
}


@dataclass
class HysteresisState:
    """Memory of the operator between calls (streaming): the current branch's turning point, the
    older turning points still remembered (``"return_point"`` memory) and the last input."""

    u_s: float = 0.0  # input at the current branch's turning point (V)
    s_s: float = 0.0  # output there (ue)
    u_last: float = 0.0  # last input seen (V); 0 V at rest
    s_last: float = 0.0  # last output (ue)
    direction: float = 0.0  # +1 rising, -1 falling, 0 not yet moved
    #: older turning points ``(u, S)`` still remembered, oldest first (return-point memory)
    older: list[tuple[float, float]] = field(default_factory=list)


@dataclass(frozen=True)
class QuasiStaticHysteresis:
    """The operator ``u (V) -> S (ue)``; see the module docstring."""

    alpha0: float
    gamma: float
    vc: float = 1.0
    shape: str | Shape = "exponential"
    memory: str = "return_point"
    _shape: Shape = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.shape, Shape):
            shp = self.shape
        elif self.shape in BUILTIN_SHAPES:
            shp = BUILTIN_SHAPES[self.shape]
        else:
            raise ValueError(f"shape must be one of {SHAPES} or a Shape, got {self.shape!r}")
        if not self.alpha0 > 0:
            raise ValueError(f"alpha0 must be positive (ue/V), got {self.alpha0!r}")
        if not self.vc > 0:
            raise ValueError(f"vc must be positive (V), got {self.vc!r}")
        if self.memory not in MEMORY_RULES:
            raise ValueError(f"memory must be one of {MEMORY_RULES}, got {self.memory!r}")
        object.__setattr__(self, "_shape", shp)

    # -- branch function ----------------------------------------------------------------------
    def branch(self, x: ArrayLike) -> NDArray[np.float64]:
        """``F(x) = alpha0 x + int_0^x h`` for ``x >= 0`` (strain change along a branch, ue)."""
        x = np.asarray(x, dtype=float)
        return self.alpha0 * x + self._shape.integral(x, self.gamma, self.vc)

    def slope(self, x: ArrayLike) -> NDArray[np.float64]:
        """``alpha = alpha0 + h(x)`` (ue/V) at distance ``x`` from the last reversal."""
        x = np.asarray(x, dtype=float)
        return self.alpha0 + self._shape.h(x, self.gamma, self.vc)

    def _odd_branch(self, d: NDArray) -> NDArray:
        return np.sign(d) * self.branch(np.abs(d))

    def branch_inverse(self, y: ArrayLike) -> NDArray[np.float64]:
        """``x >= 0`` with ``F(x) = y`` for ``y >= 0`` (V)."""
        y = np.asarray(y, dtype=float)
        a0, g, vc = self.alpha0, self.gamma, self.vc
        name = self._shape.name if self._shape.H is not None else ""
        if name == "exponential" and a0 + g > 0 and g >= 0:
            a, b = a0 + g, g * vc
            arg = -(g / a) * np.exp(-(y + b) / (a * vc))
            x = (y + b) / a + vc * special.lambertw(arg, 0).real
        elif name == "linear" and g > 0:
            x = (-a0 + np.sqrt(a0 * a0 + 2.0 * g * y)) / g
        else:
            x = self._bracketed_inverse(y)
        x = np.maximum(x, 0.0)
        for _ in range(2):  # polish to machine precision
            x = np.maximum(x - (self.branch(x) - y) / self.slope(x), 0.0)
        return x

    def _bracketed_inverse(self, y: NDArray) -> NDArray:
        lo = np.zeros_like(y)
        hi = np.maximum(y / self.alpha0, 1e-12)
        while np.any(self.branch(hi) < y):
            hi = np.where(self.branch(hi) < y, 2 * hi, hi)
        x = 0.5 * (lo + hi)
        for _ in range(200):
            f = self.branch(x) - y
            lo = np.where(f < 0, x, lo)
            hi = np.where(f >= 0, x, hi)
            xn = x - f / self.slope(x)
            bad = (xn <= lo) | (xn >= hi) | ~np.isfinite(xn)
            xn = np.where(bad, 0.5 * (lo + hi), xn)
            if np.all(np.abs(xn - x) <= 1e-15 * np.maximum(1.0, np.abs(x))):
                return xn
            x = xn
        return x

    # -- operator -----------------------------------------------------------------------------
    @property
    def _wipe(self) -> bool:
        return self.memory == "return_point"

    def _along(self, a: NDArray, b: NDArray) -> NDArray:
        """Strain change (ue) along a branch from input ``a`` to ``b`` (V)."""
        return self._odd_branch(b - a)

    def held_state(self, u0_V: float) -> HysteresisState:
        """The state of an actuator brought from rest at 0 V to ``u0_V`` (V) and held there: the
        state before a record that begins at a held voltage. The rest point at 0 V stays the
        bottom of the memory, the input arrived at ``u0_V`` along the first branch
        (strain ``sign(u0) F(|u0|)``)."""
        u0 = float(u0_V)
        d = float(np.sign(u0))
        return HysteresisState(0.0, 0.0, u0, d * float(self.branch(abs(u0))), d)

    def apply(self, u: ArrayLike, state: HysteresisState | None = None) -> NDArray[np.float64]:
        """Strain (ue) for the voltage record ``u`` (V). ``state`` is updated in place if given."""
        u = _finite(u, "voltage")
        st = HysteresisState() if state is None else state
        if u.size == 0:
            return np.zeros(0)
        br, stack, d = _branches(
            u, [*st.older, (st.u_s, st.s_s)], st.u_last, st.direction, self._along, self._wipe
        )
        out = br.per_sample(br.y0) + self._odd_branch(u - br.per_sample(br.x0))
        st.older, (st.u_s, st.s_s), st.direction = stack[:-1], stack[-1], d
        st.u_last, st.s_last = float(u[-1]), float(out[-1])
        return out

    def tangent(self, u: ArrayLike, du: ArrayLike, held_V: float = 0.0) -> NDArray[np.float64]:
        """Derivative of ``apply(u, self.held_state(held_V))`` along ``du`` (the voltage it was
        held at does not move), with the branch structure (which samples are turning points,
        which minor loops close where) held fixed (ue per unit of ``du``'s scale).

        On the branch from turning point ``k``: ``S[n] = S_k + sign F(|u[n] - u_k|)``, and
        ``S_k = S_p + sign F(|u_k - u_p|)`` with ``p`` the turning point whose branch led to
        ``k``, so ``dS[n] = dS_k + alpha(|u[n] - u_k|) (du[n] - du_k)`` and ``dS_k = dS_p +
        alpha(|u_k - u_p|) (du_k - du_p)``, ``alpha = F'``; the rest point does not move. For
        the ``"last_reversal"`` memory the structure changes when a tiny wiggle appears, which
        is why differences of ``apply`` itself are no derivative there.
        """
        u = np.asarray(u, dtype=float)
        du = np.asarray(du, dtype=float)
        if u.size == 0:
            return np.zeros(0)
        h = float(held_V)
        br, _, _ = _branches(u, [(0.0, 0.0)], h, float(np.sign(h)), self._along, self._wipe)
        dx0 = np.where(br.at >= 0, du[np.maximum(br.at, 0)], 0.0)
        dy0 = np.zeros(br.x0.size)
        new = np.flatnonzero(br.parent >= 0)
        par = br.parent[new]
        step = (self.slope(np.abs(br.x0[new] - br.x0[par])) * (dx0[new] - dx0[par])).tolist()
        acc = dy0.tolist()
        for k, p, dk in zip(new.tolist(), par.tolist(), step, strict=True):
            acc[k] = acc[p] + dk
        dy0 = np.asarray(acc)
        x0 = br.per_sample(br.x0)
        return br.per_sample(dy0) + self.slope(np.abs(u - x0)) * (du - br.per_sample(dx0))

    def invert(self, strain: ArrayLike, state: HysteresisState | None = None) -> NDArray:
        """Voltage (V) whose :meth:`apply` gives ``strain`` (ue), branch by branch.

        ``F`` is increasing, so reversals and closed loops of the strain coincide with those of
        the voltage: the same branch structure is built on the strain record and each branch is
        inverted in closed form.
        """
        s = _finite(strain, "strain")
        st = HysteresisState() if state is None else state
        if s.size == 0:
            return np.zeros(0)

        def inv(d: NDArray) -> NDArray:
            return np.sign(d) * self.branch_inverse(np.abs(d))

        br, stack, d = _branches(
            s,
            [(b, a) for a, b in st.older] + [(st.s_s, st.u_s)],
            st.s_last,
            st.direction,
            lambda a, b: inv(b - a),
            self._wipe,
        )
        u = br.per_sample(br.y0) + inv(s - br.per_sample(br.x0))
        st.older = [(b, a) for a, b in stack[:-1]]
        st.s_s, st.u_s = stack[-1]
        st.direction = d
        st.u_last, st.s_last = float(u[-1]), float(s[-1])
        return u


def _finite(x: ArrayLike, what: str) -> NDArray[np.float64]:
    """``x`` as a float array; a NaN or infinity would corrupt the remembered turning points."""
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"the {what} record must be finite (found NaN or infinity)")
    return a


@dataclass(frozen=True)
class _Branches:
    """Branch structure of a record: the record is cut into consecutive segments of
    ``counts`` samples, segment ``j`` on the branch that starts at turning point
    ``seg_anchor[j]``, whose input and output are ``x0``, ``y0``; ``at`` is each turning point's
    sample (-1: carried in from before the record), ``parent`` the turning point whose branch
    reached it (-1: carried in)."""

    seg_anchor: NDArray[np.intp]
    counts: NDArray[np.intp]
    x0: NDArray[np.float64]
    y0: NDArray[np.float64]
    at: NDArray[np.intp]
    parent: NDArray[np.intp]

    def per_sample(self, values: NDArray) -> NDArray:
        """``values`` (one per turning point) at each sample's turning point."""
        return np.repeat(values[self.seg_anchor], self.counts)


def _monotone_runs(
    x: NDArray, x_last: float, direction: float
) -> tuple[NDArray, NDArray[np.intp], NDArray[np.intp], NDArray]:
    """The monotone runs of ``x`` (preceded by ``x_last``, travelling in ``direction``):
    whether each sample starts a reversal, each run's first and end (exclusive) sample, and its
    direction. Flat stretches keep the direction before them and are not reversals."""
    n = x.size
    d = np.sign(np.diff(x, prepend=x_last))
    if d[0] == 0:
        d[0] = direction
    nz = d != 0
    if not nz.all():  # flat stretches keep the direction before them
        idx = np.where(nz, np.arange(n), 0)
        np.maximum.accumulate(idx, out=idx)
        d = np.where(nz[idx], d[idx], 0.0)
    before = np.empty(n)
    before[0] = direction
    before[1:] = d[:-1]
    reversal = (d != before) & (d != 0) & (before != 0)
    rev = np.flatnonzero(reversal)
    starts = rev if rev.size and rev[0] == 0 else np.concatenate(([0], rev))
    ends = np.append(starts[1:], n)
    return reversal, starts, ends, d[ends - 1]  # each run's samples are monotone its way


def _first_past(
    x: NDArray, lo: NDArray[np.intp], hi: NDArray[np.intp], dirs: NDArray, thr: NDArray
) -> NDArray[np.intp]:
    """For each monotone run ``x[lo:hi + 1]`` travelling in ``dirs``, the first sample at or past
    ``thr`` (vectorised bisection; the runs are known to reach it)."""
    pos = lo.copy()
    while np.any(pos < hi):
        mid = (pos + hi) // 2
        past = dirs * x[mid] >= dirs * thr
        hi = np.where(past, mid, hi)
        pos = np.where(past, pos, np.minimum(mid + 1, hi))
    return pos


def _branches(
    x: NDArray,
    stack: list[tuple[float, float]],
    x_last: float,
    direction: float,
    delta: Callable[[NDArray, NDArray], NDArray],
    wipe: bool,
) -> tuple[_Branches, list[tuple[float, float]], float]:
    """Find the branch structure of ``x`` (module docstring, memory rules).

    ``stack``: the remembered turning points ``(x, y)``, oldest first, the last one the current
    branch's; ``delta(x_a, x_b)``: the output change along a branch from ``x_a`` to ``x_b``;
    ``wipe``: return-point memory (close and forget minor loops), else the last reversal only.
    Returns the structure, the new stack and the new direction. A reversal detected at sample
    ``n`` has its extremum at ``n - 1`` (or at ``x_last``); flat stretches are not reversals.
    One Python step per monotone run; where branches start and the branches themselves are
    found and evaluated vectorised.
    """
    n = x.size
    reversal, starts, ends, dirs = _monotone_runs(x, x_last, direction)
    x_ext = np.where(starts > 0, x[np.maximum(starts - 1, 0)], x_last)  # the turning point

    m = len(stack)
    is_rev = reversal[starts]
    rev_runs = np.flatnonzero(is_rev)
    node_of_run = np.where(is_rev, m + np.cumsum(is_rev) - 1, -1)  # a turning point per reversal
    xs = [p[0] for p in stack] + x_ext[rev_runs].tolist()
    at = np.concatenate((np.full(m, -1, dtype=np.intp), starts[rev_runs] - 1))
    parent = [-1] * m
    live = list(range(m))  # ids of the remembered turning points, oldest first
    anchor0 = live[-1]
    cross_run: list[int] = []  # branches that start where a run passes a turning point
    cross_thr: list[float] = []
    cross_anchor: list[int] = []
    runs = zip(node_of_run.tolist(), dirs.tolist(), x[ends - 1].tolist(), strict=True)
    for j, (node, dj, x_far) in enumerate(runs):
        if node >= 0:
            parent.append(live[-1])
            if wipe:
                live.append(node)
            else:  # the last reversal only: nothing older is remembered
                live[:] = [node]
        if wipe and dj != 0.0:
            far = dj * x_far  # a run is monotone: its last sample is its farthest
            while len(live) >= 2 and far >= dj * xs[live[-2]]:
                # the run reaches the turning point where the current minor loop began: close
                # the loop and forget it (the rest point at the bottom stays). Closing on
                # reaching, not passing, gives the same strain (the branches meet there) and
                # keeps the stack from growing under exactly repeated extrema
                cross_run.append(j)
                cross_thr.append(xs[live[-2]])
                del live[-2 if len(live) >= 3 else -1 :]
                cross_anchor.append(live[-1])
    # where each branch starts: a reversal run's first sample, or the first sample of a run past
    # a turning point (vectorised bisection inside the monotone run)
    cj = np.asarray(cross_run, dtype=np.intp)
    pos_c = _first_past(x, starts[cj], ends[cj] - 1, dirs[cj], np.asarray(cross_thr))
    pos = np.concatenate(([0], starts[rev_runs], pos_c))
    anchors = np.concatenate(([anchor0], node_of_run[rev_runs], cross_anchor)).astype(np.intp)
    # in time order; at one sample a run's reversal comes before the turning points it passes
    key = 2 * pos + np.concatenate(([0], np.zeros(rev_runs.size), np.ones(cj.size)))
    order = np.argsort(key, kind="stable")
    counts = np.diff(np.concatenate((pos[order], [n])))
    ys = [p[1] for p in stack]
    if rev_runs.size:
        par = parent[m:]
        xa = np.asarray(xs)
        steps = delta(xa[par], xa[m:]).tolist()
        for pk, dk in zip(par, steps, strict=True):  # parents come first: ids in order
            ys.append(ys[pk] + dk)
    new_dir = float(dirs[-1]) if dirs[-1] != 0 else direction
    parents = np.asarray(parent, dtype=np.intp)
    out = _Branches(anchors[order], counts, np.asarray(xs), np.asarray(ys), at, parents)
    return out, [(xs[k], ys[k]) for k in live], float(new_dir)
