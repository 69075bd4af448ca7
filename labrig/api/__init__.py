"""The Python API: ``labrig.open``, ``labrig.run``, ``labrig.runs`` and the :class:`Run` they give
(docs/python-api.md). :mod:`.runs` holds them; :mod:`.frames` turns entries into pandas and
xarray objects."""

from labrig.api.runs import EntryInfo, Run, as_json, open, run, runs

__all__ = ["EntryInfo", "Run", "as_json", "open", "run", "runs"]
