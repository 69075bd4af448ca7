"""Compensation control: the drive voltage that makes the model follow a strain command.

The model (the paper's Eq. 12, :class:`~labrig.model.DynamicHysteresisModel`) is

    S = alpha0 V* + H[V*],      V* = G_d G_t V

and the drive that makes it follow a strain command ``S_com`` (ue) is (the paper's Eq. 13)

    V = G_t^-1 G_d^-1 u,        u solves  alpha0 u + H[u] = S_com

("direct" control, the paper's baseline: ``V = S_com / alpha0``). Modules, in the order the data
flows through them:

- :mod:`~labrig.control.control_model`: the parameter file of ``labrig fit --out`` as a
  :class:`ControlModel` (the model and the creep and remanence fitted with it);
- :mod:`~labrig.control.inversion`: the offline drive of a whole command
  (:func:`compute_drive`, :func:`compensated_drive`, :func:`direct_drive`), the exact inverse of the
  model as :meth:`DynamicHysteresisModel.predict` discretises it;
- :mod:`~labrig.control.inverse_system`, :mod:`~labrig.control.static_inverse`,
  :mod:`~labrig.control.bank_inverse`: the pieces of that inverse (the relaxor banks' inverse
  recursions and their outside zeros, the quasi-static inverse per sample, the per-sample bank
  inverse);
- :mod:`~labrig.control.controllers`: the same drive one sample at a time
  (:class:`CompensationController`, :class:`DirectController`);
- :mod:`~labrig.control.drive_check`: whether a drive is within the rig's voltage and current
  limits (:func:`check_drive`, :class:`InfeasibleCommandError`);
- :mod:`~labrig.control.metrics`: how well a measured strain followed its command.

docs/control.md describes the method with its measured accuracy and cost
(benchmarks/bench_control.py, benchmarks/RESULTS.md).
"""

from labrig.control.bank_inverse import PREVIEW_TOL
from labrig.control.control_model import (
    INVERTIBLE_EFFECTS,
    ControlModel,
    as_control_model,
    load_control_model,
    load_params,
)
from labrig.control.controllers import CompensationController, DirectController
from labrig.control.drive_check import InfeasibleCommandError, check_drive
from labrig.control.inverse_system import outside_zeros
from labrig.control.inversion import (
    CONTROLS,
    compensated_drive,
    compute_drive,
    direct_drive,
    model_tracking_error,
)
from labrig.control.metrics import (
    command_metrics,
    control_metrics,
    entry_metrics,
    final_strain_ue,
    hysteresis_width_pct,
    tracking_nrmse_pct,
    zero_command_strain_ue,
)

__all__ = [
    "CONTROLS",
    "INVERTIBLE_EFFECTS",
    "PREVIEW_TOL",
    "CompensationController",
    "ControlModel",
    "DirectController",
    "InfeasibleCommandError",
    "as_control_model",
    "check_drive",
    "command_metrics",
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
