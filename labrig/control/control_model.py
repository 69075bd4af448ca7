"""What the controller inverts (:class:`ControlModel`), read from a ``labrig fit --out`` file.

A control model is the dynamic model (:class:`~labrig.model.ModelParams`) and, optionally, the
actuator effects fitted with it that the controller inverts (:data:`INVERTIBLE_EFFECTS`, the
effects the registry marks invertible, :mod:`labrig.model.effects.registry`; each has its field
in :class:`ControlModel`):

    S = KV[alpha0 V* + H[V*] - h[V*]],      V* = G_d G_t V

``KV`` the Kelvin-Voigt creep (``c``, ``tau_s``), ``h`` the Bouc-Wen remanence (``A`` ue/V,
``beta`` and ``gamma`` 1/V). :func:`load_params` reads the model alone, :func:`load_control_model`
the model with its effects; both raise ``ValueError`` naming the file and the problem (the
controller's reader: ``labrig report`` and ``diagnose`` read the same files with
:mod:`labrig.analysis.params_file`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.core.jsonsafe import MAX_JSON_BYTES, loads_bounded
from labrig.core.textfile import read_text_bounded
from labrig.model import DynamicHysteresisModel, ModelParams
from labrig.model.bouc_wen import bouc_wen_exact, max_slope
from labrig.model.effects import INVERTIBLE_EFFECTS, kelvin_voigt_filter, library


def _scipy_signal():
    """``scipy.signal``, imported on first use: it costs about a second of CPU to import (it
    loads scipy.stats), which the fast paths never need."""
    from scipy import signal

    return signal


__all__ = [
    "INVERTIBLE_EFFECTS",
    "ControlModel",
    "as_control_model",
    "load_control_model",
    "load_params",
]

Array = NDArray[np.float64]


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
        return y if ba is None else _scipy_signal().lfilter(ba[0], ba[1], y)

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
        return loads_bounded(read_text_bounded(p, MAX_JSON_BYTES))
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
