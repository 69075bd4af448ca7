"""labrig: piezo-actuator experiments on real or simulated rigs, logged to HDF5, compared with a
fractional-order dynamic hysteresis model.

The Python API (docs/python-api.md): ``labrig.open(path)`` and ``labrig.run(protocol)`` give a
:class:`~labrig.api.runs.Run` (metadata, samples as pandas or xarray, ``fit``, ``report``,
``diagnose``); ``labrig.runs(folder, where=[...])`` lists run files as ``labrig runs`` does;
``labrig.as_json(result)`` is what the matching command prints with ``--json``.

The package's folders are its layers (docs/architecture.md): ``core`` (errors, YAML/JSON safety,
outputs), ``model`` (the numerics), ``rig`` (device roles, limits, rig files), ``store`` (the run
file), ``protocol``, ``control``, ``importers``, ``catalogue``, ``runner`` (acquisition),
``analysis`` (fit, baselines, diagnose), ``report``, ``live``, ``commands`` (each command as one
library call), ``studies``, ``fleet``, ``api`` and ``cli``; instrument drivers are
``labrig.drivers``.
"""

from labrig.api.runs import EntryInfo, Run, as_json, open, run, runs
from labrig.api.validate import validate
from labrig.core.version import __version__

__all__ = ["EntryInfo", "Run", "__version__", "as_json", "open", "run", "runs", "validate"]
