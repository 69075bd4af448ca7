"""``labrig import``: measured data from other labs into run files (docs/import.md).

- :mod:`~labrig.importers.pipeline`: every input read and checked, then the run file written
  (:func:`import_files`); :mod:`~labrig.importers.writer` writes beside and renames.
- Readers, each giving :class:`~labrig.importers.table.Table` objects: delimited text
  (:mod:`~labrig.importers.sniff` finds the layout, :mod:`~labrig.importers.text` reads it with
  pandas), MATLAB files (:mod:`~labrig.importers.mat_read`, in a child process with a time
  limit, :mod:`~labrig.importers.isolated`) as plain variables
  (:mod:`~labrig.importers.mat_tables`) or dSPACE ControlDesk captures
  (:mod:`~labrig.importers.dspace`).
- A table and the options -> an entry: :mod:`~labrig.importers.select` (which column is what),
  :mod:`~labrig.importers.entry` (time base, units, sign and scale, window),
  :mod:`~labrig.importers.aux` (auxiliary channels), :mod:`~labrig.importers.units` (pint),
  :mod:`~labrig.importers.labels` (names from labels).
- :mod:`~labrig.importers.options` checks the options; :mod:`~labrig.importers.limits` bounds
  what is read; :mod:`~labrig.importers.listing` is ``--list``.
"""

from labrig.importers.entry import ImportedEntry
from labrig.importers.listing import list_table
from labrig.importers.options import ImportOptions, check_options
from labrig.importers.pipeline import import_files, read_entries, read_tables

__all__ = [
    "ImportOptions",
    "ImportedEntry",
    "check_options",
    "import_files",
    "list_table",
    "read_entries",
    "read_tables",
]
