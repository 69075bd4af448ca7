"""Recursive (modal) realisation of a linear filter as a bank of first-order modes.

A bank of independent first-order modes, each discretised *exactly* for a given input hold:

    x_i[n] = a_i x_i[n-1] + beta0_i u[n-1] + beta1_i u[n]          (one state per mode)
    y[n]   = Re( sum_i c_i x_i[n] )

For a continuous mode ``x' = q x + u`` sampled every ``dt`` (``w = q dt``):

- zero-order hold (u constant on ``[t_{n-1}, t_n)``): ``a = e^w``, ``beta0 = dt phi1(w)``,
  ``beta1 = 0``
- linear hold (u linear between samples): ``a = e^w``, ``beta0 = dt (phi1 - phi2)(w)``,
  ``beta1 = dt phi2(w)``

with ``phi1(w) = (e^w - 1)/w`` and ``phi2(w) = (e^w - 1 - w)/w^2``. There is no approximation in
this step: the discrete recursion reproduces the continuous modes exactly under the hold.

:func:`run_bank` evaluates the recursion for a whole record: compiled, one sample at a time
over all modes (:func:`labrig.model.compiled.bank_run`), or, without numba or with
``engine="numpy"``, in blocks of ``B`` samples with matrix products (the same arithmetic as the
per-sample loop, reordered). :func:`run_bank_multi` runs several input columns and several
output weight vectors in one pass (a bank's output and its derivatives with respect to its
weights). :class:`BankStepper` runs a bank one sample at a time for a control loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.core.blas import single_thread_blas
from labrig.model.accel import kernels, stream_engine

HOLDS = ("zoh", "linear")
ENGINES = ("auto", "compiled", "numpy")

_SERIES_RADIUS = 0.1
_N_SERIES = 14


def _phi(w: NDArray[np.complex128], order: int) -> NDArray[np.complex128]:
    """``phi_k(w) = sum_j w^j / (j + k)!`` (k = 1, 2, 3) of complex arguments, by series near 0
    and closed form elsewhere (``(e^w - sum_{j<k} w^j/j!) / w^k``)."""
    w = np.asarray(w, dtype=np.complex128)
    out = np.empty_like(w)
    small = np.abs(w) < _SERIES_RADIUS
    ws = w[small]
    # phi_k(w) = sum_j w^j / (j + k)!
    acc = np.zeros_like(ws)
    fact = float(np.prod(np.arange(1, order + 1)))
    term = np.ones_like(ws) / fact
    for j in range(_N_SERIES):
        acc = acc + term
        term = term * ws / (j + order + 1)
    out[small] = acc
    wb = w[~small]
    em1 = (
        np.expm1(wb.real) * np.cos(wb.imag)
        + (np.cos(wb.imag) - 1.0)
        + 1j * np.exp(wb.real) * np.sin(wb.imag)
    )
    if order == 1:
        out[~small] = em1 / wb
    elif order == 2:
        out[~small] = (em1 - wb) / wb**2
    else:
        out[~small] = (em1 - wb - wb**2 / 2) / wb**3
    return out


def hold_gains(q: NDArray, dt: float, hold: str) -> tuple[NDArray, NDArray, NDArray]:
    """``(a, beta0, beta1)`` of the modes ``x' = q x + u`` sampled every ``dt`` (s) under
    ``hold`` (module docstring): exact discretisation.

    Parameters
    ----------
    q : numpy.ndarray
        The modes' poles (1/s), complex.
    dt : float
        Sample period (s).
    hold : {"zoh", "linear"}
        The input's hold.

    Returns
    -------
    a, beta0, beta1 : numpy.ndarray
        ``x[n] = a x[n-1] + beta0 u[n-1] + beta1 u[n]`` (``beta1 = 0`` for ``zoh``).

    Examples
    --------
    ``zoh``: ``a = exp(q dt)`` and ``beta0 = (exp(q dt) - 1) / q``.

    >>> import numpy as np
    >>> a, b0, b1 = hold_gains(np.array([-1000.0]), 1e-3, "zoh")
    >>> round(float(a[0].real), 12), round(float(b0[0].real) * 1000.0, 12), float(b1[0].real)
    (0.367879441171, 0.632120558829, 0.0)
    """
    if hold not in HOLDS:
        raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
    w = np.asarray(q, dtype=np.complex128) * dt
    p1 = _phi(w, 1)
    if hold == "zoh":
        return np.exp(w), dt * p1, np.zeros_like(p1)
    p2 = _phi(w, 2)
    return np.exp(w), dt * (p1 - p2), dt * p2


def hold_gain_derivatives(q: NDArray, dt: float, hold: str) -> tuple[NDArray, NDArray, NDArray]:
    """``d(a, beta0, beta1)/dq`` for :func:`hold_gains`, from ``phi_k' = phi_k - k phi_(k+1)``:
    ``da = dt a``; zoh ``dbeta0 = dt^2 (phi1 - phi2)``; linear ``dbeta0 = dt^2 (phi1 - 2 phi2 +
    2 phi3)``, ``dbeta1 = dt^2 (phi2 - 2 phi3)``.

    Parameters
    ----------
    q : numpy.ndarray
        The modes' poles (1/s).
    dt : float
        Sample period (s).
    hold : {"zoh", "linear"}
        The input's hold.

    Returns
    -------
    da, dbeta0, dbeta1 : numpy.ndarray
        The derivatives with respect to ``q``.
    """
    if hold not in HOLDS:
        raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
    w = np.asarray(q, dtype=np.complex128) * dt
    p1, p2 = _phi(w, 1), _phi(w, 2)
    if hold == "zoh":
        return dt * np.exp(w), dt * dt * (p1 - p2), np.zeros_like(p1)
    p3 = _phi(w, 3)
    return dt * np.exp(w), dt * dt * (p1 - 2 * p2 + 2 * p3), dt * dt * (p2 - 2 * p3)


@dataclass(frozen=True)
class ContinuousModes:
    """``H(s) = sum_i c_i / (s - q_i)`` plus instantaneous parts that sampling makes exact.

    ``direct_m1`` and ``direct_m2`` describe modes too fast to resolve at any rate used (their
    response settles within a sample): for such a mode ``c/(s + xi)`` the discrete action is
    ``c/xi`` times the held input (``direct_m1 = sum c/xi``) with a linear-hold correction
    ``direct_m2 = sum c/xi^2``.

    Parameters
    ----------
    q : numpy.ndarray
        The poles (1/s), complex.
    c : numpy.ndarray
        The residues (1/s), complex.
    direct_m1 : float
        ``sum c / xi`` of the modes too fast to resolve.
    direct_m2 : float
        ``sum c / xi^2`` of those modes (s).
    """

    q: NDArray[np.complex128]
    c: NDArray[np.complex128]
    direct_m1: float = 0.0
    direct_m2: float = 0.0

    def frequency_response(self, f_hz: NDArray[np.float64]) -> NDArray[np.complex128]:
        """``H(j 2 pi f)`` of the modes and the instantaneous gain.

        Parameters
        ----------
        f_hz : numpy.ndarray
            Frequencies (Hz).

        Returns
        -------
        numpy.ndarray
            ``H(j 2 pi f)``, complex.
        """
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)[..., None]
        return np.sum(self.c / (s - self.q), axis=-1) + self.direct_m1

    def discretise(self, dt: float, hold: str) -> DiscreteBank:
        """The modes discretised exactly for ``hold`` (:func:`hold_gains`).

        Parameters
        ----------
        dt : float
            Sample period (s).
        hold : {"zoh", "linear"}
            The input's hold.

        Returns
        -------
        DiscreteBank
            The bank, the instantaneous part one extra mode.
        """
        a, b0, b1 = hold_gains(self.q, dt, hold)
        c = self.c
        # instantaneous part as one extra mode with a = 0 (exact to e^-40)
        if self.direct_m1 != 0.0 or self.direct_m2 != 0.0:
            if hold == "zoh":
                d0, d1 = self.direct_m1, 0.0
            else:
                d0, d1 = self.direct_m2 / dt, self.direct_m1 - self.direct_m2 / dt
            a = np.append(a, 0.0)
            b0 = np.append(b0, d0)
            b1 = np.append(b1, d1)
            c = np.append(c, 1.0)
        return DiscreteBank.from_arrays(a, b0, b1, c)


@dataclass(frozen=True)
class _Group:
    """Modes of one dtype (real or complex); complex modes carry conjugate pairs as one mode."""

    a: NDArray
    b0: NDArray
    b1: NDArray
    c: NDArray

    @property
    def size(self) -> int:
        return int(self.a.size)


@dataclass(frozen=True)
class DiscreteBank:
    """A bank of exactly discretised first-order modes (see module docstring).

    ``order[g]`` holds the positions, in the arrays given to :meth:`from_arrays`, of group
    ``g``'s modes (extra output rows of :func:`run_bank_multi` are given in that order).

    Parameters
    ----------
    groups : tuple
        The modes, real and complex apart.
    _cache : dict
        Forms derived from the bank, kept (internal).
    order : tuple of numpy.ndarray
        Each group's positions among the modes given to :meth:`from_arrays`.
    """

    groups: tuple[_Group, ...]
    _cache: dict = field(default_factory=dict, compare=False, repr=False)
    order: tuple[NDArray[np.intp], ...] = ()

    @classmethod
    def from_arrays(cls, a: ArrayLike, b0: ArrayLike, b1: ArrayLike, c: ArrayLike) -> DiscreteBank:
        """A bank from per-mode arrays (real modes grouped apart from complex ones).

        Parameters
        ----------
        a, b0, b1 : array_like
            ``x[n] = a x[n-1] + b0 u[n-1] + b1 u[n]`` per mode.
        c : array_like
            Output weights: ``y = Re sum c x``.

        Returns
        -------
        DiscreteBank
            The modes grouped into real and complex ones.
        """
        a, b0, b1, c = (np.asarray(x, dtype=np.complex128) for x in (a, b0, b1, c))
        is_real = (np.abs(a.imag) == 0) & (np.abs(b0.imag) == 0) & (np.abs(b1.imag) == 0)
        is_real &= np.abs(c.imag) == 0
        groups, order = [], []
        if np.any(is_real):
            r = is_real
            groups.append(_Group(a[r].real, b0[r].real, b1[r].real, c[r].real))
            order.append(np.flatnonzero(r))
        if np.any(~is_real):
            r = ~is_real
            groups.append(_Group(a[r], b0[r], b1[r], c[r]))
            order.append(np.flatnonzero(r))
        return cls(tuple(groups), order=tuple(order))

    @property
    def size(self) -> int:
        return sum(g.size for g in self.groups)

    @cached_property
    def feedthrough(self) -> float:
        """Gain from ``u[n]`` to ``y[n]`` (non-zero only for the linear hold)."""
        return float(sum(np.sum(g.c * g.b1).real for g in self.groups))

    def impulse_response(self, n: int) -> NDArray[np.float64]:
        """``y`` for a unit sample at index 0 (system at rest), length ``n``.

        Parameters
        ----------
        n : int
            Number of samples.

        Returns
        -------
        numpy.ndarray
            ``y``, length ``n``.
        """
        u = np.zeros(n)
        u[0] = 1.0
        return run_bank(self, u)[0]

    def initial_state(self) -> list[NDArray]:
        """The state at rest.

        Returns
        -------
        list of numpy.ndarray
            One zero array per group.
        """
        return [np.zeros(g.size, dtype=g.a.dtype) for g in self.groups]


def _folded(g: _Group) -> tuple[NDArray, NDArray]:
    """Fold the linear-hold term into ZOH form: with ``z = x - b1 u[n]``,
    ``z[n] = a z[n-1] + (a b1 + b0) u[n-1]`` and ``y[n] = Re(c z[n]) + Re(sum c b1) u[n]``."""
    return g.a, g.a * g.b1 + g.b0


def _block_matrices(bank: DiscreteBank, B: int) -> tuple:
    """Per-group ``(Q, P, a^B)`` and the Toeplitz matrix summed over groups, for blocks of B."""
    idx = np.arange(B)
    lag = idx[None, :] - idx[:, None]  # [l, k] -> k - l
    T = np.zeros(B)
    per_group = []
    for g in bank.groups:
        a, b = _folded(g)
        k = np.arange(B + 1)
        pw = a[None, :] ** k[:, None]  # (B+1, M): a^k
        pw[0, :] = 1.0  # 0**0
        # y[k] = Re(Q[k] . z_prev) + sum_{l<=k} T[k-l] u[l-1];  z_end = a^B z_prev + u_prev_blk @ P
        Q = pw[1:, :] * g.c[None, :]
        T += (pw[:B, :] @ (g.c * b)).real
        P = pw[B - 1 - idx, :] * b[None, :]
        per_group.append((Q, P, pw[B, :]))
    Tm = np.where(lag >= 0, T[np.clip(lag, 0, B - 1)], 0.0)
    return per_group, Tm


_CHUNK = 1 << 16  # samples per pass: keeps the working arrays in cache
#: records shorter than this (samples) run without :func:`single_thread_blas`: their products
#: are a few small matrices, and a simulated bench, stepping in its servers' threads, would
#: otherwise change the process-wide setting several times per block
SMALL_RECORD = 4096


def _engine_kernels(engine: str) -> ModuleType | None:
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if engine == "numpy":
        return None
    k = kernels()
    if k is None and engine == "compiled":
        raise RuntimeError("the compiled engine needs numba, which could not be imported")
    return k


def run_bank(
    bank: DiscreteBank,
    u: NDArray,
    state: list[NDArray] | None = None,
    u_prev: float = 0.0,
    block: int = 256,
    engine: str = "auto",
) -> tuple[NDArray[np.float64], list[NDArray]]:
    """Run the bank over a record ``u``; returns ``(y, final_state)``.

    ``state`` and ``u_prev`` carry the recursion across calls (streaming); ``None`` and 0 mean
    the system is at rest with zero input before the first sample. ``engine``: ``"auto"``
    (compiled when numba is available), ``"compiled"`` (the recursion sample by sample), or
    ``"numpy"`` (blocks of ``block`` samples with matrix products: the same recursion,
    reordered). The two agree to rounding.

    Parameters
    ----------
    bank : DiscreteBank
        The bank.
    u : numpy.ndarray
        The input record.
    state : list of numpy.ndarray, optional
        The state before the record (default: at rest).
    u_prev : float
        The input before the record.
    block : int
        Block length of the numpy engine.
    engine : {"auto", "compiled", "numpy"}
        Which code runs.

    Returns
    -------
    y : numpy.ndarray
        The output at each sample.
    final_state : list of numpy.ndarray
        The state after the record.
    """
    u = np.ascontiguousarray(u, dtype=np.float64)
    kern = _engine_kernels(engine)
    if kern is not None:
        y, st = run_bank_multi(bank, u[:, None], None, None if state is None else [state],
                               np.array([u_prev]), engine="compiled")  # fmt: skip
        return y[:, 0, 0], st[0]
    if u.size < SMALL_RECORD:
        return _run_bank(bank, u, state, u_prev, block)
    with single_thread_blas():
        return _run_bank(bank, u, state, u_prev, block)


def first_order_filter(b: ArrayLike, a: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
    """A first-order IIR filter at rest before the record, as ``scipy.signal.lfilter(b, a, x)``:

        y[n] = (b[0] x[n] + b[1] x[n-1] - a[1] y[n-1]) / a[0]      (x[-1] = y[-1] = 0)

    run as a one-mode bank (pole ``p = -a[1]/a[0]``), so the effects' lags need no import of
    ``scipy.signal`` (about a second of CPU: it loads ``scipy.stats``). The compiled recursion
    when the kernels are already loaded, else the numpy one
    (:func:`labrig.model.accel.stream_engine`). The bank folds the numerator into one input
    gain ``p b[0] + b[1]`` (over ``a[0]``), which loses digits when the two terms nearly cancel
    (a pole near 1 with a numerator near ``(1, -p)``): write such a filter as a gain plus a lag,
    as ``viscoelastic_creep`` does.

    Parameters
    ----------
    b : array_like
        Numerator ``[b0, b1]`` (a shorter one is padded with zeros).
    a : array_like
        Denominator ``[a0, a1]``, ``a0 != 0``.
    x : array_like
        The input record.

    Returns
    -------
    numpy.ndarray
        The output at each sample.

    Examples
    --------
    >>> import numpy as np
    >>> first_order_filter([0.0, 0.5], [1.0, -0.5], np.ones(4)).tolist()
    [0.0, 0.5, 0.75, 0.875]
    """
    bb = np.zeros(2)
    b_in = np.asarray(b, dtype=np.float64).ravel()
    a_in = np.asarray(a, dtype=np.float64).ravel()
    if b_in.size > 2 or a_in.size != 2 or a_in[0] == 0.0:
        raise ValueError(
            "a first-order filter needs b of 1-2 and a of 2 terms, a[0] != 0; "
            f"got b={b_in.tolist()}, a={a_in.tolist()}"
        )
    bb[: b_in.size] = b_in / a_in[0]
    pole = -a_in[1] / a_in[0]
    bank = DiscreteBank.from_arrays([pole], [bb[1]], [bb[0]], [1.0])
    return run_bank(bank, np.asarray(x, dtype=np.float64), engine=stream_engine())[0]


def _scaled(bank: DiscreteBank, extra: NDArray | None) -> tuple:
    """The compiled kernel's form of the bank: poles ``a``, output weights ``cw = c b`` with
    ``b = a b1 + b0`` the folded input gain (rows: the bank's ``c``, then ``extra``), and the
    feedthrough of each row ``Re sum c b1``; real and complex modes apart."""
    parts = []
    for g, idx in zip(bank.groups, bank.order, strict=True):
        rows = g.c[None, :] if extra is None else np.vstack([g.c[None, :], extra[:, idx]])
        b = g.a * g.b1 + g.b0
        live = b != 0  # b = 0: the mode is never driven (a pure feedthrough, in `feed`)
        parts.append((g, rows, b, live))
    # each group's feedthrough added in turn (a loop: mypy is slow to infer ``sum`` over a
    # generator of numpy expressions)
    feed = np.zeros(parts[0][1].shape[0])
    for g, rows, _, _ in parts:
        feed = feed + np.sum(rows * g.b1[None, :], axis=1).real
    real = [p for p in parts if not np.iscomplexobj(p[0].a)]
    cplx = [p for p in parts if np.iscomplexobj(p[0].a)]

    def pack(ps: list, dtype: type) -> tuple[NDArray, NDArray]:
        if not ps:
            return np.zeros(0, dtype), np.zeros((feed.size, 0), dtype)
        g, rows, b, live = ps[0]
        cw = (rows * b[None, :])[:, live]
        cw = cw.real if dtype is np.float64 else cw  # a real mode's output is Re(c) x
        return (np.ascontiguousarray(g.a[live], dtype=dtype),
                np.ascontiguousarray(cw, dtype=dtype))  # fmt: skip

    a_r, cw_r = pack(real, np.float64)
    a_c, cw_c = pack(cplx, np.complex128)
    return a_r, cw_r, a_c, cw_c, np.ascontiguousarray(feed, dtype=np.float64), parts


def run_bank_multi(
    bank: DiscreteBank,
    u: NDArray,
    extra_outputs: NDArray | None = None,
    state: list[list[NDArray]] | None = None,
    u_prev: NDArray | None = None,
    engine: str = "auto",
) -> tuple[NDArray[np.float64], list[list[NDArray]]]:
    """Run the bank over each column of ``u`` (N, k) and read several outputs in one pass.

    Output row 0 is the bank's own ``y = Re sum c x``; rows ``1..r`` are
    ``Re sum extra_outputs[q - 1] x`` for the weight vectors ``extra_outputs`` (r, M), given in
    the order of the modes passed to :meth:`DiscreteBank.from_arrays` (each row's feedthrough
    follows from its weights). Returns ``y`` (N, k, 1 + r) and each column's final state.
    ``state`` (one :meth:`DiscreteBank.initial_state`-like list per column) and ``u_prev`` (k,)
    carry the recursion across calls; ``None``: at rest with zero input before the record.

    Parameters
    ----------
    bank : DiscreteBank
        The bank.
    u : numpy.ndarray
        The inputs, (N, k).
    extra_outputs : numpy.ndarray, optional
        Weight vectors of further outputs, (r, M).
    state : list, optional
        Each column's state before the record (default: at rest).
    u_prev : numpy.ndarray, optional
        Each column's input before the record, (k,).
    engine : {"auto", "compiled", "numpy"}
        Which code runs.

    Returns
    -------
    y : numpy.ndarray
        The outputs, (N, k, 1 + r).
    final_states : list
        Each column's state after the record.
    """
    u = np.asarray(u, dtype=np.float64)
    if u.ndim != 2:
        raise ValueError(f"u must have shape (N, k), got {u.shape}")
    n, kc = u.shape
    extra = None if extra_outputs is None else np.atleast_2d(np.asarray(extra_outputs))
    if extra is not None and extra.shape[1] != bank.size:
        raise ValueError(f"extra_outputs must have {bank.size} columns, got {extra.shape}")
    up = np.zeros(kc) if u_prev is None else np.asarray(u_prev, dtype=np.float64).reshape(kc)
    states = [bank.initial_state() for _ in range(kc)] if state is None else state
    kern = _engine_kernels(engine)
    if kern is None:
        return _run_bank_multi_numpy(bank, u, extra, states, up)
    key = ("scaled", None if extra is None else extra.tobytes())
    if key not in bank._cache:
        if len(bank._cache) > 16:  # extra outputs differ per call: do not pile them up
            bank._cache.clear()
        bank._cache[key] = _scaled(bank, extra)
    a_r, cw_r, a_c, cw_c, feed, _ = bank._cache[key]
    w_r = np.zeros((kc, a_r.size))
    w_c = np.zeros((kc, a_c.size), dtype=np.complex128)
    for j in range(kc):
        w_r[j], w_c[j] = scaled_state(bank, states[j], float(up[j]))
    y = kern.bank_run(a_r, cw_r, a_c, cw_c, feed, np.ascontiguousarray(u), w_r, w_c, up)
    u_last = u[-1] if n else up
    out_states = [unscaled_state(bank, w_r[j], w_c[j], float(u_last[j])) for j in range(kc)]
    return y, out_states


def scaled_form(bank: DiscreteBank) -> tuple:
    """``(a, cw, feed, ca, ccw)``: the bank as the compiled kernels run it (real modes' poles and
    output weights ``c (a b1 + b0)``, the feedthrough, complex modes' poles and weights).

    Parameters
    ----------
    bank : DiscreteBank
        The bank.

    Returns
    -------
    tuple
        ``(a, cw, feed, ca, ccw)``.
    """
    key = ("scaled", None)
    if key not in bank._cache:
        bank._cache[key] = _scaled(bank, None)
    a_r, cw_r, a_c, cw_c, feed, _ = bank._cache[key]
    return a_r, cw_r[0], float(feed[0]), a_c, cw_c[0]


#: what :func:`compact_form` may drop: the summed worst-case contribution of the dropped modes,
#: as a fraction of the largest input magnitude (far below the quadrature's ~1e-13)
COMPACT_TOL = 1e-15
#: the compact form's real modes are padded with idle ones to a multiple of this (the compiled
#: sweep runs four modes per vector instruction; a remainder would run one at a time)
MODE_PAD = 4


def compact_form(bank: DiscreteBank, tol: float = COMPACT_TOL) -> tuple:
    """:func:`scaled_form` with fewer modes and the same output to within ``tol`` of the
    input's full scale, for a bank started at rest (zero state) and driven by a real input.

    Three reductions, the first two exact: real modes with the same pole ``a`` (the slowest
    nodes round to ``a = 1``: integrators) are one mode with the summed weight; a conjugate pair
    of complex modes is one mode, ``Re(c w) + Re(conj(c) conj(w)) = Re(2 c w)`` for real inputs
    (weight ``c_i + conj(c_j)``); real modes whose worst-case contributions, ``|cw| / (1 - |a|)``
    times the largest ``|u|`` (the sum of ``|cw a^k|`` over all lags), add up to at most ``tol``
    are dropped, smallest first. The real modes are then padded with idle ones (``a = cw = 0``,
    output exactly 0) to a multiple of :data:`MODE_PAD`.

    Parameters
    ----------
    bank : DiscreteBank
        The bank.
    tol : float
        The largest summed contribution of the dropped modes, as a fraction of ``max |u|``.

    Returns
    -------
    tuple
        ``(a, cw, feed, ca, ccw)`` as :func:`scaled_form` (fresh arrays).

    Examples
    --------
    >>> import numpy as np
    >>> bank = DiscreteBank.from_arrays([0.5, 0.5, 1e-3], [1.0, 1.0, 1.0], [0, 0, 0],
    ...                                 [1.0, 2.0, 1e-18])
    >>> a, cw, feed, ca, ccw = compact_form(bank)
    >>> a.tolist(), cw.tolist()
    ([0.5, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0, 0.0])
    """
    a, cw, feed, ca, ccw = scaled_form(bank)
    # real modes: merge equal poles, then drop the least significant within tol
    ua, inv = np.unique(a, return_inverse=True)
    ucw = np.zeros(ua.size)
    np.add.at(ucw, inv, cw)
    with np.errstate(divide="ignore"):
        bound = np.where(np.abs(ua) < 1.0, np.abs(ucw) / (1.0 - np.abs(ua)), np.inf)
    bound[ucw == 0.0] = 0.0
    order = np.argsort(bound, kind="stable")
    dropped = np.cumsum(bound[order]) <= tol
    keep = np.sort(order[~dropped])
    ua, ucw = ua[keep], ucw[keep]
    # complex modes: one of each conjugate pair, weights folded onto it
    ca_out: list[complex] = []
    ccw_out: list[complex] = []
    used = np.zeros(ca.size, dtype=bool)
    for i in range(ca.size):
        if used[i]:
            continue
        used[i] = True
        c = complex(ccw[i])
        scale = max(abs(ca[i]), 1e-300)
        for j in range(i + 1, ca.size):
            if not used[j] and abs(ca[j] - np.conj(ca[i])) <= 4 * np.finfo(float).eps * scale:
                used[j] = True
                c += complex(np.conj(ccw[j]))
                break
        ca_out.append(complex(ca[i]))
        ccw_out.append(c)
    m = int(np.ceil(ua.size / MODE_PAD)) * MODE_PAD
    a_p, cw_p = np.zeros(m), np.zeros(m)
    a_p[: ua.size], cw_p[: ua.size] = ua, ucw
    return (a_p, cw_p, float(feed), np.array(ca_out, dtype=np.complex128),
            np.array(ccw_out, dtype=np.complex128))  # fmt: skip


def scaled_state(
    bank: DiscreteBank, state: list[NDArray], u_prev: float
) -> tuple[NDArray, NDArray]:
    """A state of :meth:`DiscreteBank.initial_state`'s form as the compiled kernels keep it:
    ``w = (x - b1 u_prev) / b`` for the modes that are driven, real and complex apart.

    Parameters
    ----------
    bank : DiscreteBank
        The bank.
    state : list of numpy.ndarray
        A state of :meth:`DiscreteBank.initial_state`'s form.
    u_prev : float
        The last input.

    Returns
    -------
    w_r, w_c : numpy.ndarray
        The real and complex modes' scaled states.
    """
    if ("scaled", None) not in bank._cache:
        bank._cache[("scaled", None)] = _scaled(bank, None)
    parts = bank._cache[("scaled", None)][5]
    w_r, w_c = np.zeros(0), np.zeros(0, dtype=np.complex128)
    for gi, (g, _, b, live) in enumerate(parts):
        w = (state[gi] - g.b1 * u_prev)[live] / b[live]
        if np.iscomplexobj(g.a):
            w_c = np.ascontiguousarray(w, dtype=np.complex128)
        else:
            w_r = np.ascontiguousarray(w.real, dtype=np.float64)
    return w_r, w_c


def unscaled_state(bank: DiscreteBank, w_r: NDArray, w_c: NDArray, u_last: float) -> list[NDArray]:
    """The inverse of :func:`scaled_state` after a record whose last input was ``u_last``.

    Parameters
    ----------
    bank : DiscreteBank
        The bank.
    w_r, w_c : numpy.ndarray
        The real and complex modes' scaled states.
    u_last : float
        The record's last input.

    Returns
    -------
    list of numpy.ndarray
        The state in :meth:`DiscreteBank.initial_state`'s form.
    """
    if ("scaled", None) not in bank._cache:
        bank._cache[("scaled", None)] = _scaled(bank, None)
    parts = bank._cache[("scaled", None)][5]
    out = []
    for g, _, b, live in parts:
        x = np.zeros(g.size, dtype=g.a.dtype)
        x[live] = (w_c if np.iscomplexobj(g.a) else w_r) * b[live]
        out.append(x + g.b1 * u_last)
    return out


def _run_bank_multi_numpy(
    bank: DiscreteBank,
    u: NDArray,
    extra: NDArray | None,
    states: list[list[NDArray]],
    up: NDArray,
) -> tuple[NDArray[np.float64], list[list[NDArray]]]:
    """:func:`run_bank_multi` with the numpy block realisation, one output row at a time."""
    rows = [None] if extra is None else [None, *list(extra)]
    n, kc = u.shape
    y = np.empty((n, kc, len(rows)))
    out_states = []
    for j in range(kc):
        for q, row in enumerate(rows):
            b = bank
            if row is not None:
                cs = [row[idx] if np.iscomplexobj(g.a) else row[idx].real
                      for g, idx in zip(bank.groups, bank.order, strict=True)]  # fmt: skip
                b = DiscreteBank(tuple(_Group(g.a, g.b0, g.b1, c) for g, c in zip(
                    bank.groups, cs, strict=True)), order=bank.order)  # fmt: skip
            yq, st = run_bank(b, u[:, j], states[j], float(up[j]), engine="numpy")
            y[:, j, q] = yq
            if q == 0:
                out_states.append(st)
    return y, out_states


def _run_bank(
    bank: DiscreteBank, u: NDArray, state: list[NDArray] | None, u_prev: float, block: int
) -> tuple[NDArray[np.float64], list[NDArray]]:
    n = u.size
    state = bank.initial_state() if state is None else state
    feed = bank.feedthrough
    up = np.empty(n)
    if n:
        up[0] = u_prev
        up[1:] = u[:-1]
    # folded states z = x - b1 u_prev
    z = [
        x.astype(g.a.dtype, copy=True) - g.b1 * u_prev
        for g, x in zip(bank.groups, state, strict=True)
    ]
    y = feed * u
    pos = 0
    while pos < n:
        stop = min(n, pos + _CHUNK)
        for size in (block, (stop - pos) % block):
            nb = (stop - pos) // size if size else 0
            if nb == 0:
                continue
            key = ("blocks", size)
            if key not in bank._cache:
                bank._cache[key] = _block_matrices(bank, size)
            per_group, Tm = bank._cache[key]
            Up = up[pos : pos + nb * size].reshape(nb, size)
            yb = Up @ Tm
            for gi, (Q, P, aB) in enumerate(per_group):
                inj = Up @ P.real + 1j * (Up @ P.imag) if np.iscomplexobj(P) else Up @ P
                X = np.empty_like(inj)
                x = z[gi]
                for j in range(nb):
                    X[j] = x
                    x = aB * x + inj[j]
                z[gi] = x
                if np.iscomplexobj(X):
                    yb += X.real @ Q.real.T - X.imag @ Q.imag.T
                else:
                    yb += X @ Q.T
            y[pos : pos + nb * size] += yb.ravel()
            pos += nb * size
    u_last = float(u[-1]) if n else u_prev
    out_state = [zz + g.b1 * u_last for g, zz in zip(bank.groups, z, strict=True)]
    return y, out_state


class BankStepper:
    """Sample-by-sample evaluation of a :class:`DiscreteBank` (O(M) work, no history kept).

    Parameters
    ----------
    bank : DiscreteBank
        The bank, at rest at the start.

    Examples
    --------
    >>> import numpy as np
    >>> from labrig.model.relaxor import Relaxor
    >>> bank = Relaxor(1e-3, 0.5).bank(1000.0)
    >>> stepper = BankStepper(bank)
    >>> u = np.sin(np.arange(20) / 3.0)
    >>> y = [stepper.step(float(x)) for x in u]
    >>> bool(np.allclose(y, run_bank(bank, u)[0], rtol=0, atol=1e-12))
    True
    """

    def __init__(self, bank: DiscreteBank):
        self.bank = bank
        self._a = [g.a for g in bank.groups]
        self._b0 = [g.b0 for g in bank.groups]
        self._b1 = [g.b1 for g in bank.groups]
        self._c = [g.c for g in bank.groups]
        self.reset()

    def reset(self) -> None:
        """Back to rest (zero state, zero last input)."""
        self._x = self.bank.initial_state()
        self._u_prev = 0.0

    def step(self, u: float) -> float:
        """Advance one sample with input ``u[n]``; return ``y[n]``.

        Parameters
        ----------
        u : float
            The input ``u[n]``.

        Returns
        -------
        float
            The output ``y[n]``.
        """
        y = 0.0
        for i, x in enumerate(self._x):
            x *= self._a[i]
            x += self._b0[i] * self._u_prev + self._b1[i] * u
            y += float(np.dot(self._c[i], x).real)
        self._u_prev = u
        return y

    def peek(self, u: float) -> float:
        """``y[n]`` that :meth:`step` would return for input ``u``, without advancing.

        Parameters
        ----------
        u : float
            A candidate input ``u[n]``.

        Returns
        -------
        float
            The output ``y[n]`` it would give.
        """
        y = 0.0
        for i, x in enumerate(self._x):
            xn = self._a[i] * x + self._b0[i] * self._u_prev + self._b1[i] * u
            y += float(np.dot(self._c[i], xn).real)
        return y
