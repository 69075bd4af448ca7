"""Run a file reader in a child process with a time limit.

The MATLAB readers are compiled code (scipy's MAT reader, libhdf5 under h5py): a malformed file
can make them loop, recurse until the stack overflows, or crash, and neither Ctrl-C nor a Python
exception stops them. In a forked child, such a file costs at most the time limit and ends in a
clear error; the parent stays responsive. The result comes back through a pipe (pickled).
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import signal
from collections.abc import Callable
from typing import Any


class ReaderError(Exception):
    """The reader raised (message), took too long or died (a message saying which)."""


def _child(conn: Any, fn: Callable[..., Any], args: tuple) -> None:
    faulthandler.disable()  # a crash is reported by the parent, without the child's stack
    try:
        result: tuple[str, Any] = ("ok", fn(*args))
    except BaseException as e:  # everything goes back to the parent as a message
        result = ("error", f"{type(e).__name__}: {e}" if not str(e) else str(e))
    try:
        conn.send(result)
    finally:
        conn.close()


def call_isolated(fn: Callable[..., Any], *args: Any, timeout_s: float) -> Any:
    """``fn(*args)`` in a forked child; raises :class:`ReaderError` if it raises (its message),
    runs longer than ``timeout_s`` (killed), or dies (the signal)."""
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args), daemon=True)
    proc.start()
    send.close()
    try:
        if not receive.poll(timeout_s):
            raise ReaderError(f"reading took longer than {timeout_s:g} s: the file is malformed")
        try:
            status, value = receive.recv()
        except EOFError:
            proc.join()
            raise ReaderError(_death(proc.exitcode)) from None
    finally:
        receive.close()
        if proc.is_alive():
            proc.kill()
        proc.join()
    if status != "ok":
        raise ReaderError(value)
    return value


def _death(code: int | None) -> str:
    if code is not None and code < 0:
        name = signal.Signals(-code).name if -code in signal.valid_signals() else str(-code)
        return f"the reader crashed ({name}): the file is malformed"
    return f"the reader stopped (exit code {code}): the file is malformed"
