"""Stop requests from the operating system: SIGINT, SIGTERM, SIGHUP and SIGQUIT, handled once.

Inside :func:`interrupt_once` the four catchable stop signals become :class:`Interrupted` (a
:class:`KeyboardInterrupt` that knows its signal, its exit code ``128 + signal number`` and a
reason in words). The first one counts; later ones are recorded and ignored until the block
ends, so an impatient second Ctrl-C, or the SIGTERM that follows a SIGHUP when a terminal
closes, cannot interrupt the ramp to 0 V or the closing of the run file.

Where an exception must not appear at an arbitrary point (while the output is energised, during
the ramp to 0 V, while a run file is being written), code runs under :meth:`SignalGuard.defer`:
a signal is then only recorded, and :meth:`SignalGuard.check` raises it at a safe point of the
caller's choosing (the runner checks after every acquired block).

A signal handler runs between any two bytecodes, including those of a finaliser (``__del__``),
a weakref callback or a garbage-collector callback, where Python prints an exception and drops
it. A first signal lost that way would leave the command running with every later Ctrl-C
ignored; :func:`interrupt_once` therefore watches ``sys.unraisablehook`` for its own exception and
delivers the signal again (see :meth:`SignalGuard.lost`).
"""

from __future__ import annotations

import _thread
import contextlib
import signal
import sys
import threading
import time
from collections.abc import Iterator

#: the signals a run stops on, with the words its run file records (SIGHUP and SIGQUIT do not
#: exist on Windows)
STOP_SIGNALS: dict[int, str] = {
    getattr(signal, name): words
    for name, words in (
        ("SIGINT", "interrupted (Ctrl-C, SIGINT)"),
        ("SIGTERM", "terminated (SIGTERM)"),
        ("SIGHUP", "hangup (SIGHUP: the terminal or the SSH session closed)"),
        ("SIGQUIT", "quit (SIGQUIT, Ctrl-\\)"),
    )
    if hasattr(signal, name)
}


def exit_code_for(signum: int) -> int:
    """The shell's exit status of a process stopped by ``signum``: 128 + signal number."""
    return 128 + int(signum)


def reason_for(signum: int) -> str:
    """The run file's ``status_reason`` for a run stopped by ``signum``."""
    return STOP_SIGNALS.get(signum, f"stopped by signal {signum}")


class Interrupted(KeyboardInterrupt):
    """A stop signal turned into an exception; ``exit_code`` is ``128 + signum``."""

    def __init__(self, signum: int = signal.SIGINT):
        self.signum = int(signum)
        super().__init__(reason_for(self.signum))

    @property
    def exit_code(self) -> int:
        return exit_code_for(self.signum)

    @property
    def reason(self) -> str:
        return reason_for(self.signum)


def signum_of(exc: BaseException | None) -> int:
    """The signal behind a :class:`KeyboardInterrupt` (a plain one is Ctrl-C, SIGINT)."""
    return getattr(exc, "signum", signal.SIGINT)


class SignalGuard:
    """What :func:`interrupt_once` has seen: ``received`` signals in order, the first one
    raised or pending (see :meth:`defer` and :meth:`check`)."""

    def __init__(self) -> None:
        self.received: list[int] = []
        self.raised = False
        self._deferring = 0
        self._resent: int | None = None

    @property
    def first(self) -> int | None:
        """The first stop signal received, or None."""
        return self.received[0] if self.received else None

    @property
    def pending(self) -> bool:
        """A signal arrived while deferred (or was lost) and has not been raised yet."""
        return bool(self.received) and not self.raised

    def handle(self, signum: int, frame: object = None) -> None:
        # a repeat can run this handler again at any bytecode of this one; whichever call sees
        # ``raised`` False first raises, and its exception unwinds the other
        if self._resent == signum:
            self._resent = None  # :meth:`lost` sent it again: already recorded
        else:
            self.received.append(signum)
        if not self.raised and not self._deferring:
            self.raised = True
            raise Interrupted(self.received[0])

    def check(self) -> None:
        """Raise the pending signal as :class:`Interrupted` (once); otherwise do nothing."""
        if self.pending:
            self.raised = True
            raise Interrupted(self.received[0])

    def lost(self, exc: Interrupted) -> None:
        """``exc`` was raised where Python drops exceptions (a finaliser or a callback): make the
        signal pending again and, unless deferred, send it to the main thread once more."""
        self.raised = False
        if self._deferring:
            return  # the caller's next :meth:`check` raises it
        # from another thread, once this hook has returned: a handler that ran inside the hook
        # would be dropped too (``threading.Thread.start`` waits, so the low-level call)
        _thread.start_new_thread(self._send_again, (exc.signum,))

    def _send_again(self, signum: int) -> None:
        time.sleep(0.01)
        if self.pending and not self._deferring and _active is self:
            self._resent = signum
            _thread.interrupt_main(signal.Signals(signum))

    @contextlib.contextmanager
    def defer(self) -> Iterator[SignalGuard]:
        """Within this block a stop signal is recorded, never raised (see :meth:`check`)."""
        self._deferring += 1
        try:
            yield self
        finally:
            self._deferring -= 1


_active: SignalGuard | None = None


@contextlib.contextmanager
def interrupt_once() -> Iterator[SignalGuard]:
    """SIGINT, SIGTERM, SIGHUP and SIGQUIT raise :class:`Interrupted` the first time only;
    later ones are ignored until the block ends. The previous handlers come back afterwards.

    Nested blocks share the outermost guard (``execute()`` inside the CLI's block). Outside the
    main thread (Python delivers signals there only) this yields a guard that sees nothing.
    """
    global _active
    if threading.current_thread() is not threading.main_thread():
        yield SignalGuard()
        return
    if _active is not None:
        yield _active
        return
    guard = SignalGuard()
    old = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    old_hook = sys.unraisablehook

    def unraisable(info: sys.UnraisableHookArgs) -> None:
        if isinstance(info.exc_value, Interrupted) and _active is guard:
            guard.lost(info.exc_value)
        else:
            old_hook(info)

    _active = guard
    try:
        sys.unraisablehook = unraisable
        for sig in old:
            signal.signal(sig, guard.handle)
        yield guard
    finally:
        # handlers first: a signal arriving between the two steps finds no stale guard
        for sig, h in old.items():
            if h is not None:
                signal.signal(sig, h)
        _active = None
        if sys.unraisablehook is unraisable:
            sys.unraisablehook = old_hook
