"""Former home of the ``fit`` / ``report`` helpers, kept for callers not yet moved
(tests/test_fit_effects_context.py): :mod:`labrig.analysis.prepare` reads a run file's records,
:mod:`labrig.params_file` reads parameter files, :mod:`labrig.report.build` builds the report.
Remove once nothing imports it."""

from labrig.analysis.prepare import prepare
from labrig.params_file import fitted_effects as _fitted_effects
from labrig.params_file import read_fit_output as read_params
from labrig.report.build import predict_entries

__all__ = ["_fitted_effects", "predict_entries", "prepare", "read_params"]
