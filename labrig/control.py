"""Compensation control: the drive voltage that makes the model follow a strain command.

The model (seed Eq. 12, :class:`~labrig.model.DynamicHysteresisModel`) is

    S = alpha0 V* + H[V*],      V* = G_d G_t V

so the voltage that makes it follow a strain command ``S_com`` (ue) is (seed Eq. 13, Fig. 14)

    V = G_t^-1 G_d^-1 u,        u solves  alpha0 u + H[u] = S_com:

the quasi-static operator is inverted exactly along its branches
(:meth:`QuasiStaticHysteresis.invert`), then the two relaxors are inverted. "Direct" control (the
seed's baseline) inverts only the linear part, ``V = S_com / alpha0``.

Discretisation (what "inverse" means here)
------------------------------------------
A command is a record ``S[n]`` at ``rate_hz``; the drive ``V[n]`` is held by the DAQ on
``[t_n, t_{n+1})`` and the actuator is at rest at 0 V before ``t_0`` (so ``S[0]`` should be 0).
The drive is the exact inverse of the model *as* :meth:`DynamicHysteresisModel.predict`
*discretises it*: ``G_t`` driven with the zero-order hold, ``G_d`` with the linear hold on
``G_t``'s samples. Both are linear convolutions with exact sampled kernels
(:func:`labrig.model.relaxor.sampled_kernel`), so the drive solves

    k_d * vt = u,        k_t * V = vt          (sample by sample, n >= 0)

- ``G_t`` (zero-order hold): ``vt[n+1]`` is the first sample ``V[n]`` reaches, so ``V[n]`` needs
  one sample of preview; for ``lam_t <= 1`` this is :meth:`Relaxor.inverse_filter`.
- ``G_d`` (linear hold): for ``lam_d > 1`` its sampled kernel has a zero *outside* the unit
  circle (``z ~ -1.34`` for the ``G_d`` fitted on the hybrid rig, ``-1.59`` for the seed's, at
  1 kHz; it comes from the hold, not from the physics), so the causal inverse diverges. The zero
  ``zeta`` is inverted anti-causally instead (``1/(1 - zeta z^-1) = -sum_m zeta^-m z^m``): the
  drive at ``n`` looks ahead at the command; the weights fall as ``|zeta|^-m``. The rest of the
  kernel is minimum phase and is inverted causally (power-series reciprocal).

The outside zeros are found for any relaxor and hold (as eigenvalues of the modal bank's inverse
recursion, polished on the exact kernel), so the same code serves ``lam_t > 1`` or ``lam_d < 1``.

Offline (:func:`compensated_drive`) the look-ahead is exact (the command continues at its last
value), so ``predict(compensated_drive(S)) == S`` up to rounding, except for a start-up transient
of a few samples (the anti-causal part would need drive before ``t_0``; the first sample takes
the defect, whose effect then decays with the relaxors' memory). Measured at 1 kHz for a 0-1000 ue
sine (fitted hybrid parameters / seed's control parameters): the peak error is at sample 1-2,
7e-7 / 1.4e-6 of the command span at 1 Hz and 1.2e-3 / 2.4e-3 at 40 Hz; after 0.1 s it is below
3e-8 / 3e-7 of the span, the modal (``"fast"``) realisation of ``predict`` adding its own ~3e-10.
:func:`model_tracking_error` measures it. Start commands smoothly from 0 (the protocol's commands
do): a reversal inside the start-up transient would keep its error in the hysteresis memory.

Per sample (:class:`CompensationController`): the same inverse, realised on the relaxors' modal
banks (:meth:`Relaxor.bank`, the ``"fast"`` method). The inverse of each bank is a recursion
``z[n] = A z[n-1] + B y[n]`` (one state per mode, plus the last output) whose matrix has the
kernel's outside zeros as eigenvalues; their eigen-directions are split off and solved
anti-causally over a look-ahead window (``preview``), the rest runs forward and is re-projected
every 16 samples so rounding cannot build up in the unstable direction. Cost O(modes + preview) per
sample, no history kept. It agrees with the offline drive to the quadrature error of the banks
plus ``|zeta|^-preview`` (default window: 1e-9).

Limits
------
:func:`check_drive` compares a drive with a rig's :class:`~labrig.limits.RigLimits` the way the
protocol preflight does (voltage range; peak current ``C_eff dV/dt`` via
:meth:`RigLimits.current_A` on a grid 4 times finer than the rate; mean ``|i|`` over one command
period, or 1 s) and raises :class:`InfeasibleCommandError` (a ``ValueError``) saying what the
command needs and what the rig gives. Compensation asks for negative voltages (to cancel the
drift, seed Fig. 17): within ``v_min_V`` they are allowed.

Metrics for strain-command entries (plain functions of arrays, for reports)
--------------------------------------------------------------------------
- :func:`tracking_nrmse_pct`: ``100 RMS(S - S_com) / (max S_com - min S_com)``.
- :func:`hysteresis_width_pct`: over the last command period, the largest difference between the
  falling and the rising branch of the measured strain at the same command (both interpolated on
  101 commands spanning the middle 90 % of the loop), in % of the command span; signed, positive
  for the piezo's orientation (falling above rising), report ``abs`` for "width".
- :func:`zero_command_strain_ue`: over the last command period, the strain where the command is
  at its minimum (0 for a unipolar sine; averaged over the samples within 1 % of the span of it):
  the seed's "strain bias at zero command".
- :func:`final_strain_ue`: mean strain over the last ``window_s`` of the command (the vanishing
  command's end), with its noise-limited standard error.
- :func:`entry_metrics`: all of them for one recorded strain-command entry (a ``Record``),
  over its command samples, with ``control`` and ``frequency_hz``: what ``labrig report``
  needs per strain-command entry.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg, signal

from labrig.limits import RigLimits
from labrig.model import DynamicHysteresisModel, ModelParams, QuasiStaticHysteresis, Relaxor
from labrig.model.bouc_wen import bouc_wen_exact, bouc_wen_step, max_slope
from labrig.model.effects import kelvin_voigt_filter, library
from labrig.model.modal import DiscreteBank
from labrig.model.relaxor import sampled_kernel, series_reciprocal

__all__ = [
    "CONTROLS",
    "CompensationController",
    "ControlModel",
    "DirectController",
    "DriveCheck",
    "InfeasibleCommandError",
    "check_drive",
    "compensated_drive",
    "compute_drive",
    "control_metrics",
    "direct_drive",
    "entry_metrics",
    "final_strain_ue",
    "hysteresis_width_pct",
    "load_control_model",
    "load_params",
    "model_tracking_error",
    "outside_zeros",
    "tracking_nrmse_pct",
    "zero_command_strain_ue",
]

CONTROLS = ("direct", "compensated")
#: look-ahead window of the per-sample controller: anti-causal weights are cut below this
PREVIEW_TOL = 1e-9
#: a zero of a sampled kernel farther than this from the unit circle counts as outside
_OUTSIDE = 1.0 + 1e-6
#: the per-sample inverse removes rounding's unstable components every this many samples
#: (they grow like |zeta|^n: by at most 1.7^16 ~ 5e3 in between, from 1e-16)
_REPROJECT = 16
#: preflight's grid refinement for the current (kept equal to labrig.protocol.preflight)
_OVERSAMPLE = 4
_AVG_WINDOW_S = 1.0
#: zero-command strain: samples whose command is within this fraction of the span of its minimum
_ZERO_BAND = 0.01
#: most secant iterations of the remanence inverse per sample (3-5 reach 1e-12 in practice)
_FIXED_POINT_ITER = 60

Array = NDArray[np.float64]


class InfeasibleCommandError(ValueError):
    """The drive a command needs is beyond the rig (voltage range or amplifier current).

    ``kind`` is ``"voltage"``, ``"peak_current"`` or ``"mean_current"``; ``needed`` and
    ``limit`` are in V or A; ``time_s`` is where in the command it happens.
    """

    def __init__(self, message: str, kind: str, needed: float, limit: float, time_s: float):
        super().__init__(message)
        self.kind, self.needed, self.limit, self.time_s = kind, needed, limit, time_s


# -- parameters --------------------------------------------------------------------------------


#: actuator effects (labrig.model.effects) the controller inverts along with the model
INVERTIBLE_EFFECTS = ("viscoelastic_creep", "remanence")


@dataclass(frozen=True)
class ControlModel:
    """What the compensation inverts: the dynamic model and, optionally, the actuator effects
    fitted with it (``labrig fit --effect viscoelastic_creep --effect remanence``):
    ``S = KV[alpha0 V* + H[V*] - h[V*]]``, ``KV`` = :func:`labrig.model.effects.
    kelvin_voigt_filter` with ``creep = (c, tau_s)``, ``h`` the Bouc-Wen state of
    :class:`labrig.model.effects.Remanence` with ``remanence = (A, beta, gamma)`` (ue/V, 1/V,
    1/V)."""

    params: ModelParams
    creep: tuple[float, float] | None = None
    remanence: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.creep is not None:
            c, tau = self.creep
            if not (math.isfinite(c) and -1.0 < c < 1.0 and math.isfinite(tau) and tau > 0):
                raise ValueError(
                    f"viscoelastic_creep needs -1 < c < 1 and tau_s > 0, got c={c}, tau_s={tau}"
                )
        if self.remanence is not None:
            A, beta, gam = self.remanence
            bounded = beta > 0 and abs(gam) <= beta and beta + (gam if A >= 0 else -gam) > 0
            if not (all(map(math.isfinite, self.remanence)) and bounded):
                raise ValueError(
                    "remanence needs beta > 0, |gamma| <= beta and beta + sign(A) gamma > 0 (a "
                    f"bounded element), got A={A}, beta={beta}, gamma={gam}"
                )
            # the inverse needs S = H - h increasing along every branch: the element's steepest
            # slope below the operator's shallowest
            p = self.params
            g = p.gamma_ue_per_V
            op_min = p.alpha0_ue_per_V + min(0.0, g) if p.shape != "linear" or g >= 0 else -1.0
            if not max_slope(A, beta, gam) < op_min:
                raise ValueError(
                    f"remanence needs to be less steep than the operator for an invertible "
                    f"strain: A={A:.4g} ue/V, beta={beta:.4g}, gamma={gam:.4g} /V reaches "
                    f"{max_slope(A, beta, gam):.4g} ue/V, the operator only {op_min:.4g} ue/V"
                )

    def predict(self, v: ArrayLike, rate_hz: float, method: str = "fast") -> Array:
        """The strain (ue) this model gives for the drive ``v`` (V), at rest before it."""
        model = DynamicHysteresisModel(self.params)
        x = model.equivalent_static_voltage(v, rate_hz, method)
        y = model.operator.apply(x)
        if self.remanence is not None:
            y = y - bouc_wen_exact(np.concatenate(([0.0], x)), *self.remanence)[1:]
        ba = self.creep_filter(rate_hz)
        return y if ba is None else signal.lfilter(ba[0], ba[1], y)

    def creep_filter(self, rate_hz: float) -> tuple[Array, Array] | None:
        """``(b, a)`` of the creep filter at ``rate_hz`` (None without creep)."""
        if self.creep is None:
            return None
        return kelvin_voigt_filter(self.creep[0], self.creep[1], rate_hz)


def as_control_model(model: ModelParams | ControlModel) -> ControlModel:
    """A :class:`ControlModel` for either argument form (``ModelParams``: no creep)."""
    return model if isinstance(model, ControlModel) else ControlModel(model)


def _read_json(p: Path) -> Any:
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ValueError(f"{p.name} is not valid JSON (line {e.lineno}: {e.msg})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{p.name} is not a text file") from None


def _validated_params(data: Any, name: str) -> ModelParams:
    if isinstance(data, dict) and isinstance(data.get("params"), dict):
        data = data["params"]
    if not isinstance(data, dict):
        raise ValueError(f"{name}: expected a JSON object with a 'params' mapping")
    try:
        return ModelParams.model_validate(data)
    except Exception as e:  # pydantic ValidationError: say which fields
        errs = getattr(e, "errors", None)
        if callable(errs):
            parts = [f"{'.'.join(map(str, x['loc'])) or 'params'}: {x['msg']}" for x in errs()]
            raise ValueError(f"{name}: invalid model parameters ({'; '.join(parts)})") from None
        raise ValueError(f"{name}: invalid model parameters ({e})") from None


def load_params(path: str | Path) -> ModelParams:
    """:class:`ModelParams` from a JSON file written by ``labrig fit --out``.

    The file's ``params`` key holds the :class:`ModelParams` fields (``FitResult.to_json()``);
    a file that is itself a mapping of those fields is accepted too. Raises ``ValueError``
    (``OSError`` for an unreadable file) with a message naming the problem.
    """
    p = Path(path)
    return _validated_params(_read_json(p), p.name)


def load_control_model(path: str | Path) -> ControlModel:
    """:class:`ControlModel` from ``labrig fit --out`` JSON: its ``params`` and the invertible
    effects (:data:`INVERTIBLE_EFFECTS`) in its ``effects`` list. Any other fitted effect is
    refused with a ``ValueError`` naming it (the controller cannot invert it)."""
    p = Path(path)
    data = _read_json(p)
    params = _validated_params(data, p.name)
    effects = data.get("effects", []) if isinstance(data, dict) else []
    if not isinstance(effects, list):
        raise ValueError(f"{p.name}: 'effects' must be a list of {{effect, params}} objects")
    found: dict[str, tuple[float, ...]] = {}
    for e in effects:
        name = e.get("effect") if isinstance(e, dict) else None
        if name not in INVERTIBLE_EFFECTS:
            raise ValueError(
                f"{p.name}: the controller cannot invert the effect {name!r} (it inverts "
                f"{', '.join(INVERTIBLE_EFFECTS)}); refit without --effect {name}"
            )
        keys = [q.name for q in library()[name].params]  # ControlModel's order
        q = e.get("params", {})
        try:
            found[name] = tuple(float(q[k]) for k in keys)
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{p.name}: {name} needs numeric params {', '.join(keys)}") from None
    creep, rem = found.get("viscoelastic_creep"), found.get("remanence")
    try:
        return ControlModel(
            params,
            None if creep is None else (creep[0], creep[1]),
            None if rem is None else (rem[0], rem[1], rem[2] * rem[1]),  # gamma = ratio * beta
        )
    except ValueError as e:
        raise ValueError(f"{p.name}: {e}") from None


# -- offline (whole-waveform) drives -------------------------------------------------------------


def _command(strain_ue: ArrayLike) -> Array:
    s = np.asarray(strain_ue, dtype=np.float64)
    if s.ndim != 1:
        raise ValueError("the strain command must be a 1-D record")
    if not np.all(np.isfinite(s)):
        raise ValueError("the strain command contains NaN or infinite values")
    return s


def direct_drive(strain_ue: ArrayLike, params: ModelParams | ControlModel) -> Array:
    """``V = S_com / alpha0`` held on each sample interval: ``V[n]`` is the interval mean
    ``(S[n] + S[n+1]) / (2 alpha0)`` (the last sample repeats ``S[-1]``), the same timing as
    :func:`compensated_drive` so the two controls are compared on equal terms."""
    s = _command(strain_ue)
    if s.size == 0:
        return s.copy()
    nxt = np.append(s[1:], s[-1])
    return 0.5 * (s + nxt) / as_control_model(params).params.alpha0_ue_per_V


def _real_layout(bank: DiscreteBank, zoh: bool):
    """Modes of ``bank`` as one complex array each (a, b0, b1, c, complex flag).

    ``zoh=True`` gives the one-sample-shifted zero-order-hold bank (``x'[n] = x[n+1]``,
    ``y'[n] = y[n+1]``): its input enters with no delay, like the linear hold's ``b1``.
    """
    a = np.concatenate([g.a for g in bank.groups]).astype(complex)
    b0 = np.concatenate([g.b0 for g in bank.groups]).astype(complex)
    b1 = np.concatenate([g.b1 for g in bank.groups]).astype(complex)
    c = np.concatenate([g.c for g in bank.groups]).astype(complex)
    cplx = np.concatenate([np.full(g.size, np.iscomplexobj(g.a)) for g in bank.groups])
    if zoh:
        b0, b1 = np.zeros_like(b0), b0
    return a, b0, b1, c, cplx


@dataclass(frozen=True)
class _InverseSystem:
    """The inverse recursion of a bank in real coordinates ``z = [Re x, Im x (complex modes),
    v_prev]`` and its unstable eigen-directions (see :class:`_BankInverse`)."""

    a: NDArray[np.complex128]
    b0: NDArray[np.complex128]
    b1: NDArray[np.complex128]
    c: NDArray[np.complex128]
    cplx: NDArray[np.bool_]
    gain: float  # Re(c . b1): the input's immediate effect on the output
    cb0: float  # Re(c . b0)
    lam: NDArray[np.complex128]  # unstable eigenvalues (one of each conjugate pair)
    left: NDArray[np.complex128]  # (k, R) left eigenvectors, left[k] . right[k] = 1
    right: NDArray[np.complex128]  # (k, R)
    weight: NDArray[np.float64]  # 1 for a real eigenvalue, 2 for a pair


def _inverse_matrix(a, b0, b1, c, cplx) -> tuple[NDArray, float, float]:
    """Dense real matrix of ``z[n] = A z[n-1] + B y[n]`` (for the eigen-analysis only)."""
    m = a.size
    ci = np.flatnonzero(cplx)
    r = m + ci.size + 1
    g = float(np.sum(c * b1).real)
    if not g > 0:
        raise ValueError("the bank has no immediate response to its input; cannot invert")
    cb0 = float(np.sum(c * b0).real)
    # v = (y - Re(c.(a x)) - cb0 v_prev) / g ; kx = -(c a)/g acting on x = xr + i xi
    k = -(c * a) / g
    row_v = np.zeros(r)
    row_v[:m] = k.real
    row_v[m : m + ci.size] = -k.imag[ci]
    row_v[-1] = -cb0 / g
    A = np.zeros((r, r))
    A[-1] = row_v
    # Re x' = Re(a) Re x - Im(a) Im x + Re(b0) v_prev + Re(b1) v
    idx = np.arange(m)
    A[idx, idx] = a.real
    A[idx, -1] += b0.real
    A[:m] += np.outer(b1.real, row_v)
    for j, i in enumerate(ci):
        ri = m + j
        A[i, ri] += -a[i].imag
        A[ri, i] += a[i].imag
        A[ri, ri] += a[i].real
        A[ri, -1] += b0[i].imag
        A[ri] += b1[i].imag * row_v
    return A, g, cb0


@lru_cache(maxsize=32)
def _inverse_system(tau_s: float, lam: float, rate_hz: float, hold: str) -> _InverseSystem:
    bank = Relaxor(tau_s, lam).bank(rate_hz, "zoh" if hold == "zoh" else "linear")
    a, b0, b1, c, cplx = _real_layout(bank, zoh=hold == "zoh")
    A, g, cb0 = _inverse_matrix(a, b0, b1, c, cplx)
    w, vl, vr = linalg.eig(A, left=True, right=True)
    out = np.flatnonzero((np.abs(w) > _OUTSIDE) & (w.imag >= 0))
    lam_u = w[out]
    left = np.conj(vl[:, out]).T  # scipy: vl^H A = w vl^H  ->  left = conj(vl)
    right = vr[:, out].T
    for k in range(out.size):
        left[k] /= left[k] @ right[k]
    weight = np.where(np.abs(lam_u.imag) > 0, 2.0, 1.0)
    return _InverseSystem(a, b0, b1, c, cplx, g, cb0, lam_u, left, right, weight)


def _kernel_zeros_polished(h: Array, guesses: NDArray[np.complex128]) -> list[complex]:
    """Newton-polish the zeros of ``H(z) = sum h[n] z^-n`` (``|z| > 1``) from ``guesses``."""
    n = np.arange(h.size)
    out = []
    for z in guesses:
        z = complex(z)
        for _ in range(30):
            p = z ** (-n.astype(float))
            hz = np.sum(h * p)
            dh = np.sum(-n * h * p) / z
            if dh == 0:
                break
            step = hz / dh
            z -= step
            if abs(step) < 1e-15 * abs(z):
                break
        out.append(z)
    return out


def outside_zeros(tau_s: float, lam: float, rate_hz: float, hold: str) -> list[complex]:
    """Zeros outside the unit circle of the relaxor's sampled kernel for ``hold``.

    ``"zoh"``: the kernel shifted by the hold's one-sample delay (``k[1:]``), the one a drive
    with one sample of preview inverts; ``"linear"``: the kernel as it is. Found as the
    unstable eigenvalues of the modal bank's inverse recursion (one of each conjugate pair).
    ``[]`` for the relaxors of the seed's ``G_t``; one negative real zero for ``G_d`` with
    ``lam > 1`` under the linear hold.
    """
    return [complex(z) for z in _inverse_system(tau_s, lam, float(rate_hz), hold).lam]


def _deconvolve(h: Array, y: Array, zeros: list[complex]) -> Array:
    """``v`` with ``(h * v)[n] = y[n]`` for ``n >= 0``, ``y`` continued at its last value.

    Each zero ``zeta`` outside the unit circle is divided out of the kernel from its tail
    (``m[n] = -sum_j zeta^-j h[n+j]``) and inverted anti-causally on ``y``
    (``w[n] - zeta w[n-1] = y[n]``, solved backwards from the constant continuation
    ``w = y[-1] / (1 - zeta)``); the remaining minimum-phase kernel is inverted by its
    power-series reciprocal. ``h`` must be longer than ``y`` by enough samples for the tail
    division (``|zeta|^-extra`` negligible).
    """
    n = y.size
    m = h.astype(complex)
    w = y.astype(complex)
    for zeta in zeros:
        # kernel: m[k-1] = (m[k] - h[k]) / zeta, backwards from m[L-1] = 0
        rev = m[::-1]
        mm = signal.lfilter([0.0, -1.0 / zeta], [1.0, -1.0 / zeta], rev)
        m = mm[::-1]
        # signal: w[k-1] = (w[k] - y[k]) / zeta, from w[n-1] = y[-1] / (1 - zeta) (the bounded
        # solution for y continued at its last value); reversed: out[r] = (out[r-1] - rev[r-1])
        # / zeta, and with b[0] = 0 lfilter's out[0] is its initial state
        last = w[-1] / (1.0 - zeta)
        zi = np.array([last], dtype=complex)
        w = signal.lfilter([0.0, -1.0 / zeta], [1.0, -1.0 / zeta], w[::-1], zi=zi)[0][::-1]
    r = series_reciprocal(m[:n]) if not zeros else _series_reciprocal_complex(m[:n])
    v = signal.fftconvolve(w, r)[:n]
    return v.real.copy()


def _series_reciprocal_complex(h: NDArray[np.complex128]) -> NDArray[np.complex128]:
    if np.all(h.imag == 0):
        return series_reciprocal(h.real).astype(complex)
    return series_reciprocal(h)  # the same Newton iteration works in complex arithmetic


def _tail(zeros: list[complex]) -> int:
    """Extra kernel samples for the tail division: ``|zeta|^-extra < 1e-18``."""
    if not zeros:
        return 0
    rho = min(abs(z) for z in zeros)
    return math.ceil(18.0 * math.log(10.0) / math.log(rho)) + 8


def _relaxor_inverse(
    y: Array, tau_s: float, lam: float, rate_hz: float, hold: str
) -> tuple[Array, list[complex]]:
    """Offline inverse of one relaxor under ``hold`` (module docstring); ``y`` continues at its
    last value. ``"zoh"``: returns ``V`` (length ``y.size - 1``) with ``k * V = y`` at samples
    ``1..``; ``"linear"``: ``vt`` (same length) with ``k * vt = y``."""
    dt = 1.0 / rate_hz
    guesses = outside_zeros(tau_s, lam, rate_hz, hold)
    extra = _tail(guesses)
    if hold == "zoh":
        target = y[1:]
        h = sampled_kernel(tau_s, lam, dt, target.size + extra + 1, "zoh")[1:]
    else:
        target = y
        h = sampled_kernel(tau_s, lam, dt, target.size + extra, "linear")
    zeros = _kernel_zeros_polished(h[: max(64, min(h.size, 4096))], np.array(guesses))
    return _deconvolve(h, target, zeros), zeros


def compensated_drive(
    strain_ue: ArrayLike, params: ModelParams | ControlModel, rate_hz: float
) -> Array:
    """The drive ``V`` (V) whose model response follows ``strain_ue`` (offline, exact).

    ``V[n]`` is held on ``[t_n, t_{n+1})``; ``predict(V)[n] = strain_ue[n]`` (module docstring;
    ``strain_ue[0]`` should be 0, the actuator at rest). Uses the command's future (the
    anti-causal zero of ``G_d``) and continues it at its last value. With a
    :class:`ControlModel` holding creep, the command is first passed through the creep's
    inverse (causal and stable, :func:`labrig.model.effects.kelvin_voigt_filter`).
    """
    s = _command(strain_ue)
    rate_hz = float(rate_hz)
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate, got {rate_hz!r}")
    if s.size == 0:
        return s.copy()
    cm = as_control_model(params)
    p = cm.params
    n = s.size
    ba = cm.creep_filter(rate_hz)
    if ba is None:
        s = np.append(s, s[-1])  # one extra sample: V[N-1] reaches vt[N]
    else:
        # the *strain* command continues at its last value, so the uncrept one keeps moving:
        # uncreep it over the look-ahead the relaxor inverses use (as the per-sample form does)
        ahead = 1 + sum(
            _tail(outside_zeros(tau, lam, rate_hz, hold))
            for tau, lam, hold in ((p.tau_d_s, p.lam_d, "linear"), (p.tau_t_s, p.lam_t, "zoh"))
        )
        s = signal.lfilter(ba[1], ba[0], np.append(s, np.full(ahead, s[-1])))
    if cm.remanence is None:
        u = p.operator().invert(s)
    else:
        stepper = _static_stepper(cm)
        u = np.array([stepper.step(float(x)) for x in s])
    vt, _ = _relaxor_inverse(u, p.tau_d_s, p.lam_d, rate_hz, "linear")
    v, _ = _relaxor_inverse(vt, p.tau_t_s, p.lam_t, rate_hz, "zoh")
    return v[:n]


def compute_drive(
    strain_ue: ArrayLike,
    params: ModelParams | ControlModel,
    rate_hz: float,
    control: str = "compensated",
    limits: RigLimits | None = None,
    frequency_hz: float | None = None,
    on_infeasible: str = "raise",
) -> Array:
    """Drive voltage (V) for a strain command (ue) sampled at ``rate_hz``.

    ``control``: ``"compensated"`` (:func:`compensated_drive`) or ``"direct"``
    (:func:`direct_drive`). With ``limits`` the drive is checked (:func:`check_drive`;
    ``frequency_hz`` sets the averaging window of the mean current): ``on_infeasible="raise"``
    raises :class:`InfeasibleCommandError`; ``"clip"`` clips the voltage to the rig's range
    instead (the current is still checked on the clipped drive).
    """
    if control not in CONTROLS:
        raise ValueError(f"control must be one of {CONTROLS}, got {control!r}")
    if on_infeasible not in ("raise", "clip"):
        raise ValueError(f"on_infeasible must be 'raise' or 'clip', got {on_infeasible!r}")
    if control == "direct":
        v = direct_drive(strain_ue, params)
    else:
        v = compensated_drive(strain_ue, params, rate_hz)
    if limits is not None:
        if on_infeasible == "clip":
            v = np.clip(v, limits.v_min_V, limits.v_max_V)
        check_drive(v, rate_hz, limits, frequency_hz, what=f"the {control} drive")
    return v


def model_tracking_error(
    strain_ue: ArrayLike, params: ModelParams | ControlModel, rate_hz: float, method: str = "fast"
) -> Array:
    """``predict(compensated_drive(S)) - S`` (ue): how exactly the drive inverts the model
    (with a :class:`ControlModel`'s effects in the prediction, :meth:`ControlModel.predict`)."""
    s = _command(strain_ue)
    cm = as_control_model(params)
    return cm.predict(compensated_drive(s, cm, rate_hz), rate_hz, method) - s


# -- limits ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DriveCheck:
    """What :func:`check_drive` measured on a drive."""

    v_min_V: float
    v_max_V: float
    peak_current_A: float
    peak_time_s: float
    mean_current_A: float
    mean_time_s: float
    window_s: float


def check_drive(
    v: ArrayLike,
    rate_hz: float,
    limits: RigLimits,
    frequency_hz: float | None = None,
    what: str = "the drive",
) -> DriveCheck:
    """Check a drive against ``limits`` like the protocol preflight; raise
    :class:`InfeasibleCommandError` naming what is needed and what the rig gives."""
    v = np.asarray(v, dtype=np.float64)
    if v.size == 0:
        return DriveCheck(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    dt = 1.0 / rate_hz
    # the drive starts from rest at 0 V (the step to v[0] counts); bringing the output back to
    # 0 V afterwards is the player's business (the protocol adds an edge ramp at its slew)
    vv = np.concatenate(([0.0], v))
    fine = np.interp(
        np.arange((vv.size - 1) * _OVERSAMPLE + 1) / _OVERSAMPLE, np.arange(vv.size), vv
    )
    cur = np.abs(limits.current_A(fine, rate_hz * _OVERSAMPLE))
    k = int(np.argmax(cur))
    peak, peak_t = float(cur[k]), (k / _OVERSAMPLE - 1) * dt
    window_s = 1.0 / frequency_hz if frequency_hz else _AVG_WINDOW_S
    w = max(1, round(window_s * rate_hz * _OVERSAMPLE))
    cs = np.concatenate((np.zeros(w), np.cumsum(cur)))
    means = (cs[w:] - cs[:-w]) / w
    j = int(np.argmax(means))
    mean, mean_t = float(means[j]), (j / _OVERSAMPLE - 1) * dt
    vmin_i, vmax_i = int(np.argmin(v)), int(np.argmax(v))
    chk = DriveCheck(
        float(v[vmin_i]), float(v[vmax_i]), peak, peak_t, mean, mean_t, w / (rate_hz * _OVERSAMPLE)
    )
    tol = 1e-9
    if chk.v_max_V > limits.v_max_V + tol or chk.v_min_V < limits.v_min_V - tol:
        hi = chk.v_max_V > limits.v_max_V + tol
        bad, at = (chk.v_max_V, vmax_i) if hi else (chk.v_min_V, vmin_i)
        lim = limits.v_max_V if hi else limits.v_min_V
        raise InfeasibleCommandError(
            f"{what} needs {bad:.4g} V at t = {at * dt:.4g} s; the rig allows "
            f"{limits.v_min_V:g} to {limits.v_max_V:g} V (lower the strain amplitude"
            + (
                ", or its frequency: compensation goes below 0 V to cancel the drift)"
                if not hi
                else ")"
            ),
            "voltage",
            bad,
            lim,
            at * dt,
        )
    if not peak <= limits.i_peak_A * (1 + 1e-6):
        raise InfeasibleCommandError(
            f"{what} needs {peak:.3g} A peak at t = {peak_t:.4g} s; the amplifier gives "
            f"{limits.i_peak_A:g} A (C_eff dV/dt with C_eff = "
            f"{limits.effective_capacitance_F * 1e6:.3g} uF; lower the amplitude or frequency)",
            "peak_current",
            peak,
            limits.i_peak_A,
            peak_t,
        )
    if not mean <= limits.i_avg_A * (1 + 1e-6):
        raise InfeasibleCommandError(
            f"{what} draws {mean:.3g} A on average over {chk.window_s:.3g} s (around "
            f"t = {mean_t:.4g} s); the amplifier's average limit is {limits.i_avg_A:g} A "
            "(lower the amplitude or frequency)",
            "mean_current",
            mean,
            limits.i_avg_A,
            mean_t,
        )
    return chk


# -- per-sample controllers --------------------------------------------------------------------


class _StaticInverseStepper:
    """:meth:`QuasiStaticHysteresis.invert` one sample at a time (same memory rule: the
    remembered turning points ``(strain, voltage)`` as a stack, the current branch's on top)."""

    def __init__(self, op: QuasiStaticHysteresis):
        self.op = op
        self._exp = op._shape.name == "exponential" and op._shape.H is not None
        self._a0, self._g, self._vc = op.alpha0, op.gamma, op.vc
        self._wipe = op.memory == "return_point"
        self.reset()

    def reset(self) -> None:
        self._hint = 0.0  # the last branch inverse (a start for the next)
        self.stack: list[tuple[float, float]] = [(0.0, 0.0)]  # at rest
        self.s_last = 0.0
        self.u_last = 0.0
        self.direction = 0.0

    def _advance(self, s: float) -> tuple[list[tuple[float, float]], float]:
        """The stack and direction after the strain moves to ``s`` (copied when they change,
        so that :meth:`peek` leaves the state alone)."""
        st, sgn = self.stack, self.direction
        d = s - self.s_last
        if d == 0.0:
            return st, sgn
        sgn = 1.0 if d > 0 else -1.0
        if self.direction != 0.0 and sgn != self.direction:  # reversal at the last sample
            turn = (self.s_last, self.u_last)
            st = [*st, turn] if self._wipe else [turn]
        while self._wipe and len(st) >= 2 and sgn * (s - st[-2][0]) >= 0:
            st = st[:-2] if len(st) >= 3 else st[:-1]  # a minor loop closed: forget it
        return st, sgn

    def _finv(self, y: float) -> float:
        if y <= 0.0:
            return 0.0
        if not self._exp or self._g < 0:
            return float(self.op.branch_inverse(np.array([y]))[0])
        a0, g, vc = self._a0, self._g, self._vc
        # F(x) = (a0 + g) x - g vc (1 - exp(-x/vc)): increasing and convex, so Newton from any
        # x with F(x) >= y decreases monotonically onto the root, and one Newton step from below
        # lands above it. Start from the last root (consecutive calls ask for nearby values)
        x = self._hint
        e = math.exp(-x / vc)
        f = (a0 + g) * x - g * vc * (1.0 - e) - y
        if f < 0.0:
            x -= f / (a0 + g * (1.0 - e))
        for _ in range(60):
            e = math.exp(-x / vc)
            f = (a0 + g) * x - g * vc * (1.0 - e) - y
            x_new = x - f / (a0 + g * (1.0 - e))
            if x_new >= x:
                break
            # quadratic convergence: after a step below 1e-8 x the error is ~1e-3 step^2 / V
            # (F'' / 2F' <= g / (2 vc a0)), far below rounding
            done = x - x_new <= 1e-8 * x
            x = max(x_new, 0.0)
            if done:
                break
        self._hint = x
        return x

    def _voltage(self, s: float, anchor: tuple[float, float]) -> float:
        dd = s - anchor[0]
        return anchor[1] + math.copysign(self._finv(abs(dd)), dd)

    def peek(self, s: float) -> float:
        """The voltage :meth:`step` would return for ``s``, without advancing."""
        return self._voltage(s, self._advance(s)[0][-1])

    def step(self, s: float) -> float:
        self.stack, self.direction = self._advance(s)
        u = self._voltage(s, self.stack[-1])
        self.s_last, self.u_last = s, u
        return u


class _RemanentInverseStepper:
    """Per-sample inverse of ``H[u] - h[u] = s`` (operator and Bouc-Wen remanence, both with
    memory): ``u = H^-1(s + h(u))``, solved for the sample's ``h`` (a contraction: the element's
    steepest slope is below the operator's shallowest, :class:`ControlModel` checks it) by secant
    steps."""

    def __init__(self, static: _StaticInverseStepper, A: float, beta: float, gamma: float):
        self.static, self.bw = static, (A, beta, gamma)
        self.reset()

    def reset(self) -> None:
        self.static.reset()
        self.h = 0.0
        self.u_last = 0.0

    def _g(self, s: float, h: float) -> float:
        """The sample's ``h`` if the operator were inverted at ``s + h``."""
        return bouc_wen_step(self.h, self.static.peek(s + h) - self.u_last, *self.bw)

    def step(self, s: float) -> float:
        # secant on r(h) = g(h) - h from the fixed-point step (r is smooth with slope in
        # (-1, 0) where the sample's direction holds: a few evaluations reach 1e-12)
        h0 = self.h
        r0 = self._g(s, h0) - h0
        h = h0 + r0
        for _ in range(_FIXED_POINT_ITER):
            r = self._g(s, h) - h
            if abs(r) <= 1e-12 * (1.0 + abs(h)):
                break
            d = r - r0
            h_next = h - r * (h - h0) / d if d != 0.0 else h + r
            h0, r0, h = h, r, h_next
        u = self.static.step(s + h)
        self.h = bouc_wen_step(self.h, u - self.u_last, *self.bw)
        self.u_last = u
        return u


def _static_stepper(cm: ControlModel) -> _StaticInverseStepper | _RemanentInverseStepper:
    """The per-sample inverse of the quasi-static part of ``cm`` (with its remanence)."""
    static = _StaticInverseStepper(cm.params.operator())
    return static if cm.remanence is None else _RemanentInverseStepper(static, *cm.remanence)


class _BankInverse:
    """Per-sample inverse of a relaxor bank with anti-causal handling of its outside zeros.

    The bank's inverse recursion in real coordinates ``z = [Re x, Im x (complex modes), v]``
    is ``z[n] = A z[n-1] + B y[n]``, output ``v[n]``. For each unstable eigenvalue ``lam`` (left
    and right eigenvectors ``l``, ``r``, ``l . r = 1``) the component ``xi = l . z`` obeys
    ``xi[n] = lam xi[n-1] + (l . B) y[n]`` and is taken as its bounded (anti-causal) solution
    ``xi[n] = -sum_{m>=1} lam^-m (l . B) y[n+m]``, truncated at ``preview`` terms; the rest,
    ``z_s = z - sum r xi``, runs forward with the projected input ``P B`` and is re-projected
    each sample (rounding would otherwise grow like ``lam^n``). Starting from rest, the first
    target samples get the defect that zeroes every ``xi`` before ``t_0`` (as the offline
    inverse does). Feed the wanted output with :meth:`push`; once ``preview`` samples are ahead,
    each push returns the input for the sample ``preview`` earlier. For ``"zoh"`` the wanted
    output is ``y[n] = vt[n+1]`` (the shifted bank).

    Arithmetic: real modes in float arrays, complex modes (the pole pair of ``lam > 1``) in a
    small complex array; real unstable eigenvalues (the only kind the relaxors produce) use
    real eigenvectors, a conjugate pair is carried as one complex direction with weight 2.
    """

    def __init__(self, tau_s: float, lam: float, rate_hz: float, hold: str, tol: float):
        sysm = _inverse_system(tau_s, lam, float(rate_hz), hold)
        self.sys = sysm
        a, b0, b1, c, cplx = sysm.a, sysm.b0, sysm.b1, sysm.c, sysm.cplx
        m = a.size
        ci = np.flatnonzero(cplx)
        ri = np.flatnonzero(~cplx)
        self.g, self.cb0 = sysm.gain, sysm.cb0
        # real modes
        self._ar = np.ascontiguousarray(a[ri].real)
        self._car = np.ascontiguousarray((c[ri] * a[ri]).real)
        # complex modes (y = Re(c x): their contribution is Re(c a x))
        self._acl = [complex(x) for x in a[ci]]
        self._cacl = [complex(x) for x in c[ci] * a[ci]]
        self._b0cl = [complex(x) for x in b0[ci]]
        self._b1cl = [complex(x) for x in b1[ci]]
        B = np.zeros(m + ci.size + 1)
        B[:m] = b1.real / self.g
        B[m : m + ci.size] = b1.imag[ci] / self.g
        B[-1] = 1.0 / self.g
        rho = min((abs(z) for z in sysm.lam), default=math.inf)
        self.preview = math.ceil(math.log(1.0 / tol) / math.log(rho)) if sysm.lam.size else 0
        PB = B.copy()
        self._proj = []
        self._fir = []
        steps = np.arange(1, self.preview + 1, dtype=float)
        for k in range(sysm.lam.size):
            lv, rv, wt = sysm.left[k].copy(), sysm.right[k].copy(), float(sysm.weight[k])
            if wt == 1.0:  # real eigenvalue: make both eigenvectors real
                rv = rv * np.conj(rv[np.argmax(np.abs(rv))])
                lv = lv * np.conj(lv[np.argmax(np.abs(lv))])
                rv, lv = rv.real, lv.real
                lv = lv / (lv @ rv)
            beta = lv @ B
            PB = PB - wt * np.real(rv * beta)
            lim = np.zeros(m, dtype=lv.dtype)
            lim[ci] = lv[m : m + ci.size]
            rim = np.zeros(m, dtype=rv.dtype)
            rim[ci] = rv[m : m + ci.size]
            self._proj.append(
                (
                    np.ascontiguousarray(lv[ri]),
                    list(lv[ci]),
                    list(lim[ci]),
                    lv[-1],
                    np.ascontiguousarray(rv[ri]),
                    list(rv[ci]),
                    list(rim[ci]),
                    rv[-1],
                    wt,
                )
            )
            fir = -(sysm.lam[k] ** -steps) * beta
            self._fir.append((fir.real if wt == 1.0 else fir, rv[-1], wt))
        pbx = PB[:m]
        # stacked input vectors: x += [v_prev, w, y] @ rows
        self._inr = np.ascontiguousarray(np.stack([b0[ri].real, b1[ri].real, pbx[ri]]))
        self._pbcl = [complex(x) for x in pbx[ci] + 1j * PB[m : m + ci.size]]
        self._pbv = float(PB[-1])
        # start from rest: defect on the first q target samples (sum_m lam^-(m+1) y[m] = 0)
        lams = [*sysm.lam, *(np.conj(z) for z in sysm.lam if z.imag != 0)]
        self._q = len(lams)
        if self._q:
            jj = np.arange(self._q, dtype=float)
            allm = np.arange(self.preview + 1, dtype=float)
            self._defect_mat = np.array([lk ** -(jj + 1) for lk in lams])
            self._defect_rhs = np.array([-(lk ** -(allm + 1)) for lk in lams])
        self.reset()

    @property
    def n_modes(self) -> int:
        return self._ar.size + len(self._acl)

    def reset(self) -> None:
        self.xr = np.zeros(self._ar.size)
        self.xc = [0j] * len(self._acl)
        self.v = 0.0
        n = self.preview + 1
        self._ring = np.zeros(2 * n)  # each sample twice: the window is one contiguous slice
        self._pos = n - 1  # where the newest sample went
        self._count = 0
        self._started = False
        self._since = 0

    def _stable(self, y: float) -> float:
        """Stable part: ``z_s[n] = A z_s[n-1] + P B y[n]``; returns ``v_s[n]``."""
        v0 = self.v
        pred = float(np.dot(self._car, self.xr)) + self.cb0 * v0
        xc = self.xc
        for cac, x in zip(self._cacl, xc, strict=True):
            pred += (cac * x).real
        w = -pred / self.g
        xr = self._ar * self.xr
        xr += np.dot((v0, w, y), self._inr)
        if xc:
            xc = [
                a * x + b0 * v0 + b1 * w + pb * y
                for a, x, b0, b1, pb in zip(
                    self._acl, xc, self._b0cl, self._b1cl, self._pbcl, strict=True
                )
            ]
        v = w + self._pbv * y
        self._since += 1
        if self._proj and self._since >= _REPROJECT:
            # remove the unstable components rounding has put into z_s (they grow like lam^n)
            self._since = 0
            for l_r, l_cre, l_cim, l_v, r_r, r_cre, r_cim, r_v, wt in self._proj:
                q = np.dot(l_r, xr) + l_v * v
                for lre, lim, x in zip(l_cre, l_cim, xc, strict=True):
                    q += lre * x.real + lim * x.imag
                if wt == 1.0:
                    xr -= r_r * q
                    xc = [
                        x - complex(rre * q, rim * q)
                        for x, rre, rim in zip(xc, r_cre, r_cim, strict=True)
                    ]
                    v -= r_v * q
                else:
                    xr -= wt * np.real(r_r * q)
                    xc = [
                        x - wt * complex((rre * q).real, (rim * q).real)
                        for x, rre, rim in zip(xc, r_cre, r_cim, strict=True)
                    ]
                    v -= wt * float(np.real(r_v * q))
        self.xr, self.xc, self.v = xr, xc, float(v)
        return self.v

    def push(self, y: float) -> float | None:
        n = self.preview + 1
        pos = self._pos + 1
        if pos == n:
            pos = 0
        self._pos = pos
        self._ring[pos] = self._ring[pos + n] = y
        self._count += 1
        if self._count < n:
            return None
        window = self._ring[pos + 1 : pos + 1 + n]  # y[k - P .. k], oldest first
        if self._q and not self._started:
            self._started = True
            d = np.linalg.solve(self._defect_mat, self._defect_rhs @ window).real
            for j in range(self._q):
                i = (pos + 1 + j) % n
                self._ring[i] += d[j]
                self._ring[i + n] = self._ring[i]
        v = self._stable(float(window[0]))
        if self._fir:
            ahead = window[1:]
            for fir, r_v, wt in self._fir:
                xi = np.dot(fir, ahead)
                v += float(r_v * xi) if wt == 1.0 else float(wt * np.real(r_v * xi))
        return float(v)


class CompensationController:
    """The compensated drive one sample at a time (O(modes + preview) per sample, no history).

    ``step(s)`` takes the command ``preview`` samples ahead of the drive it returns::

        ctl = CompensationController(params, rate_hz)
        ctl.prime(s_com[: ctl.preview])               # the first preview command samples
        for n in range(N):                            # the real-time loop
            v[n] = ctl.step(s_com[min(n + ctl.preview, N - 1)])

    ``preview = P_d + 1 + P_t``: one sample for the zero-order hold of ``G_t`` plus the
    anti-causal windows of the relaxors' outside zeros (``P_d`` for a sampled ``G_d`` with a zero
    outside the unit circle: some ``lam_d > 1`` at some rates, e.g. 209 samples at 10 kHz for
    experiments/hybrid-params.json, none at 1 kHz; 0 otherwise), cut where the weights fall below
    ``tol``. :meth:`run` does the whole loop and agrees with :func:`compensated_drive` to the
    modal banks' quadrature error plus ``tol`` (measured: 3e-7 V on drives of 90 V). With
    ``limits`` the
    output is clipped to the rig's voltage range and ``n_clipped`` counts the clipped samples
    (the controller runs open loop: its model state does not see the clipping).
    """

    def __init__(
        self,
        params: ModelParams | ControlModel,
        rate_hz: float,
        limits: RigLimits | None = None,
        tol: float = PREVIEW_TOL,
    ):
        cm = as_control_model(params)
        p = cm.params
        self.params, self.rate_hz, self.limits = p, float(rate_hz), limits
        ba = cm.creep_filter(self.rate_hz)
        # inverse creep filter a(z)/b(z): one state (the previous input and output)
        self._creep = None if ba is None else (ba[1], ba[0])
        self._static = _static_stepper(cm)
        self._gd = _BankInverse(p.tau_d_s, p.lam_d, self.rate_hz, "linear", tol)
        self._gt = _BankInverse(p.tau_t_s, p.lam_t, self.rate_hz, "zoh", tol)
        self.preview = self._gd.preview + 1 + self._gt.preview
        self.reset()

    def reset(self) -> None:
        """Back to rest: 0 V, zero strain, no command seen."""
        self._static.reset()
        self._gd.reset()
        self._gt.reset()
        self._creep_x = self._creep_y = 0.0
        self._vt_seen = 0
        self._pushed = 0
        self.n_clipped = 0

    def prime(self, first: ArrayLike) -> None:
        """Feed the first ``preview`` command samples (no drive is due yet)."""
        for s in np.asarray(first, dtype=float).ravel():
            if self._push(float(s)) is not None:  # pragma: no cover - guarded by preview
                raise RuntimeError("prime() got more than preview samples")

    def _uncreep(self, s: float) -> float:
        if self._creep is None:
            return s
        (n0, n1), (d0, d1) = self._creep
        y = (n0 * s + n1 * self._creep_x - d1 * self._creep_y) / d0
        self._creep_x, self._creep_y = s, y
        return y

    def _push(self, s: float) -> float | None:
        self._pushed += 1
        vt = self._gd.push(self._static.step(self._uncreep(s)))
        if vt is None:
            return None
        self._vt_seen += 1
        if self._vt_seen == 1:  # vt[0] = 0 at rest: V[0] aims at vt[1]
            return None
        return self._gt.push(vt)

    def step(self, s_ahead: float) -> float:
        """Take the command sample ``preview`` ahead; return the drive (V) due now."""
        v = self._push(float(s_ahead))
        if v is None:
            raise RuntimeError(f"call prime() with the first {self.preview} command samples first")
        if self.limits is not None:
            c = min(max(v, self.limits.v_min_V), self.limits.v_max_V)
            if c != v:
                self.n_clipped += 1
            v = c
        return v

    def run(self, strain_ue: ArrayLike) -> Array:
        """The drive for a whole command, sample by sample (from rest; the command continues
        at its last value for the look-ahead)."""
        s = _command(strain_ue)
        self.reset()
        n = s.size
        if n == 0:
            return s.copy()
        ext = np.concatenate((s, np.full(self.preview, s[-1])))
        self.prime(ext[: self.preview])
        return np.array([self.step(ext[k + self.preview]) for k in range(n)])


class DirectController:
    """``V = S_com / alpha0`` one sample at a time, with the timing of :func:`direct_drive`
    (one sample of preview: ``V[n] = (S[n] + S[n+1]) / (2 alpha0)``)."""

    preview = 1

    def __init__(
        self, params: ModelParams | ControlModel, rate_hz: float, limits: RigLimits | None = None
    ):
        self.alpha0 = as_control_model(params).params.alpha0_ue_per_V
        self.rate_hz, self.limits = float(rate_hz), limits
        self.reset()

    def reset(self) -> None:
        self._prev: float | None = None
        self.n_clipped = 0

    def prime(self, first: ArrayLike) -> None:
        vals = np.asarray(first, dtype=float).ravel()
        if vals.size:
            self._prev = float(vals[-1])

    def step(self, s_ahead: float) -> float:
        if self._prev is None:
            raise RuntimeError("call prime() with the first command sample first")
        v = 0.5 * (self._prev + float(s_ahead)) / self.alpha0
        self._prev = float(s_ahead)
        if self.limits is not None:
            c = min(max(v, self.limits.v_min_V), self.limits.v_max_V)
            self.n_clipped += c != v
            v = c
        return v

    def run(self, strain_ue: ArrayLike) -> Array:
        s = _command(strain_ue)
        self.reset()
        if s.size == 0:
            return s.copy()
        self.prime(s[:1])
        ext = np.append(s, s[-1])
        return np.array([self.step(ext[k + 1]) for k in range(s.size)])


# -- metrics of strain-command entries -----------------------------------------------------------


def _pair(command: ArrayLike, measured: ArrayLike) -> tuple[Array, Array]:
    c = np.asarray(command, dtype=float).ravel()
    m = np.asarray(measured, dtype=float).ravel()
    if c.shape != m.shape or c.size == 0:
        raise ValueError(f"command {c.shape} and measured {m.shape} must match and be non-empty")
    return c, m


def tracking_nrmse_pct(command: ArrayLike, measured: ArrayLike) -> float:
    """``100 RMS(measured - command) / (max command - min command)`` (percent)."""
    c, m = _pair(command, measured)
    span = float(np.ptp(c))
    if not span > 0:
        raise ValueError("tracking NRMSE is undefined for a constant command")
    return 100.0 * float(np.sqrt(np.mean((m - c) ** 2))) / span


def _last_period(c: Array, m: Array, rate_hz: float, frequency_hz: float) -> tuple[Array, Array]:
    p = round(rate_hz / frequency_hz)
    if p < 4 or c.size < p:
        raise ValueError("no full command period in the record (frequency or length)")
    return c[-p:], m[-p:]


def hysteresis_width_pct(
    command: ArrayLike, measured: ArrayLike, rate_hz: float, frequency_hz: float
) -> float:
    """Largest falling-minus-rising strain gap at equal command over the last period, in % of
    the command span (signed; positive when the falling branch lies above the rising one)."""
    c, m = _last_period(*_pair(command, measured), rate_hz, frequency_hz)
    span = float(np.ptp(c))
    if not span > 0:
        raise ValueError("hysteresis width is undefined for a constant command")
    i_lo, i_hi = int(np.argmin(c)), int(np.argmax(c))
    p = c.size
    rise = (i_lo + np.arange((i_hi - i_lo) % p + 1)) % p
    fall = (i_hi + np.arange((i_lo - i_hi) % p + 1)) % p
    grid = c[i_lo] + span * np.linspace(0.05, 0.95, 101)

    def branch(idx: NDArray) -> Array:
        order = np.argsort(c[idx], kind="stable")
        return np.interp(grid, c[idx][order], m[idx][order])

    gap = branch(fall) - branch(rise)
    return 100.0 * float(gap[np.argmax(np.abs(gap))]) / span


def zero_command_strain_ue(
    command: ArrayLike, measured: ArrayLike, rate_hz: float, frequency_hz: float
) -> float:
    """Measured strain (ue) where the command is at its minimum (0 for a unipolar sine), over
    the last period: ``min command + mean(measured - command)`` over the samples whose command
    is within 1 % of the command span of its minimum (about 30 samples around each minimum at
    1 Hz and 1 kHz, 3 at 40 Hz: a few gauge-noise samples are averaged, and the tracking error
    barely changes over 1 % of the stroke)."""
    c, m = _last_period(*_pair(command, measured), rate_hz, frequency_hz)
    lo = float(np.min(c))
    near = c <= lo + _ZERO_BAND * float(np.ptp(c))
    return float(np.mean(m[near] - c[near])) + lo


def final_strain_ue(
    measured: ArrayLike, rate_hz: float, window_s: float = 1.0
) -> tuple[float, float]:
    """Mean measured strain over the last ``window_s`` and its standard error (ue):
    ``std / sqrt(n)`` (white noise). For "the strain returns to zero as the command ends"."""
    m = np.asarray(measured, dtype=float).ravel()
    n = max(2, min(m.size, round(window_s * rate_hz)))
    tail = m[-n:]
    return float(np.mean(tail)), float(np.std(tail, ddof=1) / math.sqrt(tail.size))


def control_metrics(
    command: ArrayLike,
    measured: ArrayLike,
    rate_hz: float,
    frequency_hz: float | None = None,
    periodic: bool = True,
) -> dict[str, Any]:
    """All metrics of one strain-command entry (the command part of it): keys
    ``tracking_nrmse_pct``, ``hysteresis_width_pct`` (``abs`` of the signed width),
    ``zero_command_strain_ue`` (``None`` unless ``periodic`` and ``frequency_hz``), and
    ``final_strain_ue`` / ``final_strain_se_ue`` (last second)."""
    c, m = _pair(command, measured)
    out: dict[str, Any] = {"tracking_nrmse_pct": tracking_nrmse_pct(c, m)}
    if periodic and frequency_hz:
        out["hysteresis_width_pct"] = abs(hysteresis_width_pct(c, m, rate_hz, frequency_hz))
        out["zero_command_strain_ue"] = zero_command_strain_ue(c, m, rate_hz, frequency_hz)
    else:
        out["hysteresis_width_pct"] = None
        out["zero_command_strain_ue"] = None
    out["final_strain_ue"], out["final_strain_se_ue"] = final_strain_ue(m, rate_hz)
    return out


def entry_metrics(record: Any) -> dict[str, Any]:
    """Metrics of one recorded strain-command entry (a :class:`labrig.analysis.records.Record`
    from :func:`labrig.analysis.load.records_from_run`), over its command samples only
    (``meta["command_start_index"]:meta["command_stop_index"]``, leaving out the 0 V sample
    before and the ramp to 0 V after). Keys: ``control``, ``frequency_hz``, ``kind``,
    ``amplitude_ue`` and those of :func:`control_metrics` (``hysteresis_width_pct`` and
    ``zero_command_strain_ue`` for ``strain_sine`` entries only, else ``None``). Raises
    ``ValueError`` for an entry without a ``command_strain`` channel."""
    meta = record.meta
    if "command_strain" not in record.aux or "control" not in meta:
        raise ValueError(f"entry {record.name!r} is not a strain-command entry")
    i0 = int(meta.get("command_start_index", 0))
    i1 = int(meta.get("command_stop_index", record.strain_ue.size))
    c = record.aux["command_strain"][i0:i1]
    m = record.strain_ue[i0:i1]
    f = meta.get("frequency_hz")
    periodic = meta.get("kind") == "strain_sine" and bool(f)
    out = {
        "control": meta["control"],
        "kind": meta.get("kind"),
        "frequency_hz": f,
        "amplitude_ue": meta.get("amplitude_ue"),
    }
    out.update(control_metrics(c, m, record.rate_hz, f, periodic=periodic))
    return out
