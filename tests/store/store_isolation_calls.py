"""The functions test_store_isolation.py has a reader call in a child. A long-lived worker
(:class:`labrig.store.isolated.IsolatedWorker`) imports the module a function is defined in to
call it: this one imports little, where the test module would bring the CLI and its commands
into each new worker."""

from __future__ import annotations

import os
import signal
import time

import numpy as np

from labrig.core.errors import InputFileError, InputIssue


def crash() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def spin() -> None:
    while True:
        pass


def sleep() -> None:
    time.sleep(60)


def refuse() -> None:
    raise InputFileError([InputIssue("f.h5", 3, "entry/data", "why")])


def value(n: int) -> dict:
    return {"x": np.arange(n)}


def pid() -> int:
    print("a stray print in the reader")  # must not garble its answers
    return os.getpid()


def unpicklable() -> None:
    raise ValueError(lambda: 0)
