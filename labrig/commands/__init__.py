"""Each analysis command as one library call, used alike by the command line, the Python API and
the fleet: read a run file into records and settings (:mod:`.prepare`), ``fit`` (:mod:`.fit`),
``diagnose`` (:mod:`.diagnose`)."""
