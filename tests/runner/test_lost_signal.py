"""A stop signal whose exception Python drops (raised inside a finaliser or a gc callback) is
delivered again, so Ctrl-C still stops the command and later repeats are still ignored."""

from __future__ import annotations

import gc
import os
import signal
import sys
import time

import pytest

from labrig.core.interrupts import Interrupted, interrupt_once


class _SignalInFinaliser:
    """Sends ``sig`` to this process from ``__del__``: the handler runs inside the finaliser,
    where Python prints and drops any exception."""

    def __init__(self, sig: int) -> None:
        self.sig = sig

    def __del__(self) -> None:
        os.kill(os.getpid(), self.sig)
        total = 0
        for k in range(1000):  # bytecodes for the handler to run at
            total += k


def _wait_for_interrupt(seconds: float = 3.0) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(0.01)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_lost_in_a_finaliser_is_raised_again(sig):
    with interrupt_once() as guard:
        with pytest.raises(Interrupted) as ei:
            _SignalInFinaliser(sig)  # dropped at once: the finaliser runs here
            _wait_for_interrupt()
        assert ei.value.signum == sig and ei.value.exit_code == 128 + sig
        assert guard.received == [sig]  # the second delivery is not a second signal
        # repeats are still ignored until the block ends
        os.kill(os.getpid(), signal.SIGINT)
        _wait_for_interrupt(0.1)
    assert guard.received == [sig, signal.SIGINT]


def test_a_signal_lost_in_a_gc_callback_is_raised_again():
    fired = []
    armed = []  # an automatic collection before the guard is in place must not fire it

    def callback(phase, info):
        if phase == "start" and armed and not fired:
            fired.append(phase)
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(1000))

    gc.callbacks.append(callback)
    try:
        with interrupt_once(), pytest.raises(Interrupted):
            armed.append(True)
            # the youngest generation only: the callbacks run for any collection, and a full
            # one in a worker that has run hundreds of tests takes seconds
            gc.collect(0)
            _wait_for_interrupt()
    finally:
        gc.callbacks.remove(callback)
    assert fired == ["start"]


def test_other_dropped_exceptions_still_reach_the_previous_hook(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda info: seen.append(info.exc_type))

    class Broken:
        def __del__(self):
            raise ValueError("not ours")

    with interrupt_once():
        Broken()
    assert seen == [ValueError]
    assert sys.unraisablehook is not None and sys.unraisablehook.__name__ == "<lambda>"


def test_a_lost_signal_while_deferred_waits_for_check():
    with interrupt_once() as guard:
        with guard.defer():
            os.kill(os.getpid(), signal.SIGINT)
            _wait_for_interrupt(0.1)  # deferred: recorded, not raised
            assert guard.pending
            guard.lost(Interrupted(signal.SIGINT))  # a late report of a dropped one
            _wait_for_interrupt(0.1)  # nothing sent again while deferred
        with pytest.raises(Interrupted):
            guard.check()
    assert guard.received == [signal.SIGINT]
