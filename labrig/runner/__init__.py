"""Acquisition: open a rig (:mod:`.rigfile`), execute a checked plan on it and log the run file
(:mod:`.execute`, the only code that sequences hardware), record how a run ended
(:mod:`.record`)."""
