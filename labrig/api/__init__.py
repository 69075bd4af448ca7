"""The Python API: ``labrig.open``, ``labrig.run``, ``labrig.runs`` and the :class:`Run` they
give, and ``labrig.validate`` (docs/python-api.md). :mod:`.runs` holds the first ones,
:mod:`.validate` the last; :mod:`.frames` turns entries into pandas and xarray objects."""

from labrig.api.runs import EntryInfo, Run, as_json, open, run, runs
from labrig.api.validate import validate

__all__ = ["EntryInfo", "Run", "as_json", "open", "run", "runs", "validate"]
