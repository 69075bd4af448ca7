"""The HDF5 run file: written incrementally while a protocol runs, read back for analysis.

Layout (NeXus conventions; docs/runfile.md is the full description)::

    /                         @NX_class=NXroot @default=<first entry> @creator=labrig
                              @creator_version @file_name @file_time @file_update_time
                              @HDF5_Version @h5py_version @labrig_format=1
    /run                      NXcollection: the run as a whole
        status, status_reason   "running" | "complete" | "aborted" | "failed"; why
        start_time, end_time    ISO 8601 with UTC offset
        seed, software_version, program_name, protocol_name, planned_entries (JSON list)
        protocol              NXnote: type, file_name, data = the protocol file's text
        rig                   NXnote: type, file_name, data = the rig file's text
        instrument            NXinstrument: one group per device (identity / settings),
                              description_json = the rig's describe() as JSON
        ramp_to_zero          NXcollection (runs): time (s), voltage (V) of the ramp to 0 V
        final_amplifier_voltage_V, exit_code    how the run ended (runs)
    /<entry>                  NXentry per concrete step, in run order, @default=data
        title, entry_index, start_time, end_time, status, status_reason, sample_rate (Hz),
        step_definition (JSON of the concrete step), duration (s, at finish)
        instrument, protocol, rig   hard links to the /run groups
        data                  NXdata @signal=strain @axes=time @auxiliary_signals=[...]
            time (s), command_voltage (V), amplifier_voltage (V), gauge_raw (V),
            strain (ue), temperature (degC), ...   every one with @units and @long_name

Crash safety: sample datasets are chunked, resizable and checksummed (Fletcher32);
:meth:`EntryWriter.append` extends them, writes the block and flushes the file (``H5Fflush``)
before returning, so after a ``kill -9`` the file opens and holds every block whose ``append``
returned. The statuses then still read ``running``: readers report such a run as incomplete.
Tests kill a writer for real. We do not use SWMR: it needs every object created before writing
starts and leaves a file that plain readers refuse to open after a crash; plain flushes
survived every kill we tried. A full disk stops the writer cleanly (:mod:`labrig.store.space`).

This module is the public face; the work is in :mod:`labrig.store.format` (vocabulary),
:mod:`labrig.store.writer`, :mod:`labrig.store.reader` and :mod:`labrig.store.space`.
"""

from __future__ import annotations

from labrig.store.format import (
    FINAL_STATUSES,
    FORMAT_VERSION,
    STANDARD_CHANNELS,
    STATUSES,
    Channel,
    channel,
    now_iso,
)
from labrig.store.reader import (
    RunEntry,
    RunFile,
    export_csv,
    read_run,
    run_info,
    run_summary,
)
from labrig.store.space import estimate_run_bytes, free_bytes
from labrig.store.writer import EntryWriter, RunWriter

__all__ = [
    "FINAL_STATUSES",
    "FORMAT_VERSION",
    "STANDARD_CHANNELS",
    "STATUSES",
    "Channel",
    "EntryWriter",
    "RunEntry",
    "RunFile",
    "RunWriter",
    "channel",
    "estimate_run_bytes",
    "export_csv",
    "free_bytes",
    "now_iso",
    "read_run",
    "run_info",
    "run_summary",
]
