"""Evaluate one function over many items, locally or on a Dask cluster.

One code path for every expensive batch (FEM grids, width sweeps, posterior propagation):

    results = map_evaluations(function, items, scheduler=None)

- ``scheduler=None``: a process pool over the local cores (fork start method where the
  platform has it, so workers start in milliseconds);
- ``scheduler="synchronous"``: in this process, one item after the other (debugging, tests
  that count calls);
- ``scheduler="tcp://host:port"`` (or a ``distributed.Client``): the items run on an existing
  Dask cluster (see ``docs/scaling.md``).

``function`` and the items must be picklable: a module-level function and plain data
(frozen dataclasses are fine).  Results come back in the order of ``items`` and are the
same numbers on every path, since the same function runs on the same inputs.
"""

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterable, List, Optional

from workflow.errors import TactileError
from workflow.execution.memory import keep_freed_memory
from workflow.progress import Progress

SYNCHRONOUS = "synchronous"
"""The ``scheduler`` value that runs every item in the calling process."""

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a Dask scheduler before giving up [s]."""


class SchedulerError(TactileError):
    """The Dask scheduler named by the user cannot be reached or is not an address."""


def local_workers() -> int:
    """Cores this process may run on [-]."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def map_evaluations(
    function: Callable,
    items: Iterable,
    scheduler=None,
    progress: bool = True,
    workers: Optional[int] = None,
    description: str = "evaluations",
) -> List:
    """``[function(item) for item in items]``, in parallel.

    Parameters
    ----------
    function : callable
        A picklable (module-level) function of one item.
    items : iterable
        Picklable inputs.
    scheduler : None, "synchronous", str or distributed.Client
        None: local process pool; "synchronous": in this process; ``"tcp://host:port"``: the
        Dask scheduler of an existing cluster; a ``distributed.Client``: that client.
    progress : bool
        Show the progress on stderr (:class:`~workflow.progress.Progress`: a bar on a terminal,
        plain lines when stderr is piped or logged).
    workers : int, optional
        Local processes (default: the cores available); ignored on a cluster.
    description : str
        Label of the progress.

    Returns
    -------
    list
        The results in the order of ``items``.

    Raises
    ------
    SchedulerError
        When the scheduler address is malformed or unreachable.
    """
    items = list(items)
    with Progress(len(items), description, enabled=progress and bool(items)) as bar:
        if scheduler is None:
            return _process_pool(function, items, workers or local_workers(), bar)
        if scheduler == SYNCHRONOUS:
            return _in_process(function, items, bar)
        return _dask(function, items, scheduler, bar)


def _in_process(function, items, bar):
    results = []
    for item in items:
        results.append(function(item))
        bar.update()
    return results


def _process_pool(function, items, workers, bar):
    if workers <= 1 or len(items) <= 1:
        return _in_process(function, items, bar)
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else None)
    workers = min(workers, len(items))
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_share_cores,
                             initargs=(max(1, local_workers() // workers),)) as pool:
        futures = {pool.submit(function, item): index for index, item in enumerate(items)}
        results = [None] * len(items)
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            bar.update()
    return results


THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""Environment variables through which the BLAS and OpenMP libraries take their thread count when they load."""
_worker_limits = []
"""The thread limits of this worker process (kept so that they hold for its life)."""


def _share_cores(threads: int) -> None:
    """Limit a pool worker's BLAS and OpenMP (MKL, PARDISO) threads to its share of the cores: two workers of two
    threads each on two cores make the FEM's factorisations wait on each other (eight calibration evaluations
    took 40-41 s so, 30-34 s with one thread per worker; docs/scaling.md)."""
    from threadpoolctl import threadpool_limits

    keep_freed_memory()  # inherited from a forked parent that set it; set here for spawned workers
    for name in THREAD_VARIABLES:  # for the libraries this worker loads later (MKL is loaded when first used)
        os.environ[name] = str(threads)
    _worker_limits.append(threadpool_limits(limits=threads))  # for those already loaded


def _dask(function, items, scheduler, bar):
    from distributed import Client

    if isinstance(scheduler, Client):
        return _gather(scheduler, function, items, bar)
    with connect(scheduler) as client:
        return _gather(client, function, items, bar)


def connect(address: str):
    """A ``distributed.Client`` on the scheduler at ``address`` (close it after use).

    Raises
    ------
    SchedulerError
        When ``address`` is not a scheduler address or cannot be reached.
    """
    from distributed import Client

    if not isinstance(address, str) or "://" not in address:
        raise SchedulerError(f"--scheduler {address!r} is not a Dask scheduler address; expected e.g. tcp://host:8786")
    try:
        return Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as error:
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {error}") from None


def _gather(client, function, items, bar):
    """Submit every item, collect in order (the bar advances as the leading results arrive)."""
    futures = client.map(function, items, pure=False)
    results = []
    for future in futures:
        results.append(future.result())
        bar.update()
    return results
