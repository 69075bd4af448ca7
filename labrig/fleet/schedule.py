"""Running a batch's tasks: on a Dask cluster (a ``LocalCluster`` on this machine, or a running
scheduler reached by its address) or one after another in this process, with a progress bar
and an ETA.

On Dask each run file is one task (:func:`labrig.fleet.tasks.run_task`, pickled by reference:
every worker must have the same labrig installed, which is checked before anything is
submitted). The task's argument is the run file's **path**; its result (the row and the
documents, a few hundred kB) comes back to the client, which writes every output. When a worker
dies, the scheduler gives its unfinished tasks to the others; a task that took down
``distributed.scheduler.allowed-failures`` (3) workers in a row comes back as ``KilledWorker``
and is recorded as a failed run like any other error.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from labrig.core.errors import LabrigError
from labrig.core.version import __version__
from labrig.fleet.tasks import TaskResult, TaskSpec, error_text, run_task

OnResult = Callable[[TaskResult], None]


class ClusterError(LabrigError):
    """The cluster cannot be used (unreachable scheduler, other labrig on the workers, no
    Dask): exit code 2."""

    exit_code = 2


@dataclass(frozen=True)
class Where:
    """Where the tasks run: ``serial`` (this process), ``local`` (a LocalCluster of
    ``workers`` processes) or ``address`` (the scheduler at ``address``)."""

    kind: str
    workers: int = 1
    address: str = ""


@dataclass
class ScheduleInfo:
    """How a batch ran: where, on how many workers, and its wall-clock time (s)."""

    kind: str
    n_workers: int
    wall_s: float = 0.0
    note: str = ""


def dask_available() -> bool:
    """Whether ``dask.distributed`` can be imported (the ``labrig[fleet]`` extra)."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def labrig_version() -> str:
    """This process's labrig version (run on each worker to compare with the client's)."""
    return __version__


def progress_bar(console: Console) -> Progress:
    """Runs done of all, failures, elapsed time and the time left (rich's ETA)."""
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(bar_width=30),
        MofNCompleteColumn(),
        TextColumn("[red]{task.fields[failed]} failed[/]"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=console,
    )


def failed_result(spec: TaskSpec, e: BaseException) -> TaskResult:
    """A task that did not come back (its worker died too often, the cluster failed)."""
    return TaskResult(spec.command, spec.path, spec.key, ok=False, error=error_text(e))


def run_serial(specs: Sequence[TaskSpec], on_result: OnResult, tick: Callable[[bool], None]):
    for spec in specs:
        res = run_task(spec)
        on_result(res)
        tick(res.ok)


#: Dask settings of the LocalCluster a batch starts (its workers get them from their nannies):
#:
#: - ``MALLOC_TRIM_THRESHOLD_`` not set in the workers' environment. Dask's nannies set it
#:   (65536) so that workers return freed memory to the system; setting it also fixes glibc's
#:   mmap threshold at 128 kB, so every NumPy temporary above that size is a fresh ``mmap``,
#:   zeroed page by page on first touch: on a fleet run's ``diagnose`` task, about 3 s of system
#:   CPU per task (+25 %). Without it a worker keeps its freed pages for the next arrays.
#: - the workers' statistical profiler off and two event-loop monitors slower (tick 1 s,
#:   system monitor 5 s; nothing here reads the profiles or the dashboard's history); the
#:   memory monitor, which enforces the workers' memory limit, keeps its pace.
LOCAL_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
}


def cluster_client(where: Where, stack: ExitStack):
    """A Dask client for ``where`` (``local`` or ``address``), closed with ``stack``: on a
    running scheduler, or on a LocalCluster of ``where.workers`` processes (one thread each, on
    127.0.0.1, with :data:`LOCAL_CLUSTER_CONFIG`); :class:`ClusterError` when the scheduler
    cannot be reached."""
    from distributed import Client, LocalCluster

    if where.kind == "address":
        try:
            return stack.enter_context(Client(where.address, timeout="20s"))
        except (OSError, TimeoutError, ValueError) as e:
            raise ClusterError(f"--scheduler {where.address}: cannot connect ({e})") from None
    import dask

    stack.enter_context(dask.config.set(LOCAL_CLUSTER_CONFIG))
    cluster = stack.enter_context(
        LocalCluster(
            n_workers=where.workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",  # its HTTP server on a free port (no warning)
            worker_dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    )
    return stack.enter_context(Client(cluster))


def check_versions(client) -> int:
    """The number of workers; a :class:`ClusterError` when a worker has another labrig."""
    versions = client.run(labrig_version)
    other = {w: v for w, v in versions.items() if v != __version__}
    if other:
        w, v = next(iter(other.items()))
        raise ClusterError(
            f"worker {w} has labrig {v}, this client {__version__}: install the same version "
            "on every worker (the results would differ)"
        )
    return len(versions)


def run_dask(
    specs: Sequence[TaskSpec],
    where: Where,
    on_result: OnResult,
    tick: Callable[[bool], None],
    info: ScheduleInfo,
) -> None:
    from distributed import as_completed

    with ExitStack() as stack:
        client = cluster_client(where, stack)
        if where.kind == "address":
            client.wait_for_workers(1, timeout=60)
        info.n_workers = check_versions(client)
        batch = uuid.uuid4().hex[:8]
        keys = [f"labrig-{s.command}-{s.key}-{batch}" for s in specs]
        futures = client.map(run_task, list(specs), key=keys, pure=False)
        by_key = dict(zip(keys, specs, strict=True))
        try:
            for fut in as_completed(futures):
                try:
                    res = fut.result()
                except Exception as e:  # KilledWorker, a lost connection
                    res = failed_result(by_key[fut.key], e)
                on_result(res)
                tick(res.ok)
                fut.release()
        except BaseException:
            client.cancel(futures)
            raise


def run_tasks(
    specs: Sequence[TaskSpec], where: Where, on_result: OnResult, console: Console
) -> ScheduleInfo:
    """Run every task where ``where`` says, calling ``on_result`` in the client as each
    finishes (in completion order) and drawing progress on ``console``."""
    info = ScheduleInfo(where.kind, where.workers if where.kind != "serial" else 1)
    t0 = time.perf_counter()
    bar = progress_bar(console)
    failed = 0
    with bar:
        task = bar.add_task(f"{specs[0].command if specs else 'batch'}", total=len(specs), failed=0)

        def tick(ok: bool) -> None:
            nonlocal failed
            failed += not ok
            bar.update(task, advance=1, failed=failed)

        if where.kind == "serial":
            run_serial(specs, on_result, tick)
        elif specs:
            run_dask(specs, where, on_result, tick, info)
    info.wall_s = time.perf_counter() - t0
    return info
