"""Fractional-order relaxor ``G(s) = 1 / (1 + (tau s)^lam)`` (the paper's Eq. 4-9).

Sampling convention ("hold")
----------------------------
A record ``v[n]`` sampled at ``rate_hz`` (``dt = 1/rate_hz``, ``t_n = n dt``) is a continuous
input under one of two holds; the output is the continuous response sampled at ``t_n``, with the
system at rest (zero input) before ``t_0``:

- ``"zoh"`` (default): ``v[n]`` is held constant on ``[t_n, t_{n+1})``, as a DAQ's DAC does.
  ``y[n]`` depends on ``v[0..n-1]`` only (the DAC updates at the instant the ADC samples), so a
  unit step record gives exactly the step response at the sample times. Versus the continuous
  ``G(jw)``, the discrete response carries the hold's factor
  ``exp(-j w dt/2) sinc(w dt / 2 pi)`` (plus aliasing, negligible well below Nyquist).
- ``"linear"``: the input is linear between samples (first-order hold, a smooth signal known at
  its samples), with the ramp from 0 at ``t_{-1}`` to ``v[0]`` at ``t_0``. No hold delay; used
  for a relaxor fed by another relaxor's output.

Methods
-------
- ``"exact"``: the sampled kernel is built from the closed-form step response
  ``1 - E_lam(-(t/tau)^lam)`` (zoh: first differences; linear: differences of interval means,
  from the ramp response ``t^(lam+1)/tau^lam E_{lam,lam+2}``) and applied by FFT convolution,
  O(N log N). Beyond the first ``2048`` samples the kernel uses a log-time Chebyshev interpolant
  of the step response (24 nodes per half-decade, poles subtracted in closed form), accurate to
  ~1e-14 and tested against direct evaluation. Memory is never truncated.
- ``"fast"``: the diffusive representation
  ``G(s) = int_0^inf mu(xi) / (s + xi) dxi (+ pole pair -(p/lam)/(s-p) for lam > 1)`` with
  ``mu(xi) = (1/pi) r sin(pi lam) / (1 + 2 r cos(pi lam) + r^2)``, ``r = (tau xi)^lam``,
  discretised by a pole-corrected trapezoidal rule in ``log xi`` on nodes fixed for the
  sample rate (:mod:`labrig.model.diffusive`): the mass below the nodes is one moment-matched
  slow mode, the mass above ``40/dt`` exactly an instantaneous gain. Each mode is discretised
  exactly for the hold (:mod:`labrig.model.modal`), so the only error is the quadrature:
  ~1e-13 of full scale against ``"exact"`` for every ``0 < lam < 2`` (through ``lam = 1``) over
  records up to 1e7 samples (``benchmarks/RESULTS.md``). O(M) work per sample with M ~ 80
  modes at 1 kHz, no history. :meth:`Relaxor.filter_sensitivities` gives the derivatives with
  respect to ``ln tau`` and ``lam`` from the same pass.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType

import numpy as np
from numpy.polynomial import chebyshev as C
from numpy.typing import ArrayLike, NDArray

from labrig.model import diffusive
from labrig.model.accel import kernels
from labrig.model.diffusive import ModeDerivatives
from labrig.model.mittag_leffler import (
    pole_pair,
    relaxor_ramp,
    relaxor_step,
    relaxor_step_pole_part,
)
from labrig.model.modal import (
    HOLDS,
    BankStepper,
    ContinuousModes,
    DiscreteBank,
    hold_gain_derivatives,
    hold_gains,
    run_bank,
    run_bank_multi,
)


def _scipy_signal() -> ModuleType:
    """``scipy.signal``, imported on first use: it costs about a second of CPU to import (it
    loads scipy.stats), which the fast paths never need."""
    from scipy import signal

    return signal


METHODS = ("exact", "fast")

_EXACT_SAMPLES = 2048  # kernel samples evaluated directly before switching to the interpolant
_PANELS_PER_DECADE = 2
_CHEB_NODES = 24


def _validate(tau_s: float, lam: float) -> None:
    if not (np.isfinite(tau_s) and tau_s > 0):
        raise ValueError(f"tau_s must be a positive time in seconds, got {tau_s!r}")
    if not (0.0 < lam < 2.0):
        raise ValueError(f"lam must satisfy 0 < lam < 2 (stable relaxor), got {lam!r}")


def _check_rate(rate_hz: float) -> float:
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate, got {rate_hz!r}")
    return 1.0 / float(rate_hz)


@dataclass(frozen=True)
class Relaxor:
    """``G(s) = 1 / (1 + (tau_s s)^lam)``, ``0 < lam < 2``; DC gain 1.

    Parameters
    ----------
    tau_s : float
        Time constant ``tau`` (s, > 0).
    lam : float
        Order ``lam`` (``0 < lam < 2``).

    Examples
    --------
    For ``lam = 1``, the first-order lag: a unit step held by a DAQ gives ``1 - exp(-t/tau)`` at
    the samples.

    >>> import numpy as np
    >>> g = Relaxor(1e-3, 1.0)
    >>> g.filter(np.ones(3), 1000.0).round(9).tolist()
    [0.0, 0.632120559, 0.864664717]
    >>> complex(g.frequency_response(0.0))
    (1+0j)
    """

    tau_s: float
    lam: float

    def __post_init__(self) -> None:
        _validate(self.tau_s, self.lam)

    # -- closed forms -------------------------------------------------------------------------
    def frequency_response(self, f_hz: ArrayLike) -> NDArray[np.complex128]:
        """``G(j 2 pi f) = 1 / (1 + (tau w)^lam exp(j lam pi/2))`` (the paper's Eq. 6).

        Parameters
        ----------
        f_hz : array_like
            Frequencies (Hz); negative ones give the conjugate.

        Returns
        -------
        numpy.ndarray
            ``G(j 2 pi f)``, complex.
        """
        w = 2.0 * np.pi * np.abs(np.asarray(f_hz, dtype=float))
        g = 1.0 / (1.0 + (self.tau_s * w) ** self.lam * np.exp(1j * self.lam * np.pi / 2))
        return np.where(np.asarray(f_hz) < 0, np.conj(g), g)

    def step_response(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Unit-step response ``1 - E_lam(-(t/tau)^lam)`` (0 for t <= 0), by direct evaluation.

        Parameters
        ----------
        t_s : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            The step response at ``t_s``.
        """
        return relaxor_step(t_s, self.tau_s, self.lam)

    # -- sampled filtering --------------------------------------------------------------------
    def filter(
        self, v: ArrayLike, rate_hz: float, method: str = "exact", hold: str = "zoh"
    ) -> NDArray[np.float64]:
        """Filter the record ``v`` sampled at ``rate_hz`` (see the module docstring for holds).

        Parameters
        ----------
        v : array_like
            The input record, 1-D.
        rate_hz : float
            Sample rate (Hz).
        method : {"exact", "fast"}
            FFT convolution with the exact kernel, or the modal bank (module docstring).
        hold : {"zoh", "linear"}
            How the input behaves between samples (module docstring).

        Returns
        -------
        numpy.ndarray
            The output at each sample (the input's unit), at rest before the record.
        """
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1:
            raise ValueError("v must be a 1-D record")
        dt = _check_rate(rate_hz)
        if hold not in HOLDS:
            raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
        if method == "exact":
            if v.size == 0:
                return v.copy()
            k = sampled_kernel(self.tau_s, self.lam, dt, v.size, hold)
            return _scipy_signal().fftconvolve(v, k)[: v.size]
        if method == "fast":
            return run_bank(self.bank(rate_hz, hold), v)[0]
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")

    def filter_sensitivities(
        self, v: ArrayLike, rate_hz: float, hold: str = "zoh", rest_V: float = 0.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(y, dy/d ln tau, dy/d lam)`` of the fast realisation, the relaxor at rest at
        ``rest_V`` (V) before the record (``y = rest_V + G (v - rest_V)``).

        At fixed node positions only the modes' output weights depend on ``tau`` and ``lam``,
        so the derivatives are further output rows of the same pass over the modes
        (:func:`~labrig.model.modal.run_bank_multi`); the instantaneous part's two gains are
        two more modes. The few special modes whose poles move with the parameters (the
        complex pair, the slow-tail mode) add ``Re(c dq dx/dq)``, ``dx/dq`` the derivative of
        the exactly discretised mode: ``z[n] = a z[n-1] + a' x[n-1] + beta0' u[n-1] +
        beta1' u[n]`` (:func:`~labrig.model.modal.hold_gain_derivatives`; the mode applied to
        its own state). Exact up to rounding: it differentiates what ``filter(method="fast")``
        computes, and agrees with its central differences (tests/model/test_sensitivities.py).

        Parameters
        ----------
        v : array_like
            The input record (V), 1-D.
        rate_hz : float
            Sample rate (Hz).
        hold : {"zoh", "linear"}
            How the input behaves between samples (module docstring).
        rest_V : float
            The input held before the record (V).

        Returns
        -------
        y : numpy.ndarray
            The output (V).
        dy_dln_tau : numpy.ndarray
            Its derivative with respect to ``ln tau``.
        dy_dlam : numpy.ndarray
            Its derivative with respect to ``lam``.
        """
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1:
            raise ValueError("v must be a 1-D record")
        dt = _check_rate(rate_hz)
        if hold not in HOLDS:
            raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
        u = v - float(rest_V)
        if u.size == 0:
            return u.copy(), u.copy(), u.copy()
        sp = _sensitivity_pass(self.tau_s, self.lam, dt, hold)
        y = run_bank_multi(sp.bank, u[:, None], sp.extra)[0][:, 0, :]
        if sp.moving:
            kern = kernels()
            dy = np.ascontiguousarray(y[:, 1:])
            for i, j, g in zip(sp.moving, sp.derivative_row, sp.weights, strict=True):
                a, b0, b1 = sp.a[i], sp.b0[i], sp.b1[i]
                da, db0, db1 = sp.da[j], sp.db0[j], sp.db1[j]
                if kern is not None:
                    kern.mode_derivative(u, a, b0, b1, da, db0, db1, g, dy)
                    continue
                x = _scipy_signal().lfilter([b1, b0], [1.0, -a], u)
                rhs = da * np.r_[0.0, x[:-1]] + db0 * np.r_[0.0, u[:-1]] + db1 * u
                z = _scipy_signal().lfilter([1.0], [1.0, -a], rhs)
                dy += (g[None, :] * z[:, None]).real
            y[:, 1:] = dy
        return y[:, 0] + rest_V, y[:, 1], y[:, 2]

    def kernel(self, n: int, rate_hz: float, hold: str = "zoh") -> NDArray[np.float64]:
        """Exact sampled kernel ``k`` with ``y = k * v`` (length ``n``).

        Parameters
        ----------
        n : int
            Number of samples.
        rate_hz : float
            Sample rate (Hz).
        hold : {"zoh", "linear"}
            How the input behaves between samples (module docstring).

        Returns
        -------
        numpy.ndarray
            The kernel, length ``n``.
        """
        return sampled_kernel(self.tau_s, self.lam, _check_rate(rate_hz), n, hold)

    def modes(self, rate_hz: float) -> ContinuousModes:
        """Continuous modal (diffusive) approximation used by ``method="fast"``.

        Parameters
        ----------
        rate_hz : float
            Sample rate (Hz).

        Returns
        -------
        ContinuousModes
            The modes and instantaneous gains of the diffusive realisation.
        """
        return diffusive_modes(self.tau_s, self.lam, _check_rate(rate_hz))

    def bank(self, rate_hz: float, hold: str = "zoh") -> DiscreteBank:
        """The discrete modal bank of ``method="fast"``.

        Parameters
        ----------
        rate_hz : float
            Sample rate (Hz).
        hold : {"zoh", "linear"}
            How the input behaves between samples (module docstring).

        Returns
        -------
        DiscreteBank
            The modes discretised exactly for ``hold`` (cached).
        """
        return _bank(self.tau_s, self.lam, _check_rate(rate_hz), hold)

    def stepper(self, rate_hz: float, hold: str = "zoh") -> BankStepper:
        """Per-sample realisation for a control loop: ``y_n = stepper.step(v_n)``.

        Parameters
        ----------
        rate_hz : float
            Sample rate (Hz).
        hold : {"zoh", "linear"}
            How the input behaves between samples (module docstring).

        Returns
        -------
        BankStepper
            At rest.
        """
        return BankStepper(self.bank(rate_hz, hold))

    def inverse_filter(self, y: ArrayLike, rate_hz: float) -> NDArray[np.float64]:
        """Band-limited ``1 + (tau s)^lam`` for a controller: the ZOH drive ``v`` for output ``y``.

        For ``lam <= 1`` this is the exact inverse of the sampled ZOH relaxor: ``v`` such that
        ``filter(v, method="exact") = y`` at every sample (one sample of preview; the last sample
        repeats ``y[-1]``), computed by power-series reciprocal of the kernel. It is stable: the
        relaxor is then a Stieltjes function and the reciprocal series decays.

        For ``1 < lam < 2`` the sampled relaxor has zeros outside the unit circle, so that exact
        inverse diverges; instead ``y`` (the wanted relaxor output, sampled, taken linear
        between samples and at rest before ``t_0``) defines the exact continuous input
        ``y + tau^lam D^lam y`` (Riemann-Liouville derivative; ``1/G`` applied to ``y``).
        A DAC holds each ``v[n]`` on
        ``[t_n, t_{n+1})``, so we return the mean of that exact input over each interval:

            v[n] = (y[n] + y[n+1]) / 2 + tau^lam (Phi[n+1] - Phi[n]) / dt,
            Phi = D^(lam-1) y = sum_k y[k] W[n-k],
            W[m] = dt^(1-lam) / Gamma(3-lam) * second difference of m^(2-lam)

        (``W`` is the exact response of ``s^(lam-1)`` to the linear hold). This is a convolution
        with a decaying kernel, stable for every ``0 < lam < 2``, O(N log N), and needs one sample
        of preview (``y[n+1]``; the last sample repeats ``y[-1]``).
        Band and error: the interval mean is the band limit (a sinc with its first zero at the
        sample rate); ``filter(v, method="exact", hold="zoh")`` reproduces ``y`` with a residual
        that falls as ``(f/rate)^1.4`` for the paper's ``G_d`` (measured: 4e-5 of full scale at
        1 Hz, 2e-4 at 5 Hz, 4e-3 at 40 Hz, 1 kHz sampling).

        Parameters
        ----------
        y : array_like
            The wanted output record.
        rate_hz : float
            Sample rate (Hz).

        Returns
        -------
        numpy.ndarray
            The drive ``v``, one value per sample of ``y``.
        """
        y = np.asarray(y, dtype=np.float64)
        dt = _check_rate(rate_hz)
        if y.size == 0:
            return y.copy()
        if self.lam <= 1.0:
            # exact discrete inverse of the ZOH kernel: y[n+1] = sum_k h[n+1-k] v[k]
            h = sampled_kernel(self.tau_s, self.lam, dt, y.size + 1, "zoh")[1:]
            y_next = np.append(y[1:], y[-1])
            return _scipy_signal().fftconvolve(y_next, series_reciprocal(h))[: y.size]
        y_ext = np.append(y, y[-1])
        w = power_ramp_kernel(self.lam - 1.0, dt, y_ext.size)
        phi = _scipy_signal().fftconvolve(y_ext, w)[: y_ext.size]
        mean_y = 0.5 * (y_ext[:-1] + y_ext[1:])
        return mean_y + self.tau_s**self.lam * np.diff(phi) / dt

    def inverse_stepper(self, rate_hz: float) -> InverseStepper:
        """Per-sample ``1 + (tau s)^lam`` for ``lam <= 1`` (exact inverse of the fast bank).

        For ``lam <= 1`` the relaxor is a Stieltjes function: the modal bank has positive
        weights, real poles and interlacing real zeros, so its exact inverse is stable (checked by
        :func:`check_inverse_stable`). For ``lam > 1`` the truncated bank is not minimum-phase and
        this raises ``ValueError``; use :meth:`inverse_filter` offline.

        Parameters
        ----------
        rate_hz : float
            Sample rate (Hz).

        Returns
        -------
        InverseStepper
            At rest.
        """
        if self.lam > 1.0:
            raise ValueError(
                f"no stable per-sample inverse for lam = {self.lam} > 1; use inverse_filter"
            )
        return InverseStepper(self.bank(rate_hz, "linear"))


class InverseStepper:
    """``v[n]`` such that the bank's output at ``n`` equals ``y[n]`` (O(M) per sample).

    Parameters
    ----------
    bank : DiscreteBank
        A bank with a positive instantaneous gain (the linear hold).
    """

    def __init__(self, bank: DiscreteBank):
        self._g = bank.feedthrough
        if self._g <= 0:
            raise ValueError("inversion needs a positive instantaneous gain (linear hold)")
        self._fwd = BankStepper(bank)

    def step(self, y: float) -> float:
        """The input ``v[n]`` whose output is ``y``; the bank advances with it.

        Parameters
        ----------
        y : float
            The wanted output at this sample.

        Returns
        -------
        float
            The input that gives it.
        """
        v = (y - self._fwd.peek(0.0)) / self._g
        self._fwd.step(v)
        return v


# -- exact kernels ----------------------------------------------------------------------------


class _LogChebyshevStep:
    """Branch-cut part of the step response on half-decade panels in log t (Chebyshev)."""

    def __init__(self, tau_s: float, lam: float, t_lo: float, t_hi: float):
        self.tau_s, self.lam = tau_s, lam
        self.u0 = np.log10(t_lo)
        npan = max(1, int(np.ceil((np.log10(t_hi) - self.u0) * _PANELS_PER_DECADE)))
        self.width = 1.0 / _PANELS_PER_DECADE
        self.coeffs = []
        for p in range(npan):
            a = self.u0 + p * self.width

            def f(x: NDArray, a: float = a) -> NDArray:
                t = 10.0 ** (a + (x + 1.0) * self.width / 2)
                return relaxor_step(t, tau_s, lam) - relaxor_step_pole_part(t, tau_s, lam)

            # numpy's stub wants f to return a scalar; chebinterpolate calls it with the array
            # of nodes and needs the array of values
            self.coeffs.append(C.chebinterpolate(f, _CHEB_NODES - 1))  # type: ignore[type-var]

    def branch(self, t: NDArray) -> NDArray:
        """The branch-cut part of the step response at ``t`` (s); compiled Clenshaw sums when
        numba is available, else one numpy ``chebval`` per panel."""
        t = np.ascontiguousarray(t, dtype=np.float64)
        coeffs = np.ascontiguousarray(self.coeffs)
        kern = kernels()
        u = np.log10(t)
        if kern is not None:
            return kern.chebyshev_panels(u, self.u0, self.width, coeffs)
        pan = np.clip(((u - self.u0) / self.width).astype(int), 0, len(self.coeffs) - 1)
        x = 2.0 * (u - (self.u0 + pan * self.width)) / self.width - 1.0
        out = np.empty_like(t)
        if np.all(pan[1:] >= pan[:-1]):  # sorted times (the kernels'): contiguous panels
            cuts = np.r_[0, np.flatnonzero(np.diff(pan)) + 1, pan.size]
            for i, j in itertools.pairwise(cuts):
                out[i:j] = C.chebval(x[i:j], coeffs[pan[i]])
            return out
        for p in np.unique(pan):
            sel = pan == p
            out[sel] = C.chebval(x[sel], coeffs[p])
        return out

    def __call__(self, t: NDArray) -> NDArray:
        return self.branch(t) + relaxor_step_pole_part(t, self.tau_s, self.lam)


def _step_grid(tau_s: float, lam: float, dt: float, n: int) -> NDArray[np.float64]:
    """``s(m dt)`` for ``m = 0..n``: direct for small m, interpolated beyond."""
    m = np.arange(n + 1, dtype=np.float64)
    out = np.empty(n + 1)
    k = min(n + 1, _EXACT_SAMPLES)
    out[:k] = relaxor_step(m[:k] * dt, tau_s, lam)
    if n + 1 > k:
        interp = _LogChebyshevStep(tau_s, lam, k * dt, (n + 1) * dt)
        out[k:] = interp(m[k:] * dt)
    return out


# Gauss-Legendre with 2 points per interval: for m >= 2048 samples the error of an interval
# mean is about (dt/t)^4 t^4 |s^(4)| / 4320 < 1e-16 of the step response
_GL2_X, _GL2_W = np.polynomial.legendre.leggauss(2)


def _interval_means(tau_s: float, lam: float, dt: float, n: int) -> NDArray[np.float64]:
    """Mean of ``s`` over ``[m dt, (m+1) dt]`` for ``m = 0..n-1``."""
    out = np.empty(n)
    k = min(n, _EXACT_SAMPLES)
    edges = np.arange(k + 1) * dt
    r = relaxor_ramp(edges, tau_s, lam)
    out[:k] = np.diff(r) / dt
    if n > k:
        m = np.arange(k, n, dtype=np.float64)
        interp = _LogChebyshevStep(tau_s, lam, k * dt, (n + 1) * dt)
        acc = np.zeros(m.size)
        for x, w in zip(_GL2_X, _GL2_W, strict=True):
            acc += 0.5 * w * interp.branch((m + 0.5 + 0.5 * x) * dt)
        # pole part integrated in closed form: mean of -(2/lam) Re e^{pt} over the interval,
        # where it has not yet decayed below 1e-30
        p = pole_pair(tau_s, lam)
        if p is not None:
            live = m * dt * p.real > -70.0
            ta, tb = m[live] * dt, (m[live] + 1) * dt
            acc[live] += -(2.0 / lam) * ((np.exp(p * tb) - np.exp(p * ta)) / (p * dt)).real
        out[k:] = acc
    return out


def sampled_kernel(tau_s: float, lam: float, dt: float, n: int, hold: str) -> NDArray[np.float64]:
    """Exact sampled kernel of the relaxor for a hold (module docstring), length ``n``.

    Parameters
    ----------
    tau_s : float
        Time constant (s).
    lam : float
        Order (``0 < lam < 2``).
    dt : float
        Sample period (s).
    n : int
        Number of samples.
    hold : {"zoh", "linear"}
        The input's hold.

    Returns
    -------
    numpy.ndarray
        ``k`` with ``y = k * v`` (discrete convolution).
    """
    _validate(tau_s, lam)
    if hold == "zoh":
        s = _step_grid(tau_s, lam, dt, n)
        k = np.empty(n)
        k[0] = 0.0
        k[1:] = np.diff(s)[: n - 1]
        return k
    if hold == "linear":
        means = _interval_means(tau_s, lam, dt, n)
        return np.diff(means, prepend=0.0)
    raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")


def series_reciprocal(h: NDArray) -> NDArray:
    """Causal inverse ``r`` of the sequence ``h`` (``h * r = delta``), by Newton's iteration on
    power series with FFT products: O(N log N); requires ``h[0] != 0``; real or complex.

    Parameters
    ----------
    h : numpy.ndarray
        The sequence (``h[0] != 0``).

    Returns
    -------
    numpy.ndarray
        ``r``, the length of ``h``.

    Examples
    --------
    The inverse of ``1 - z^-1`` is the running sum:

    >>> import numpy as np
    >>> series_reciprocal(np.array([1.0, -1.0, 0.0, 0.0])).round(12).tolist()
    [1.0, 1.0, 1.0, 1.0]
    """
    n = h.size
    r = np.array([1.0 / h[0]])
    m = 1
    while m < n:
        m = min(2 * m, n)
        e = -_scipy_signal().fftconvolve(h[:m], r)[:m]
        e[0] += 2.0
        r = _scipy_signal().fftconvolve(r, e)[:m]
    return r


def power_ramp_kernel(mu: float, dt: float, n: int) -> NDArray[np.float64]:
    """Sampled response of ``s^mu`` (``-1 < mu < 1``) to the linear hold, length ``n``.

    The ramp response of ``s^mu`` is ``t^(1-mu) / Gamma(2-mu)``; under the linear hold the
    kernel is its second difference divided by ``dt``. For large ``m`` the second difference of
    ``m^p`` is evaluated as ``m^p [expm1(p log1p(1/m)) + expm1(p log1p(-1/m))]`` to avoid
    cancellation (relative error ~1e-16 m instead of 1e-16 m^2).

    Parameters
    ----------
    mu : float
        The power (``-1 < mu < 1``).
    dt : float
        Sample period (s).
    n : int
        Number of samples.

    Returns
    -------
    numpy.ndarray
        The kernel, length ``n``.
    """
    from scipy.special import gamma as gamma_fn

    p = 1.0 - mu
    m = np.arange(n, dtype=np.float64)
    d2 = np.empty(n)
    d2[0] = 1.0  # (1)^p - 2*0 + 0
    if n > 1:
        mm = m[1:]
        small = mm < 4
        d2[1:][small] = (mm[small] + 1) ** p - 2 * mm[small] ** p + (mm[small] - 1) ** p
        mb = mm[~small]
        d2[1:][~small] = mb**p * (np.expm1(p * np.log1p(1 / mb)) + np.expm1(p * np.log1p(-1 / mb)))
    return d2 * dt ** (p - 1.0) / gamma_fn(p + 1.0)


# -- diffusive (modal) realisation ------------------------------------------------------------


@lru_cache(maxsize=64)
def _modes(tau_s: float, lam: float, dt: float) -> tuple[ContinuousModes, ModeDerivatives]:
    _validate(tau_s, lam)
    return diffusive.modes(tau_s, lam, dt)


def diffusive_modes(tau_s: float, lam: float, dt: float) -> ContinuousModes:
    """Modal realisation of the relaxor at sample period ``dt`` (s) (labrig.model.diffusive).

    Parameters
    ----------
    tau_s : float
        Time constant (s).
    lam : float
        Order (``0 < lam < 2``).
    dt : float
        Sample period (s).

    Returns
    -------
    ContinuousModes
        The modes (cached).
    """
    return _modes(tau_s, lam, dt)[0]


@lru_cache(maxsize=64)
def _bank(tau_s: float, lam: float, dt: float, hold: str) -> DiscreteBank:
    return diffusive_modes(tau_s, lam, dt).discretise(dt, hold)


@dataclass(frozen=True)
class _SensitivityPass:
    """What :meth:`Relaxor.filter_sensitivities` needs besides the input: the bank with the
    instantaneous gains as two more modes, the output rows of the derivatives (``extra``), and
    for each mode whose pole moves with the parameters (``moving``, a conjugate pair once) its
    discretised gains, their derivatives (row ``derivative_row`` of ``da``, ``db0``, ``db1``)
    and its weighted residue derivative ``weights`` (twice the real part of a pair's member).
    It depends on the parameters, the sample period and the hold only: every entry of a fit
    at one rate shares it (:func:`_sensitivity_pass` keeps it)."""

    bank: DiscreteBank
    extra: NDArray[np.complex128]
    a: NDArray[np.complex128]
    b0: NDArray[np.complex128]
    b1: NDArray[np.complex128]
    moving: tuple[int, ...]
    derivative_row: tuple[int, ...]
    weights: tuple[NDArray[np.complex128], ...]
    da: NDArray[np.complex128]
    db0: NDArray[np.complex128]
    db1: NDArray[np.complex128]


@lru_cache(maxsize=64)
def _sensitivity_pass(tau_s: float, lam: float, dt: float, hold: str) -> _SensitivityPass:
    """The :class:`_SensitivityPass` of ``(tau_s, lam)`` at sample period ``dt`` (s)."""
    modes, der = _modes(tau_s, lam, dt)
    a, b0, b1 = hold_gains(modes.q, dt, hold)
    m1, m2, dm1, dm2 = modes.direct_m1, modes.direct_m2, der.dm1, der.dm2
    if hold == "zoh":  # the instantaneous gains on u[n-1] and u[n]
        d0, d1, dd0, dd1 = m1, 0.0, dm1, np.zeros(2)
    else:
        d0, d1, dd0, dd1 = m2 / dt, m1 - m2 / dt, dm2 / dt, dm1 - dm2 / dt
    bank = DiscreteBank.from_arrays(
        np.r_[a, 0.0, 0.0], np.r_[b0, 1.0, 0.0], np.r_[b1, 0.0, 1.0], np.r_[modes.c, d0, d1]
    )
    extra = np.hstack([der.dc, dd0[:, None], dd1[:, None]])
    moving = np.flatnonzero(np.any(der.dq != 0, axis=0))
    empty = np.zeros(0, dtype=np.complex128)
    da, db0, db1 = hold_gain_derivatives(modes.q[moving], dt, hold) if moving.size else (empty,) * 3
    q, c = modes.q, modes.c
    kept: list[int] = []
    rows: list[int] = []
    weights: list[NDArray[np.complex128]] = []
    done: set[int] = set()
    for j, i in enumerate(moving.tolist()):
        if i in done:
            continue
        weight = 1.0  # a conjugate pair adds twice the real part of one member
        k = i + 1
        if k < q.size and q[k] == np.conj(q[i]) and c[k] == np.conj(c[i]):
            weight = 2.0
            done.add(k)
        kept.append(i)
        rows.append(j)
        weights.append(weight * c[i] * der.dq[:, i])
    return _SensitivityPass(
        bank, extra, a, b0, b1, tuple(kept), tuple(rows), tuple(weights), da, db0, db1
    )


def check_inverse_stable(bank: DiscreteBank) -> float:
    """Spectral radius of the inverse recursion (<= 1 + 1e-12 means the inverse is stable).

    The slowest mode (1e-10 rad/s) puts a zero within a few ulps of 1, which double-precision
    eigenvalues cannot resolve: radii within 1e-12 of 1 are rounding, not instability.

    Parameters
    ----------
    bank : DiscreteBank
        A bank with a non-zero instantaneous gain.

    Returns
    -------
    float
        The largest eigenvalue modulus of the inverse's recursion.
    """
    # inverse system: state update x[n] = A x[n-1] + b0 u[n-1] + b1 u[n], with
    # u[n] = (y[n] - c.(A x[n-1] + b0 u[n-1])) / g; closed loop on (x, u_prev).
    a = np.concatenate([g.a for g in bank.groups]).astype(complex)
    b0 = np.concatenate([g.b0 for g in bank.groups]).astype(complex)
    b1 = np.concatenate([g.b1 for g in bank.groups]).astype(complex)
    c = np.concatenate([g.c for g in bank.groups]).astype(complex)
    gain = np.sum(c * b1)
    m = a.size
    # z = [x; u_prev]; u = -(c.A x + c.b0 u_prev)/g (y = 0)
    k_x = -(c * a) / gain
    k_u = -np.sum(c * b0) / gain
    top = np.diag(a) + np.outer(b1, k_x)
    top_u = b0 + b1 * k_u
    M = np.zeros((m + 1, m + 1), dtype=complex)
    M[:m, :m] = top
    M[:m, m] = top_u
    M[m, :m] = k_x
    M[m, m] = k_u
    return float(np.max(np.abs(np.linalg.eigvals(M))))
