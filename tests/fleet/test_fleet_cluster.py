"""``labrig batch`` on a Dask scheduler and two workers started as separate processes
(``dask scheduler``, ``dask worker``) on 127.0.0.1, reached by ``--scheduler``.

- the batch runs on both workers and its rows equal a serial batch's;
- a worker killed (SIGKILL) mid-batch: the batch completes, the task it held runs again on the
  other worker, no row is missing or doubled.

Marked ``cluster`` and run only when selected (``pytest -m cluster``); every process is bounded
in time and ended by the fixture.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from labrig.fleet.simfleet import write_fleet
from labrig.fleet.table import read_table

from helpers import FLEET_CAMPAIGN

if importlib.util.find_spec("distributed") is None:  # found, not imported: importing
    # it costs every test process about half a second of collection
    pytest.skip("needs distributed (the fleet extra)", allow_module_level=True)
pytestmark = [pytest.mark.cluster, pytest.mark.timeout(900)]

BIN = Path(sys.executable).parent


@dataclass
class Cluster:
    address: str
    workers: list[subprocess.Popen]


@pytest.fixture
def cluster(request, tmp_path) -> Iterator[Cluster]:
    """A scheduler and two single-threaded workers without nannies (a killed worker stays
    dead), each its own process; all ended afterwards."""
    if "cluster" not in (request.config.getoption("markexpr") or ""):
        pytest.skip("starts a Dask cluster: run with -m cluster")
    from distributed import Client

    sched_file = tmp_path / "scheduler.json"
    common = ["--no-dashboard"]
    procs = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--scheduler-file",
                str(sched_file),
                *common,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        t0 = time.monotonic()
        while not sched_file.exists() and time.monotonic() - t0 < 60:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        workers = [
            subprocess.Popen(
                [
                    str(BIN / "dask"),
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--host",
                    "127.0.0.1",
                    "--name",
                    f"w{k}",
                    *common,
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            for k in (1, 2)
        ]
        procs += workers
        with Client(address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=120)
        yield Cluster(address, workers)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def small_fleet(tmp_path: Path, n: int) -> list[Path]:
    proto = tmp_path / "small.yaml"
    proto.write_text(FLEET_CAMPAIGN)
    return write_fleet(n, tmp_path / "runs", proto, seed=21, defect_fraction=0.0)


def labrig(*args: object) -> list[str]:
    return [str(BIN / "labrig"), *map(str, args)]


def rows_by_file(out: Path) -> dict[str, dict]:
    rows = read_table(out / "fleet.parquet")
    names = [Path(r["run_file"]).name for r in rows]
    assert len(names) == len(set(names)), "a run has two rows"
    return dict(zip(names, rows, strict=True))


def test_batch_through_a_scheduler_address(cluster, tmp_path):
    runs = small_fleet(tmp_path, 4)
    out = tmp_path / "dask"
    p = subprocess.run(
        labrig("batch", "fit", *runs, "--out", out, "--scheduler", cluster.address, "--json"),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert (summary["scheduler"], summary["workers"], summary["succeeded"]) == ("address", 2, 4)
    rows = rows_by_file(out)
    pids = {int(r["worker"].rsplit(":", 1)[1]) for r in rows.values()}
    assert pids == {w.pid for w in cluster.workers}, "both worker processes ran tasks"
    serial = tmp_path / "serial"
    s = subprocess.run(
        labrig("batch", "fit", *runs, "--out", serial, "--serial"),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert s.returncode == 0, s.stderr
    for name, r in rows_by_file(serial).items():
        for col in ("alpha0_ue_per_V", "tau_d_s", "heldout_nrmse_pct", "creep_pct_per_decade"):
            assert rows[name][col] == r[col], (name, col)


def held_by(client, pid: int, timeout_s: float = 300) -> list[str]:
    """The run keys of the tasks the worker process ``pid`` is processing (waits for one)."""
    addr = next(a for a, w in client.scheduler_info()["workers"].items() if w["name"] == "w1")
    assert client.run(os.getpid, workers=[addr])[addr] == pid
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        keys = [str(k) for k in client.processing().get(addr, ())]
        if keys:
            return [k.removeprefix("labrig-fit-").rsplit("-", 1)[0] for k in keys]
        time.sleep(0.05)
    raise AssertionError("the worker never held a task")


def test_a_killed_worker_loses_no_run(cluster, tmp_path):
    from distributed import Client

    runs = small_fleet(tmp_path, 8)
    out = tmp_path / "out"
    batch = subprocess.Popen(
        labrig("batch", "fit", *runs, "--out", out, "--scheduler", cluster.address, "--json"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    victim, survivor = cluster.workers
    try:
        with Client(cluster.address, timeout="30s") as c:
            lost = held_by(c, victim.pid)
            os.kill(victim.pid, signal.SIGKILL)
        victim.wait(timeout=30)
        stdout, stderr = batch.communicate(timeout=600)
    finally:
        if batch.poll() is None:
            batch.kill()
    assert batch.returncode == 0, stderr
    rows = rows_by_file(out)
    assert sorted(rows) == sorted(r.name for r in runs)  # none missing, none doubled
    assert all(r["status"] == "ok" for r in rows.values())
    by_key = {r["key"]: r for r in rows.values()}
    # the task the dead worker held ran again, on the other worker
    assert lost and all(by_key[k]["worker"].endswith(f":{survivor.pid}") for k in lost)
    assert json.loads(stdout)["succeeded"] == len(runs)
