"""One code path for local cores and a Dask cluster, identical numbers."""

import numpy as np
import pytest

from workflow.execution.parallel import THREAD_VARIABLES, SchedulerError, local_workers, map_evaluations


def spectrum(seed):
    """A deterministic numeric task."""
    return np.sort(np.linalg.eigvalsh(np.random.default_rng(seed).normal(size=(30, 30)) + np.eye(30) * seed))


def test_local_pool_and_in_process_agree_in_order():
    items = list(range(6))
    pooled = map_evaluations(spectrum, items, progress=False, workers=2)
    serial = map_evaluations(spectrum, items, scheduler="synchronous", progress=False)
    for a, b in zip(pooled, serial):
        np.testing.assert_array_equal(a, b)
    assert pooled[5][0] != pooled[0][0]


def test_dask_local_cluster_gives_identical_numbers():
    distributed = pytest.importorskip("distributed")
    items = list(range(6))
    local = map_evaluations(spectrum, items, progress=False, workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        by_address = map_evaluations(spectrum, items, scheduler=cluster.scheduler_address, progress=False)
        with distributed.Client(cluster) as client:
            by_client = map_evaluations(spectrum, items, scheduler=client, progress=False)
    for a, b, c in zip(local, by_address, by_client):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


@pytest.mark.parametrize("address", ["not-an-address", "tcp://127.0.0.1:9"])
def test_bad_scheduler_is_a_clear_error(address, monkeypatch):
    monkeypatch.setattr("workflow.execution.parallel.CONNECT_TIMEOUT", 1.0)
    with pytest.raises(SchedulerError, match="Dask scheduler"):
        map_evaluations(spectrum, [1, 2], scheduler=address, progress=False)


def worker_threads(_):
    """The thread settings a pool worker runs with: its environment's and those of the loaded BLAS/OpenMP libraries."""
    import os

    from threadpoolctl import threadpool_info

    return [os.environ.get(name) for name in THREAD_VARIABLES], max(info["num_threads"] for info in threadpool_info())


def test_pool_workers_share_the_cores_instead_of_each_taking_them_all():
    share = max(1, local_workers() // 2)
    for variables, loaded in map_evaluations(worker_threads, [0, 1], workers=2, progress=False):
        assert variables == [str(share)] * len(THREAD_VARIABLES)  # libraries loaded later take it from there
        assert loaded == share
