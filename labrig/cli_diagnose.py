"""Former home of ``labrig diagnose``, kept for callers not yet moved (tests/test_diagnose.py):
the command is :mod:`labrig.cli.diagnose`, the parameter file reader
:func:`labrig.params_file.start_params`. Remove once nothing imports it."""

from labrig.cli.diagnose import diagnose_command
from labrig.params_file import start_params as _load_params

__all__ = ["_load_params", "diagnose_command"]
