"""The dynamic hysteresis model of the paper's Fig. 2 (Eq. 5-7).

    V*(s) = G_t(s) G_d(s) V(s),      S = alpha0 V* + H[V*]

``V`` is the driving voltage (V) sampled at ``rate_hz``, ``S`` the strain (ue). ``G_t`` is applied
with the input hold of the record (``"zoh"`` for a DAQ-driven voltage, the default; ``"linear"``
for a measured, smooth voltage), ``G_d`` with the linear hold since its input is ``G_t``'s
continuous output known at the samples (see :mod:`labrig.model.relaxor`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.model.hysteresis import HysteresisState, QuasiStaticHysteresis
from labrig.model.modal import DiscreteBank, compact_form, run_bank
from labrig.model.params import ModelParams
from labrig.model.relaxor import Relaxor


@dataclass(frozen=True)
class DynamicHysteresisModel:
    """``predict(v, rate_hz)``: strain (ue) for a voltage record (V), system at rest at 0 V (or
    held at ``rest_V``).

    Parameters
    ----------
    params : ModelParams
        The model's parameters; the relaxors ``g_t``, ``g_d`` and the quasi-static ``operator``
        are made from them.

    Examples
    --------
    >>> import numpy as np
    >>> from labrig.model import PAPER_TABLE1
    >>> model = DynamicHysteresisModel(PAPER_TABLE1)
    >>> model.predict(np.zeros(3), 1000.0)
    array([0., 0., 0.])
    """

    params: ModelParams
    g_t: Relaxor = field(init=False)
    g_d: Relaxor = field(init=False)
    operator: QuasiStaticHysteresis = field(init=False)

    def __post_init__(self) -> None:
        p = self.params
        object.__setattr__(self, "g_t", Relaxor(p.tau_t_s, p.lam_t))
        object.__setattr__(self, "g_d", Relaxor(p.tau_d_s, p.lam_d))
        object.__setattr__(self, "operator", p.operator())

    def equivalent_static_voltage(
        self,
        v: ArrayLike,
        rate_hz: float,
        method: str = "fast",
        hold: str = "zoh",
        rest_V: float = 0.0,
    ) -> NDArray[np.float64]:
        """``V* = G_d G_t V`` (V), the paper's Eq. 7, the relaxors at rest at ``rest_V`` before
        the record (``G(0) = 1``, so ``V* = rest_V + G_d G_t (V - rest_V)``).

        Parameters
        ----------
        v : array_like
            The voltage record (V).
        rate_hz : float
            Sample rate (Hz).
        method : {"fast", "exact"}
            The relaxors' realisation (:meth:`Relaxor.filter`).
        hold : {"zoh", "linear"}
            How ``v`` behaves between samples.
        rest_V : float
            The voltage held before the record (V).

        Returns
        -------
        numpy.ndarray
            ``V*`` (V) at each sample.
        """
        if rest_V == 0.0:
            vt = self.g_t.filter(v, rate_hz, method=method, hold=hold)
            return self.g_d.filter(vt, rate_hz, method=method, hold="linear")
        u = np.asarray(v, dtype=float) - rest_V
        vt = self.g_t.filter(u, rate_hz, method=method, hold=hold)
        return rest_V + self.g_d.filter(vt, rate_hz, method=method, hold="linear")

    def predict(
        self,
        v: ArrayLike,
        rate_hz: float,
        method: str = "fast",
        hold: str = "zoh",
        rest_V: float = 0.0,
    ) -> NDArray[np.float64]:
        """Strain (ue) for the voltage record ``v`` (V) sampled at ``rate_hz``, the actuator held
        at ``rest_V`` before it (brought there from rest at 0 V, its relaxors settled:
        :meth:`~labrig.model.QuasiStaticHysteresis.held_state`).

        Parameters
        ----------
        v : array_like
            The voltage record (V).
        rate_hz : float
            Sample rate (Hz).
        method : {"fast", "exact"}
            The relaxors' realisation (``fast``: the modal banks, compiled when numba is there).
        hold : {"zoh", "linear"}
            How ``v`` behaves between samples.
        rest_V : float
            The voltage held before the record (V).

        Returns
        -------
        numpy.ndarray
            Strain (ue) at each sample.
        """
        op = self.operator
        kern = op._kernels("auto") if method == "fast" else None
        if kern is None:  # the exact method, a user shape, or no numba
            x = self.equivalent_static_voltage(v, rate_hz, method, hold, rest_V)
            return op.apply(x, op.held_state(rest_V))
        v = np.ascontiguousarray(v, dtype=np.float64)
        if v.ndim != 1:
            raise ValueError("v must be a 1-D record")
        bt, bd = self.g_t.bank(rate_hz, hold), self.g_d.bank(rate_hz, "linear")
        if not np.all(np.isfinite(v)):
            raise ValueError("the voltage record must be finite (found NaN or infinity)")
        if v.size == 0:
            return np.zeros(0)
        held = op.held_state(rest_V)
        out = kern.model_run(
            v, float(rest_V), _fresh(bt), _fresh(bd), np.zeros(2), np.zeros(1), np.zeros(1),
            held.u_last, held.direction, op._wipe, op._code, float(op.alpha0), float(op.gamma),
            float(op.vc), np.empty(v.size),
        )[0]  # fmt: skip
        return out

    def stream(self, rate_hz: float, hold: str = "zoh", engine: str = "auto") -> ModelStream:
        """A stateful evaluator for records that arrive in blocks (simulators, control loops).

        Parameters
        ----------
        rate_hz : float
            Sample rate (Hz).
        hold : {"zoh", "linear"}
            How the voltage behaves between samples.
        engine : {"auto", "compiled", "numpy"}
            Which code runs (:meth:`QuasiStaticHysteresis.apply`; ``"numpy"`` never loads numba).

        Returns
        -------
        ModelStream
            At rest at 0 V.
        """
        return ModelStream(self, rate_hz, hold, engine)


def _fresh(bank: DiscreteBank) -> tuple:
    """A bank in the compiled kernels' compact form (:func:`~labrig.model.modal.compact_form`)
    with zero (rest) states."""
    key = ("compact", None)
    if key not in bank._cache:
        bank._cache[key] = compact_form(bank)
    a, cw, feed, ca, ccw = bank._cache[key]
    return a, cw, feed, ca, ccw, np.zeros(a.size), np.zeros(ca.size, dtype=np.complex128)


class ModelStream:
    """Block-by-block evaluation of :class:`DynamicHysteresisModel` (the fast realisation).

    Feeding a record in any split gives the same result as ``predict(..., method="fast")``:
    with numba, the banks' states stay in the compiled kernels' form between blocks
    (:func:`~labrig.model.compiled.model_run`); without, the numpy code carries them.

    Parameters
    ----------
    model : DynamicHysteresisModel
        The model evaluated.
    rate_hz : float
        Sample rate (Hz).
    hold : {"zoh", "linear"}
        How the voltage behaves between samples.
    engine : {"auto", "compiled", "numpy"}
        Which code runs: ``"auto"`` compiled when numba is available; ``"numpy"`` never loads
        numba (the simulated rig's choice, :func:`labrig.model.accel.stream_engine`).

    Examples
    --------
    >>> import numpy as np
    >>> from labrig.model import PAPER_TABLE1
    >>> model = DynamicHysteresisModel(PAPER_TABLE1)
    >>> v = 50.0 * np.sin(np.linspace(0.0, 6.0, 400))
    >>> stream = model.stream(1000.0)
    >>> y = np.concatenate([stream.process(v[:150]), stream.process(v[150:])])
    >>> bool(np.allclose(y, model.predict(v, 1000.0), rtol=0, atol=1e-9))
    True
    """

    def __init__(
        self, model: DynamicHysteresisModel, rate_hz: float, hold: str = "zoh", engine: str = "auto"
    ):
        self.model = model
        self._bank_t = model.g_t.bank(rate_hz, hold)
        self._bank_d = model.g_d.bank(rate_hz, "linear")
        self._kern = model.operator._kernels(engine)
        # the banks' engine when the operator runs its numpy code: a user shape (no compiled
        # operator) keeps the compiled banks unless "numpy" was asked for
        self._bank_engine = "numpy" if engine == "numpy" else "auto"
        self.reset()

    def reset(self) -> None:
        """Back to rest at 0 V (the relaxors' states and the operator's memory)."""
        self._xt = self._bank_t.initial_state()
        self._xd = self._bank_d.initial_state()
        self._v_prev = 0.0
        self._vt_prev = 0.0
        self._hyst = HysteresisState()
        if self._kern is not None:
            self._bt, self._bd = _fresh(self._bank_t), _fresh(self._bank_d)
            self._ups = np.zeros(2)

    def process(self, v_block: ArrayLike) -> NDArray[np.float64]:
        """Strain for the next block of the record; the state carries on to the next call.

        Parameters
        ----------
        v_block : array_like
            The next samples of the voltage record (V).

        Returns
        -------
        numpy.ndarray
            Strain (ue) at those samples.
        """
        v = np.ascontiguousarray(v_block, dtype=np.float64)
        if v.size == 0:
            return np.zeros(0)
        if not np.all(np.isfinite(v)):  # before any state moves
            raise ValueError("the voltage record must be finite (found NaN or infinity)")
        if self._kern is None:
            eng = self._bank_engine
            vt, self._xt = run_bank(self._bank_t, v, self._xt, self._v_prev, engine=eng)
            vd, self._xd = run_bank(self._bank_d, vt, self._xd, self._vt_prev, engine=eng)
            self._v_prev, self._vt_prev = float(v[-1]), float(vt[-1])
            return self.model.operator.apply(vd, self._hyst, engine="numpy")
        op, st = self.model.operator, self._hyst
        xs = np.array([p[0] for p in st.older] + [st.u_s], dtype=np.float64)
        ys = np.array([p[1] for p in st.older] + [st.s_s], dtype=np.float64)
        out, xs, ys, d, last = self._kern.model_run(
            v, 0.0, self._bt, self._bd, self._ups, xs, ys, float(st.u_last), float(st.direction),
            op._wipe, op._code, float(op.alpha0), float(op.gamma), float(op.vc), np.empty(v.size),
        )  # fmt: skip
        pts = list(zip(xs.tolist(), ys.tolist(), strict=True))
        st.older, (st.u_s, st.s_s), st.direction = pts[:-1], pts[-1], float(d)
        st.u_last, st.s_last = float(last), float(out[-1])
        return out
