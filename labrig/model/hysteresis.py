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
- ``"return_point_open"``: return-point memory in which the rest point only anchors the first
  branch: no loop closes onto it. With ``"return_point"`` a branch that reaches 0 V after an
  excursion from rest closes the excursion's loop there and goes on along the initial curve,
  so the loops of a bipolar drive (or any drive crossing 0 V) are pinched at 0 V; here the
  branch from a reversal goes on through 0 V, and a bipolar loop is open there (its width at
  0 V, ``F(2A) - 2F(A)`` for amplitude ``A``). For a drive that never goes below 0 V (the
  paper's) the two agree: a branch that returns to 0 V meets the initial curve there.
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

Evaluation: for the builtin shapes :meth:`~QuasiStaticHysteresis.apply` and
:meth:`~QuasiStaticHysteresis.sensitivities` run one sequential compiled pass
(:func:`labrig.model.compiled.operator_pass`: structure, values and derivatives together);
``engine="numpy"``, a user :class:`Shape` or a missing numba run the numpy code below, which
finds the branch structure vectorised (one Python step per monotone run) and is the reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.model.accel import kernels

SHAPES = ("exponential", "linear", "gaussian")
MEMORY_RULES = ("return_point", "last_reversal", "return_point_open")
#: each memory rule as the operator's kernels read it: the least number of remembered turning
#: points a minor loop may close onto (2: down to the rest point; 3: never onto the rest point),
#: 0 for the last reversal only
_CLOSE_FLOOR = {"return_point": 2, "return_point_open": 3, "last_reversal": 0}
_GL48_X, _GL48_W = np.polynomial.legendre.leggauss(48)


#: relative step of the central differences that give a user shape's ``dH/dgamma``, ``dH/dvc``
#: when it does not state them (rounding ~1e-10 relative; exact in gamma for ``h`` linear in it)
FD_STEP = 1e-6

Fn = Callable[[NDArray, float, float], NDArray]


@dataclass(frozen=True)
class Shape:
    """A hysteretic slope ``h(x; gamma, vc)``, optionally its integral ``H(x) = int_0^x h`` and
    the integral's derivatives ``dH/dgamma`` and ``dH/dvc`` (for :meth:`sensitivities`).

    Parameters
    ----------
    name : str
        The shape's name (reports, errors).
    h : callable
        ``h(x, gamma, vc)``: the slope's variation (ue/V) at distances ``x >= 0`` (V), with
        ``h(0) = 0``.
    H : callable, optional
        ``H(x, gamma, vc) = int_0^x h`` (ue); by quadrature when not given.
    dH_dgamma, dH_dvc : callable, optional
        Derivatives of ``H``; by central differences when not given.

    Examples
    --------
    A quadratic slope, its integral by quadrature: ``H(2) = gamma 2^3 / 3``.

    >>> import numpy as np
    >>> cubic = Shape("cubic", lambda x, g, vc: g * x**2)
    >>> round(float(cubic.integral(np.array(2.0), 3.0, 1.0)), 12)
    8.0
    """

    name: str
    h: Fn
    H: Fn | None = None
    dH_dgamma: Fn | None = None
    dH_dvc: Fn | None = None

    def integral(self, x: NDArray, gamma: float, vc: float) -> NDArray:
        """The integral of the slope's variation.

        Parameters
        ----------
        x : numpy.ndarray
            Distances from the turning point (V, ``>= 0``).
        gamma : float
            The shape's ``gamma`` (ue/V).
        vc : float
            The shape's ``vc`` (V).

        Returns
        -------
        numpy.ndarray
            ``H(x) = int_0^x h`` (ue): the stated closed form, else 48-point Gauss-Legendre.
        """
        if self.H is not None:
            return self.H(x, gamma, vc)
        x = np.asarray(x, dtype=float)
        nodes = 0.5 * x[..., None] * (_GL48_X + 1.0)
        return 0.5 * x * np.sum(_GL48_W * self.h(nodes, gamma, vc), axis=-1)

    def integral_derivatives(self, x: NDArray, gamma: float, vc: float) -> tuple[NDArray, NDArray]:
        """``(dH/dgamma, dH/dvc)`` at ``x >= 0``: the stated closed forms, else central
        differences of :meth:`integral` with relative step :data:`FD_STEP`.

        Parameters
        ----------
        x : numpy.ndarray
            Distances from the turning point (V).
        gamma : float
            The shape's ``gamma`` (ue/V).
        vc : float
            The shape's ``vc`` (V).

        Returns
        -------
        dH_dgamma : numpy.ndarray
            ``dH/dgamma`` at ``x``.
        dH_dvc : numpy.ndarray
            ``dH/dvc`` at ``x``.
        """
        x = np.asarray(x, dtype=float)
        if self.dH_dgamma is not None:
            dg = self.dH_dgamma(x, gamma, vc)
        else:
            e = FD_STEP * max(abs(gamma), 1.0)
            dg = (self.integral(x, gamma + e, vc) - self.integral(x, gamma - e, vc)) / (2 * e)
        if self.dH_dvc is not None:
            dv = self.dH_dvc(x, gamma, vc)
        else:
            e = FD_STEP * vc
            dv = (self.integral(x, gamma, vc + e) - self.integral(x, gamma, vc - e)) / (2 * e)
        return dg, dv


def _erf(x: NDArray) -> NDArray:
    """scipy's erf, imported when first needed: scipy.special costs about half a second of
    CPU to import, and most commands (a simulated run: the compiled operator) never ask."""
    from scipy.special import erf

    return erf(x)


def _exp_H(x: NDArray, g: float, vc: float) -> NDArray:
    return g * (x + vc * np.expm1(-x / vc))


def _exp_dH_dvc(x: NDArray, g: float, vc: float) -> NDArray:
    z = x / vc
    return g * (np.expm1(-z) + z * np.exp(-z))


def _gauss_H(x: NDArray, g: float, vc: float) -> NDArray:
    return g * (x - vc * np.sqrt(np.pi) / 2 * _erf(x / vc))


def _gauss_dH_dvc(x: NDArray, g: float, vc: float) -> NDArray:
    z = x / vc
    return g * (z * np.exp(-z * z) - np.sqrt(np.pi) / 2 * _erf(z))


BUILTIN_SHAPES: dict[str, Shape] = {
    "exponential": Shape(
        "exponential",
        lambda x, g, vc: -g * np.expm1(-x / vc),
        _exp_H,
        lambda x, g, vc: x + vc * np.expm1(-x / vc),
        _exp_dH_dvc,
    ),
    "linear": Shape(
        "linear",
        lambda x, g, vc: g * x,
        lambda x, g, vc: 0.5 * g * x * x,
        lambda x, g, vc: 0.5 * x * x,
        lambda x, g, vc: np.zeros_like(x),
    ),
    "gaussian": Shape(
        "gaussian",
        lambda x, g, vc: -g * np.expm1(-((x / vc) ** 2)),
        _gauss_H,
        lambda x, g, vc: x - vc * np.sqrt(np.pi) / 2 * _erf(x / vc),
        _gauss_dH_dvc,
    ),
}

ENGINES = ("auto", "compiled", "numpy")


@dataclass
class HysteresisState:
    """Memory of the operator between calls (streaming): the current branch's turning point, the
    older turning points still remembered (``"return_point"`` memory) and the last input.

    Parameters
    ----------
    u_s : float
        Input at the current branch's turning point (V).
    s_s : float
        Output there (ue).
    u_last : float
        The last input seen (V).
    s_last : float
        The last output (ue).
    direction : float
        +1 rising, -1 falling, 0 not yet moved.
    older : list of tuple of float
        Older turning points ``(u, S)`` still remembered, oldest first.
    """

    u_s: float = 0.0  # input at the current branch's turning point (V)
    s_s: float = 0.0  # output there (ue)
    u_last: float = 0.0  # last input seen (V); 0 V at rest
    s_last: float = 0.0  # last output (ue)
    direction: float = 0.0  # +1 rising, -1 falling, 0 not yet moved
    #: older turning points ``(u, S)`` still remembered, oldest first (return-point memory)
    older: list[tuple[float, float]] = field(default_factory=list)


@dataclass(frozen=True)
class QuasiStaticHysteresis:
    """The operator ``u (V) -> S (ue)``; see the module docstring.

    Parameters
    ----------
    alpha0 : float
        Small-signal coefficient (ue/V, > 0).
    gamma : float
        Largest variation of the slope (ue/V).
    vc : float
        Saturation voltage (V, > 0).
    shape : {"exponential", "linear", "gaussian"} or Shape
        Shape of the slope's variation ``h``.
    memory : {"return_point", "last_reversal", "return_point_open"}
        Which turning points the operator remembers (module docstring).

    Examples
    --------
    A linear (Rayleigh) shape, ``F(x) = alpha0 x + gamma x^2 / 2``: up to 2 V and back to 0.

    >>> op = QuasiStaticHysteresis(1.0, 0.5, shape="linear")
    >>> op.apply([0.0, 1.0, 2.0, 1.0, 0.0]).tolist()
    [0.0, 1.25, 3.0, 1.75, 0.0]
    """

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
        """``F(x) = alpha0 x + int_0^x h`` for ``x >= 0`` (strain change along a branch, ue).

        Parameters
        ----------
        x : array_like
            Distance from the turning point (V, ``>= 0``).

        Returns
        -------
        numpy.ndarray
            ``F(x)`` (ue).

        Examples
        --------
        >>> float(QuasiStaticHysteresis(1.0, 0.5, shape="linear").branch(2.0))
        3.0
        """
        x = np.asarray(x, dtype=float)
        return self.alpha0 * x + self._shape.integral(x, self.gamma, self.vc)

    def slope(self, x: ArrayLike) -> NDArray[np.float64]:
        """``alpha = alpha0 + h(x)`` (ue/V) at distance ``x`` from the last reversal.

        Parameters
        ----------
        x : array_like
            Distance from the last reversal (V).

        Returns
        -------
        numpy.ndarray
            ``alpha`` (ue/V).
        """
        x = np.asarray(x, dtype=float)
        return self.alpha0 + self._shape.h(x, self.gamma, self.vc)

    def _odd_branch(self, d: NDArray) -> NDArray:
        return np.sign(d) * self.branch(np.abs(d))

    def branch_inverse(self, y: ArrayLike) -> NDArray[np.float64]:
        """``x >= 0`` with ``F(x) = y`` for ``y >= 0`` (V).

        Parameters
        ----------
        y : array_like
            Strain change along a branch (ue, ``>= 0``).

        Returns
        -------
        numpy.ndarray
            ``x`` (V).

        Examples
        --------
        >>> float(QuasiStaticHysteresis(1.0, 0.5, shape="linear").branch_inverse(3.0))
        2.0
        """
        y = np.asarray(y, dtype=float)
        a0, g, vc = self.alpha0, self.gamma, self.vc
        name = self._shape.name if self._shape.H is not None else ""
        if name == "exponential" and a0 + g > 0 and g >= 0:
            a, b = a0 + g, g * vc
            arg = -(g / a) * np.exp(-(y + b) / (a * vc))
            from scipy.special import lambertw

            x = (y + b) / a + vc * lambertw(arg, 0).real
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
    def _wipe(self) -> int:
        """The memory rule for the kernels (:data:`_CLOSE_FLOOR`)."""
        return _CLOSE_FLOOR[self.memory]

    def _along(self, a: NDArray, b: NDArray) -> NDArray:
        """Strain change (ue) along a branch from input ``a`` to ``b`` (V)."""
        return self._odd_branch(b - a)

    def held_state(self, u0_V: float) -> HysteresisState:
        """The state of an actuator brought from rest at 0 V to ``u0_V`` (V) and held there: the
        state before a record that begins at a held voltage. The rest point at 0 V stays the
        bottom of the memory, the input arrived at ``u0_V`` along the first branch
        (strain ``sign(u0) F(|u0|)``).

        Parameters
        ----------
        u0_V : float
            The voltage held (V).

        Returns
        -------
        HysteresisState
            The operator's memory at ``u0_V``.
        """
        u0 = float(u0_V)
        d = float(np.sign(u0))
        return HysteresisState(0.0, 0.0, u0, d * float(self.branch(abs(u0))), d)

    def _kernels(self, engine: str) -> ModuleType | None:
        """The compiled kernels for ``engine`` (``None``: run the numpy code).

        ``"auto"``: compiled for the builtin shapes when numba is available, numpy otherwise;
        ``"compiled"``: compiled or an error; ``"numpy"``: the numpy code (the reference)."""
        if engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        if engine == "numpy":
            return None
        if self._code < 0:
            if engine == "compiled":
                raise ValueError(f"no compiled code for the user shape {self._shape.name!r}")
            return None
        k = kernels()
        if k is None and engine == "compiled":
            raise RuntimeError("the compiled engine needs numba, which could not be imported")
        return k

    @property
    def _code(self) -> int:
        """Kernel code of a builtin shape (its index in :data:`SHAPES`), -1 for a user shape."""
        for i, name in enumerate(SHAPES):
            if self._shape is BUILTIN_SHAPES[name]:
                return i
        return -1

    def apply(
        self, u: ArrayLike, state: HysteresisState | None = None, engine: str = "auto"
    ) -> NDArray[np.float64]:
        """Strain (ue) for the voltage record ``u`` (V). ``state`` is updated in place if given.

        ``engine``: ``"auto"`` (compiled for the builtin shapes when numba is available),
        ``"compiled"`` or ``"numpy"`` (the vectorised branch search, the reference); the two
        agree to rounding (the same closed forms, summed in the same order).

        Parameters
        ----------
        u : array_like
            The voltage record (V), finite.
        state : HysteresisState, optional
            The memory before the record (default: at rest at 0 V); updated in place.
        engine : {"auto", "compiled", "numpy"}
            Which code runs.

        Returns
        -------
        numpy.ndarray
            Strain (ue) at each sample.
        """
        u = _finite(u, "voltage")
        kern = self._kernels(engine)
        st = HysteresisState() if state is None else state
        if u.size == 0:
            return np.zeros(0)
        if kern is not None:
            xs = np.array([p[0] for p in st.older] + [st.u_s], dtype=np.float64)
            ys = np.array([p[1] for p in st.older] + [st.s_s], dtype=np.float64)
            a0, g, vc = float(self.alpha0), float(self.gamma), float(self.vc)
            out, _, _, xs, ys, d = kern.operator_pass(
                u, xs, ys, float(st.u_last), float(st.direction), self._wipe, self._code,
                a0, g, vc, False, np.empty((u.size, 0)),
            )  # fmt: skip
            pts = list(zip(xs.tolist(), ys.tolist(), strict=True))
            st.older, (st.u_s, st.s_s), st.direction = pts[:-1], pts[-1], float(d)
            st.u_last, st.s_last = float(u[-1]), float(out[-1])
            return out
        br, stack, d = _branches(
            u, [*st.older, (st.u_s, st.s_s)], st.u_last, st.direction, self._along, self._wipe
        )
        out = br.per_sample(br.y0) + self._odd_branch(u - br.per_sample(br.x0))
        st.older, (st.u_s, st.s_s), st.direction = stack[:-1], stack[-1], d
        st.u_last, st.s_last = float(u[-1]), float(out[-1])
        return out

    def tangent(
        self, u: ArrayLike, du: ArrayLike, held_V: float = 0.0, engine: str = "auto"
    ) -> NDArray[np.float64]:
        """Derivative of ``apply(u, self.held_state(held_V))`` along ``du`` (the voltage it was
        held at does not move), with the branch structure (which samples are turning points,
        which minor loops close where) held fixed (ue per unit of ``du``'s scale).

        On the branch from turning point ``k``: ``S[n] = S_k + sign F(|u[n] - u_k|)``, and
        ``S_k = S_p + sign F(|u_k - u_p|)`` with ``p`` the turning point whose branch led to
        ``k``, so ``dS[n] = dS_k + alpha(|u[n] - u_k|) (du[n] - du_k)`` and ``dS_k = dS_p +
        alpha(|u_k - u_p|) (du_k - du_p)``, ``alpha = F'``; the rest point does not move. For
        the ``"last_reversal"`` memory the structure changes when a tiny wiggle appears, which
        is why differences of ``apply`` itself are no derivative there. One column of
        :meth:`sensitivities`' ``dS_du``.

        Parameters
        ----------
        u : array_like
            The voltage record (V).
        du : array_like
            The direction of the change of ``u`` (same length).
        held_V : float
            The voltage held before the record (V).
        engine : {"auto", "compiled", "numpy"}
            Which code runs.

        Returns
        -------
        numpy.ndarray
            ``dS`` along ``du`` at each sample.
        """
        du = np.asarray(du, dtype=float)
        dS_du = self.sensitivities(u, held_V, du, params=False, engine=engine)[2]
        assert dS_du is not None  # given du, sensitivities returns its tangent
        return dS_du

    def sensitivities(
        self,
        u: ArrayLike,
        held_V: float = 0.0,
        du: ArrayLike | None = None,
        params: bool = True,
        engine: str = "auto",
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64] | None]:
        """``(S, dS_dparams, dS_du)`` in one pass over the record ``u`` (V), the actuator held
        at ``held_V`` before it (:meth:`held_state`).

        - ``S`` (N,): ``apply(u, self.held_state(held_V))`` (ue);
        - ``dS_dparams`` (N, 3): exact derivatives with respect to ``alpha0`` (ue per ue/V),
          ``gamma`` (ue per ue/V, or per ue/V^2 for the linear shape) and ``vc`` (ue/V; zero
          for the linear shape). Every turning point's input is a sample of ``u``, which the
          parameters do not move, so ``S`` is a sum of branch increments
          ``sign F(|x_b - x_a|)`` and its derivative the sum of ``d/dp sign F``. ``None`` when
          ``params`` is false;
        - ``dS_du`` (N, k) for ``du`` of shape (N, k) (or (N,) for ``du`` (N,)): the tangent of
          :meth:`tangent` along each column, the branch structure held fixed. ``None`` without
          ``du``.

        ``engine`` as for :meth:`apply`. For a user :class:`Shape`, ``dH/dgamma`` and
        ``dH/dvc`` come from the shape if it states them, else from central differences
        (:meth:`Shape.integral_derivatives`).

        Parameters
        ----------
        u : array_like
            The voltage record (V).
        held_V : float
            The voltage held before the record (V).
        du : array_like, optional
            Directions of the change of ``u``: (N,) or (N, k).
        params : bool
            Whether to compute ``dS_dparams``.
        engine : {"auto", "compiled", "numpy"}
            Which code runs.

        Returns
        -------
        S : numpy.ndarray
            Strain (ue), (N,).
        dS_dparams : numpy.ndarray or None
            (N, 3), or ``None`` without ``params``.
        dS_du : numpy.ndarray or None
            (N,) or (N, k), or ``None`` without ``du``.
        """
        u = _finite(u, "voltage")
        n = u.size
        one_col = du is not None and np.ndim(du) == 1
        if du is None:
            dcols = np.zeros((n, 0))
        else:
            dcols = np.asarray(du, dtype=np.float64)
            dcols = dcols[:, None] if one_col else dcols
            if dcols.ndim != 2 or dcols.shape[0] != n:
                raise ValueError(f"du must have shape ({n},) or ({n}, k), got {np.shape(du)}")
            dcols = np.ascontiguousarray(dcols)
        kern = self._kernels(engine)
        h = float(held_V)
        if n == 0:
            S, dP, dU = np.zeros(0), np.zeros((0, 3)), np.zeros((0, dcols.shape[1]))
        elif kern is not None:
            rest = np.zeros(1)
            S, dP, dU, _, _, _ = kern.operator_pass(
                u, rest, rest, h, float(np.sign(h)), self._wipe, self._code, float(self.alpha0),
                float(self.gamma), float(self.vc), bool(params), dcols,
            )  # fmt: skip
        else:
            S, dP, dU = self._sensitivities_numpy(u, h, dcols, params)
        out_p = dP if params else None
        out_u = None if du is None else (dU[:, 0] if one_col else dU)
        return S, out_p, out_u

    def _odd_dparams(self, d: NDArray) -> NDArray:
        """``d sign(d) F(|d|) / d(alpha0, gamma, vc)`` (len(d), 3)."""
        dg, dv = self._shape.integral_derivatives(np.abs(d), self.gamma, self.vc)
        sg = np.sign(d)
        return np.column_stack((d, sg * dg, sg * dv))

    def _sensitivities_numpy(
        self, u: NDArray, held: float, du: NDArray, params: bool
    ) -> tuple[NDArray, NDArray, NDArray]:
        br, _, _ = _branches(u, [(0.0, 0.0)], held, float(np.sign(held)), self._along, self._wipe)
        x0 = br.per_sample(br.x0)
        S = br.per_sample(br.y0) + self._odd_branch(u - x0)
        new = np.flatnonzero(br.parent >= 0)
        par = br.parent[new]
        dnode = br.x0[new] - br.x0[par]

        def accumulate(step: NDArray, width: int) -> NDArray:
            # each turning point's value: its parent's plus the step (parents come first)
            out = np.zeros((br.x0.size, width))
            for j in range(width):
                acc = [0.0] * br.x0.size
                for k, p, dk in zip(new.tolist(), par.tolist(), step[:, j].tolist(), strict=True):
                    acc[k] = acc[p] + dk
                out[:, j] = acc
            return out

        dP = np.zeros((u.size, 3))
        if params:
            dy = accumulate(self._odd_dparams(dnode), 3)
            dP = dy[np.repeat(br.seg_anchor, br.counts)] + self._odd_dparams(u - x0)
        k = du.shape[1]
        dx0 = np.where((br.at >= 0)[:, None], du[np.maximum(br.at, 0)], 0.0)
        step = self.slope(np.abs(dnode))[:, None] * (dx0[new] - dx0[par])
        dy = accumulate(step, k)
        idx = np.repeat(br.seg_anchor, br.counts)
        dU = dy[idx] + self.slope(np.abs(u - x0))[:, None] * (du - dx0[idx])
        return S, dP, dU

    def invert(self, strain: ArrayLike, state: HysteresisState | None = None) -> NDArray:
        """Voltage (V) whose :meth:`apply` gives ``strain`` (ue), branch by branch.

        ``F`` is increasing, so reversals and closed loops of the strain coincide with those of
        the voltage: the same branch structure is built on the strain record and each branch is
        inverted in closed form.

        Parameters
        ----------
        strain : array_like
            The strain record (ue), finite.
        state : HysteresisState, optional
            The memory before the record (default: at rest); updated in place.

        Returns
        -------
        numpy.ndarray
            Voltage (V) at each sample.

        Examples
        --------
        >>> op = QuasiStaticHysteresis(1.0, 0.5, shape="linear")
        >>> op.invert([0.0, 1.25, 3.0, 1.75, 0.0]).round(12).tolist()
        [0.0, 1.0, 2.0, 1.0, 0.0]
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


def memory_samples(u: ArrayLike, start: int) -> NDArray[np.intp]:
    """Indices of the samples of ``u`` that :meth:`QuasiStaticHysteresis.apply` needs to give
    the same strain from sample ``start`` on: the first sample, every sample before ``start``
    that is not strictly between its neighbours (turning points, flat stretches and any sample
    that is not finite) and every sample from ``start``.

    The operator is rate independent: along a monotone run the branch and the memory depend on
    the run's ends only (a turning point is a sample; a minor loop closes when the input passes
    a remembered one, which a jump past it does as well), so ``apply(u[idx])`` equals
    ``apply(u)[idx]`` under every memory rule. A long history then costs one sample per
    reversal.

    Parameters
    ----------
    u : array_like
        The voltage record (V).
    start : int
        The first sample whose strain is wanted (0 <= start <= len(u)).

    Returns
    -------
    numpy.ndarray
        Increasing sample indices, ending with ``start, ..., len(u) - 1``.
    """
    x = np.asarray(u, dtype=float)
    n = x.size
    if not 0 <= start <= n:
        raise ValueError(f"start must be within 0..{n}, not {start}")
    keep = np.ones(start, dtype=bool)
    m = min(start, n - 1)  # samples 1..m-1 have both neighbours
    if m >= 2:
        with np.errstate(invalid="ignore"):  # inf - inf: a NaN step, kept like a NaN sample
            d = np.diff(x[: m + 1])
        # sample i drops only when strictly between i-1 and i+1 (a NaN stays, for apply to refuse)
        s = np.sign(d)  # signs, not the product of the steps: that overflows past 1e154 V
        keep[1:m] = ~(s[:-1] * s[1:] > 0)
    return np.concatenate((np.flatnonzero(keep), np.arange(start, n))).astype(np.intp)


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
    wipe: int,
) -> tuple[_Branches, list[tuple[float, float]], float]:
    """Find the branch structure of ``x`` (module docstring, memory rules).

    ``stack``: the remembered turning points ``(x, y)``, oldest first, the last one the current
    branch's; ``delta(x_a, x_b)``: the output change along a branch from ``x_a`` to ``x_b``;
    ``wipe``: return-point memory (close and forget minor loops onto any of the remembered
    turning points while at least ``wipe`` are remembered: 2 down to the rest point, 3 never
    onto it), else (0) the last reversal only.
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
            while len(live) >= wipe and far >= dj * xs[live[-2]]:
                # the run reaches the turning point where the current minor loop began: close
                # the loop and forget it (the rest point at the bottom stays; with
                # "return_point_open" no loop closes onto it). Closing on
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
