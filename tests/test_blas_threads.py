"""``labrig.core.blas.single_thread_blas`` from several threads at once: OpenBLAS's thread count
is process-wide, so overlapping blocks (a simulated bench stepping in its servers' threads while
a fit runs) must leave it at 1 while any block is open and as it was once all are closed. The
counts are read with threadpoolctl, independently of labrig's own access to OpenBLAS."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (loads scipy's OpenBLAS copy too)
from threadpoolctl import threadpool_info, threadpool_limits

from labrig.core.blas import single_thread_blas


def openblas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["internal_api"] == "openblas"]


@pytest.mark.timeout(30)
def test_blocks_overlapping_in_two_threads_restore_the_count_only_when_both_close() -> None:
    with threadpool_limits(limits=2, user_api="blas"):
        before = openblas_threads()
        if not before or set(before) != {2}:
            pytest.skip(f"no OpenBLAS whose thread count can be set to 2: {before}")
        # A opens, B opens, A closes, B closes: the order in which a block that saved the count
        # while another had set it to 1 restored the 1
        a_open, b_open, a_closed = threading.Event(), threading.Event(), threading.Event()
        seen: dict[str, list[int]] = {}

        def a() -> None:
            with single_thread_blas():
                seen["a inside"] = openblas_threads()
                a_open.set()
                assert b_open.wait(10)
            a_closed.set()

        def b() -> None:
            assert a_open.wait(10)
            with single_thread_blas():
                b_open.set()
                assert a_closed.wait(10)
                seen["b inside after a closed"] = openblas_threads()
                np.ones((64, 64)) @ np.ones((64, 64))  # BLAS still works
            seen["after both"] = openblas_threads()

        threads = [threading.Thread(target=a), threading.Thread(target=b)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(20)
        assert not any(t.is_alive() for t in threads)
        assert seen["a inside"] == [1] * len(before)
        assert seen["b inside after a closed"] == [1] * len(before)
        assert seen["after both"] == before


@pytest.mark.timeout(30)
def test_a_fork_while_another_thread_holds_the_setting_leaves_the_child_free() -> None:
    """A forked child (the analysis workers fork) must not inherit the setting's lock held by
    a thread that does not exist in it: another thread holds the lock for 0.3 s across the
    moment the main thread forks; the child then opens and closes a block and exits. Without
    the fork hooks the child waits on the lock forever (killed after 5 s here)."""
    import os
    import signal
    import time

    from labrig.core import blas

    if not hasattr(os, "fork"):
        pytest.skip("no os.fork on this platform")
    held = threading.Event()

    def hold() -> None:
        with blas._lock:
            held.set()
            time.sleep(0.3)

    t = threading.Thread(target=hold)
    t.start()
    assert held.wait(5)
    pid = os.fork()
    if pid == 0:  # the child: one block, then leave at once (no pytest teardown)
        try:
            with single_thread_blas():
                pass
        finally:
            os._exit(0)
    t.join(5)
    deadline = time.monotonic() + 5.0
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            pytest.fail("the forked child waited on the lock")
        time.sleep(0.02)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
