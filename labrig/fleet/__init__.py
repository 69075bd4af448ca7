"""A fleet of actuators: many run files identified and diagnosed at once, on Dask or serially.

- :mod:`.tasks`: one run file's task (``fit``, ``diagnose`` or ``report``), calling the library
  functions the one-by-one commands call; what a worker runs;
- :mod:`.identity`: what a run file says about itself (protocol, start time, seed, rig,
  actuator) for the table;
- :mod:`.cache`: content hashes and the per-run results a rerun reuses;
- :mod:`.schedule`: running the tasks on a Dask cluster (local or by address) or serially,
  with progress;
- :mod:`.table`: the fleet table (Parquet, CSV without pyarrow);
- :mod:`.outliers`: the robust z-score and the rule that flags a run;
- :mod:`.fleet_report`: ``fleet.html``;
- :mod:`.batch`: ``labrig batch`` as a library call;
- :mod:`.simfleet`: a simulated fleet with a manufacturing spread and defects
  (``labrig sim fleet``), and :mod:`.truth`: scoring the flags against its truth.

The method, the table's columns and the measurements: ``docs/fleet.md``.
"""
