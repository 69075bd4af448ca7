"""Reading a run file in a child process with limits on its CPU time and wall-clock time.

libhdf5 is compiled code: some damaged files make it loop forever (a run file with 512 zeroed
bytes in the fractal heap of the root's attributes spins at 100 % CPU inside ``H5Aread``), and
a loop in C never returns to Python, so neither a Python exception nor Ctrl-C stops it. No check
made before the call can rule that out for every damaged structure, so the reading happens in a
forked child:

- the kernel stops the child when one step of the reading (the reader calls
  :func:`allow_cpu` before each object it opens or reads) uses more than its CPU time
  (``RLIMIT_CPU``, renewed at every step: CPU time, so a busy machine does not make a sound
  file look damaged, and a file of many objects gets time for each);
- the parent kills it after :func:`wall_limit_s` seconds of waiting (a child that waits on
  something instead of computing);
- a child that crashes (a segmentation fault in libhdf5) takes only itself down.

The result comes back pickled through a pipe; the parent keeps answering Ctrl-C while it waits
(and kills the child). Where ``os.fork`` or the POSIX module ``resource`` does not exist
(Windows) the function is called in-process, without limits.

A read repeated many times a second (the live view's frames, :mod:`labrig.live.frames`) goes
to an :class:`IsolatedWorker` instead: one long-lived child, started as a new interpreter
(``python -c ...``: never a fork of a process whose other threads may hold h5py's lock), that
makes each call under the same limits and answers through a pipe. A fork of a process with
numpy, h5py and the model loaded costs tens of milliseconds of CPU, most of a frame's cost; a
child that runs out of time, crashes or stops answering is killed and the next call starts
another.
"""

from __future__ import annotations

import contextlib
import faulthandler
import math
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import IO, Any

try:  # POSIX only: without it (Windows) reads are made in-process, without CPU limits
    import resource
except ImportError:
    resource = None  # type: ignore[assignment]

#: CPU seconds one step of a read may take (opening the file, one object), plus
#: :data:`CPU_BYTES_PER_S` per byte it reads (a sound run file reads, checksums included,
#: at well over 100 MB per CPU second; an object's metadata in under 10 ms)
STEP_CPU_S = 1.0
CPU_BYTES_PER_S = 20e6
#: the wall-clock limit: this many seconds plus :data:`WALL_BYTES_PER_S` per byte (a slow disk)
BASE_WALL_S = 30.0
WALL_BYTES_PER_S = 2e6
#: the child's exit code when it could not send its result back
_NO_RESULT = 70
#: True in a child of :func:`call_isolated` (where :func:`allow_cpu` sets limits)
_in_child = False


class IsolatedReadError(Exception):
    """The child did not return a result: it ran out of time, was killed or crashed
    (the message says which, for a person)."""


class IsolatedCallError(Exception):
    """The function raised something the child could not send back: the traceback as text."""


def allow_cpu(seconds: float = STEP_CPU_S, size_bytes: int = 0) -> None:
    """In a child of :func:`call_isolated`: allow the next step ``seconds`` plus
    ``size_bytes / CPU_BYTES_PER_S`` of CPU time from now (the kernel stops the child beyond
    that: ``RLIMIT_CPU``, whole seconds, rounded up). Does nothing in any other process."""
    if not _in_child or resource is None:
        return
    use = resource.getrusage(resource.RUSAGE_SELF)
    limit = math.ceil(use.ru_utime + use.ru_stime + seconds + size_bytes / CPU_BYTES_PER_S)
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)  # only the soft limit moves (SIGXCPU)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_CPU, (limit, hard))


def wall_limit_s(size_bytes: int) -> float:
    """Seconds of waiting allowed for reading a file of ``size_bytes``."""
    return BASE_WALL_S + size_bytes / WALL_BYTES_PER_S


def call_isolated(
    fn: Callable[..., Any], *args: Any, size_bytes: int, wall_s: float | None = None
) -> Any:
    """``fn(*args)`` in a forked child (module docstring), with the limits for a file of
    ``size_bytes`` (``wall_s``: a shorter wall-clock limit, for a reader that would rather
    skip a read than wait: the live view). Returns what ``fn`` returns, re-raises what it
    raises (when it can be pickled; otherwise :class:`IsolatedCallError`), and raises
    :class:`IsolatedReadError` when the child is stopped by a limit or dies."""
    if not hasattr(os, "fork") or resource is None:
        return fn(*args)
    wall = wall_limit_s(size_bytes) if wall_s is None else wall_s
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(read_fd)
        _child(write_fd, size_bytes, fn, args)
    os.close(write_fd)
    reaped = False
    try:
        payload = _receive(read_fd, time.monotonic() + wall)
        if payload is None:
            raise IsolatedReadError(f"reading did not finish within {wall:.3g} s (stopped)")
        _, status = os.waitpid(pid, 0)
        reaped = True
        if not payload:
            raise IsolatedReadError(_death(status))
    finally:
        os.close(read_fd)
        if not reaped:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    return _unpacked(payload)


def _unpacked(payload: bytes) -> Any:
    """The child's answer (:func:`_answer`): the value returned, or the exception raised."""
    kind, value = pickle.loads(payload)
    if kind == "ok":
        return value
    if kind == "raised":
        raise value
    raise IsolatedCallError(value)


def _answer(fn: Callable[..., Any], args: tuple, size_bytes: int) -> bytes:
    """In a child: ``fn(*args)`` under the CPU limit, its result or exception pickled as
    ``(kind, value)``; an exception that cannot be pickled is sent as its traceback's text."""
    allow_cpu()
    try:
        result: tuple[str, Any] = ("ok", fn(*args))
    except Exception as e:
        result = ("raised", e)
    allow_cpu(size_bytes=size_bytes)  # pickling what was read
    try:
        return pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as e:
        what = result[1] if result[0] == "raised" else e
        return pickle.dumps(("bug", "".join(traceback.format_exception(what))))


def _child(write_fd: int, size_bytes: int, fn: Callable[..., Any], args: tuple) -> None:
    """Run ``fn`` under CPU limits and write ``(kind, value)`` pickled to ``write_fd``."""
    global _in_child
    code = _NO_RESULT
    try:
        _in_child = True
        faulthandler.disable()  # a crash is reported by the parent, without the child's stack
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C ends the child at once
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        data = _answer(fn, args, size_bytes)
        with os.fdopen(write_fd, "wb") as out:
            out.write(data)
        code = 0
    finally:
        os._exit(code)


def _receive(fd: int, deadline: float | None, n: int | None = None) -> bytes | None:
    """The bytes a child writes to ``fd``: all until it closes it (``n`` None), or exactly
    ``n`` (``b""`` when it closes before); ``None`` past ``deadline`` (None: no deadline)."""
    chunks: list[bytes] = []
    left_n = n
    while left_n is None or left_n > 0:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
        chunk = os.read(fd, 1 << 20 if left_n is None else min(left_n, 1 << 20))
        if not chunk:
            return b"".join(chunks) if n is None else b""
        chunks.append(chunk)
        if left_n is not None:
            left_n -= len(chunk)
    return b"".join(chunks)


def _death(status: int) -> str:
    """Why a child ended without a result, from its wait status."""
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig in (signal.SIGXCPU, signal.SIGKILL):
            return "the HDF5 library looped on it (stopped after its CPU time for one object)"
        name = signal.Signals(sig).name if sig in signal.valid_signals() else str(sig)
        return f"the HDF5 library crashed reading it ({name})"
    return f"the reading process stopped without a result (exit code {os.WEXITSTATUS(status)})"


#: the first call waits this long (s) for a worker to start (a new interpreter importing numpy
#: and h5py, on a loaded machine), besides the call's own wall-clock limit
WORKER_START_S = 60.0
#: a message between a worker and its parent: its length, then that many bytes of pickle
_LENGTH = struct.Struct("<Q")
#: the byte a worker writes once it is ready for calls
_READY = b"R"


class IsolatedWorker:
    """A long-lived child process that makes calls with the limits of :func:`call_isolated`
    (module docstring): :meth:`call` sends ``fn`` (by reference: a module-level function) and
    its arguments, the child calls it with the CPU limit renewed at each step (:func:`allow_cpu`)
    and answers with the result or the exception. Calls are made one at a time (a lock). A
    child that does not answer within the wall-clock limit, or dies, is killed; the next call
    starts another. Where ``resource`` does not exist (Windows) calls are made in-process."""

    def __init__(self) -> None:
        self._proc: subprocess.Popen[bytes] | None = None
        self._lock = threading.Lock()

    @property
    def pid(self) -> int | None:
        """The child's process id (None before the first call, or after a failure)."""
        return self._proc.pid if self._proc is not None else None

    def call(
        self, fn: Callable[..., Any], *args: Any, size_bytes: int, wall_s: float | None = None
    ) -> Any:
        """``fn(*args)`` in the worker; returns and raises as :func:`call_isolated` does."""
        if resource is None:
            return fn(*args)
        wall = wall_limit_s(size_bytes) if wall_s is None else wall_s
        with self._lock:
            proc = self._started()
            request = pickle.dumps((fn, args, size_bytes), protocol=pickle.HIGHEST_PROTOCOL)
            try:
                _send(proc.stdin, request)
                payload = _message(proc.stdout, time.monotonic() + wall)
            except (OSError, ValueError):
                payload = b""
            except BaseException:  # (Ctrl-C): its answer must not be taken for the next call's
                self._stop()
                raise
            if not payload:
                code = self._stop()
                if payload is None:
                    raise IsolatedReadError(f"reading did not finish within {wall:.3g} s (stopped)")
                raise IsolatedReadError(_ended(code))
        return _unpacked(payload)

    def _started(self) -> subprocess.Popen[bytes]:
        if self._proc is not None and self._proc.poll() is None:
            return self._proc
        self._stop()  # a child that ended: its pipes closed, itself reaped
        self._proc = proc = subprocess.Popen(
            # -P: the current folder is not put first on the path (a user's select.py or
            # h5py.py there must not be imported in its place)
            [sys.executable, "-P", "-c", "from labrig.store.isolated import serve; serve()"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            close_fds=True,
        )
        assert proc.stdout is not None
        if _receive(proc.stdout.fileno(), time.monotonic() + WORKER_START_S, 1) != _READY:
            code = self._stop()
            raise IsolatedReadError(f"the reading process did not start: {_ended(code)}")
        return proc

    def _stop(self) -> int | None:
        """Kill the child if it runs; its return code (None: there was none)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
        for stream in (proc.stdin, proc.stdout):
            with contextlib.suppress(OSError):
                stream.close()  # type: ignore[union-attr]
        return proc.wait()

    def close(self) -> None:
        """Stop the child (a new one starts at the next call)."""
        with self._lock:
            self._stop()


def serve() -> None:
    """The worker's side of :class:`IsolatedWorker`: read calls from stdin, answer on stdout,
    until stdin closes (the parent ended). Ctrl-C is the parent's to handle."""
    global _in_child
    _in_child = True
    faulthandler.disable()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    assert resource is not None
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    inp = sys.stdin.buffer
    out = os.fdopen(os.dup(1), "wb")  # the answers' own descriptor: a stray print goes to
    os.dup2(2, 1)  # stderr, not into the answers
    out.write(_READY)
    out.flush()
    while (request := _message(inp, None)) is not None and request:
        _send(out, _answer(_call_of, (request,), 0))


def _call_of(request: bytes) -> Any:
    """Make the call a worker was sent: ``(fn, args, size_bytes)`` pickled (raises what the
    function raises, or that it is not found here)."""
    fn, args, size_bytes = pickle.loads(request)
    allow_cpu(size_bytes=size_bytes)
    return fn(*args)


def _ended(code: int | None) -> str:
    """Why a worker gave no answer, from its return code (negative: the signal)."""
    if code is None or code >= 0:
        return f"the reading process stopped without a result (exit code {code})"
    return _death(-code)  # a signal number is the wait status of a process it killed


def _send(stream: IO[bytes] | None, data: bytes) -> None:
    assert stream is not None
    stream.write(_LENGTH.pack(len(data)) + data)
    stream.flush()


def _message(stream: IO[bytes] | None, deadline: float | None) -> bytes | None:
    """One message from ``stream``: its bytes; ``b""`` when the stream ended; ``None`` past
    ``deadline`` (``None``: no deadline)."""
    assert stream is not None
    fd = stream.fileno()
    head = _receive(fd, deadline, _LENGTH.size)
    if not head:
        return head
    return _receive(fd, deadline, _LENGTH.unpack(head)[0])
