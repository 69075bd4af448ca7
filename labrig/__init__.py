"""labrig: piezo-actuator experiments on real or simulated rigs, logged to HDF5, compared with a
fractional-order dynamic hysteresis model.

The Python API (docs/python-api.md): ``labrig.open(path)`` and ``labrig.run(protocol)`` give a
:class:`~labrig.api.Run` (metadata, samples as pandas or xarray, ``fit``, ``report``,
``diagnose``); ``labrig.runs(folder, where=[...])`` lists run files as ``labrig runs`` does;
``labrig.as_json(result)`` is what the matching command prints with ``--json``.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("labrig")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

# after __version__: the modules the API loads on first use read it
from labrig.api import EntryInfo, Run, as_json, open, run, runs

__all__ = ["EntryInfo", "Run", "__version__", "as_json", "open", "run", "runs"]
