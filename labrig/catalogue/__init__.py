"""The catalogue of run files (``labrig runs``; docs/catalogue.md): which runs a folder holds,
what each one is, filtered on request.

- :mod:`~labrig.catalogue.listing`: :func:`list_runs`, the listing with its filters;
- :mod:`~labrig.catalogue.index`: the per-folder SQLite index (``.labrig-index.sqlite``);
- :mod:`~labrig.catalogue.read`: one run file's record, read in child processes with time limits;
- :mod:`~labrig.catalogue.where`: the ``--where`` filter language.
"""

from labrig.catalogue.listing import ListedRun, Listing, ScanProgress, entry_summary, list_runs

__all__ = ["ListedRun", "Listing", "ScanProgress", "entry_summary", "list_runs"]
