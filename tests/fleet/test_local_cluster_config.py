"""The LocalCluster a batch starts: its workers' environment without glibc's trim threshold
(which pins the mmap threshold and made every large NumPy temporary a fresh, zeroed mapping),
the thread limits Dask's nannies set kept; the profiler off. The first test reads the
environment a nanny would give its worker from the configuration (fast); the second starts a
LocalCluster of one worker through the batch's own code and asks the worker (``cluster``)."""

from __future__ import annotations

import importlib.util
import os
from contextlib import ExitStack

import pytest

if importlib.util.find_spec("distributed") is None:  # found, not imported: importing
    # it costs every test process about half a second of collection
    pytest.skip("needs distributed (the fleet extra)", allow_module_level=True)


def test_nanny_environment_has_no_trim_threshold() -> None:
    import dask
    from distributed.nanny import _get_env_variables

    from labrig.fleet.schedule import LOCAL_CLUSTER_CONFIG

    key = "distributed.nanny.pre-spawn-environ"
    assert "MALLOC_TRIM_THRESHOLD_" in _get_env_variables(key)  # Dask's default sets it
    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        env = _get_env_variables(key)
        assert "MALLOC_TRIM_THRESHOLD_" not in env
        assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == "1"
        assert dask.config.get("distributed.worker.profile.enabled") is False


@pytest.mark.cluster
@pytest.mark.timeout(300)
def test_local_cluster_workers_run_without_trim_threshold() -> None:
    from labrig.fleet.schedule import Where, cluster_client

    def worker_env() -> tuple[str | None, str | None, bool]:
        import dask

        return (
            os.environ.get("MALLOC_TRIM_THRESHOLD_"),
            os.environ.get("OPENBLAS_NUM_THREADS"),
            bool(dask.config.get("distributed.worker.profile.enabled")),
        )

    with ExitStack() as stack:
        client = cluster_client(Where("local", workers=1), stack)
        (got,) = client.run(worker_env).values()
    assert got == (None, "1", False)
