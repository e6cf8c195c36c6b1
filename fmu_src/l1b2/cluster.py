"""The parallel engine: tasks on a Dask distributed cluster, or serially in this process.

One engine serves the rig's parallel runs (:func:`l1b2.rig.experiment.run_experiment`)
and the design studies (:mod:`l1b2.sweep`):

* :func:`dask_client` opens a client: by default on a ``LocalCluster`` of
  ``workers`` processes with **one thread each** (a PythonFMU FMU embeds a
  Python interpreter and is not thread-safe, and the physics holds the GIL
  anyway), or on an existing cluster given by its scheduler address
  (``tcp://host:8786``; start it with ``dask-scheduler`` and ``dask-worker``
  on machines that have this package installed). It checks that the workers
  run the same ``l1b2`` version as this process.
* :func:`run_tasks` runs ``fn(*args)`` for every argument tuple and yields
  ``(index, result)`` as tasks finish. With no client the tasks run here, in
  order (the serial reference). A task whose worker dies (killed, crashed) is
  rescheduled by Dask on another worker, up to Dask's
  ``distributed.scheduler.allowed-failures``; a task that raises is retried
  ``retries`` times and then its exception is raised here. Results carry
  their index, so callers that order by it get the same answer whatever the
  number of workers.

Imports only :mod:`l1b2.errors` (and Dask, lazily): every layer above may use it.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from . import __version__
from .errors import ClusterError


def default_workers() -> int:
    """Worker processes of the default ``LocalCluster``: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def package_version() -> str:
    """The ``l1b2`` version of the process this runs in (called on the workers)."""
    return __version__


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None):
    """A Dask ``Client``: on an existing cluster (``scheduler``) or on a new local one.

    Parameters
    ----------
    workers : worker processes of the local cluster (default :func:`default_workers`);
        ignored with ``scheduler``
    scheduler : address of a running Dask scheduler, e.g. ``"tcp://10.0.0.5:8786"``

    Raises
    ------
    ClusterError
        The scheduler cannot be reached, has no workers, or its workers run
        another version of ``l1b2`` (or do not have it installed).
    """
    import dask
    from dask.distributed import Client, LocalCluster
    with dask.config.set(QUIET_DASK), _quiet_loggers():
        yield from _client(Client, LocalCluster, workers, scheduler)


#: Dask settings for a busy machine: the engine's own logs only when fatal, no "event loop unresponsive"
#: warnings, and time-outs long enough that a loaded machine's slow heartbeat is not reported as a failure
#: (each with a traceback, from every worker) while the tasks go on. Task errors still reach the caller.
QUIET_DASK = {"distributed.admin.tick.limit": "60s", "distributed.comm.timeouts.connect": "60s",
              "distributed.comm.timeouts.tcp": "120s", "distributed.scheduler.worker-ttl": "15 minutes"}


@contextlib.contextmanager
def _quiet_loggers(level: int = logging.CRITICAL):
    """The ``distributed`` loggers of this process at ``level`` for the block (restored after)."""
    names = ("distributed", "distributed.worker", "distributed.nanny", "distributed.scheduler", "distributed.core",
             "distributed.comm", "distributed.client", "tornado")
    loggers = [logging.getLogger(n) for n in names]
    before = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(level)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, before):
            lg.setLevel(lv)


def _client(Client, LocalCluster, workers, scheduler):
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout="15s")
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
    else:
        n = int(workers) if workers is not None else default_workers()
        if n < 1:
            raise ClusterError(f"--workers must be at least 1 for a local cluster, got {n}")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
        client = Client(cluster)
    try:
        if scheduler:
            _check_workers(client, scheduler)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextlib.contextmanager
def optional_client(workers: int | None, scheduler: str | None = None, *, serial_up_to: int = 0):
    """:func:`dask_client` when ``scheduler`` is given or ``workers`` exceeds ``serial_up_to``; else ``None``.

    ``None`` means: run in this process. The callers' rule in one place: a sweep
    with ``workers=0`` runs in process (``serial_up_to=0``); the close-loop refits
    with 0 or 1 workers too (``serial_up_to=1``: one worker process is slower than none).
    ``workers=None`` means :func:`default_workers`.
    """
    n = default_workers() if workers is None else int(workers)
    if scheduler is None and n <= serial_up_to:
        yield None
        return
    with dask_client(n, scheduler) as client:
        yield client


def _check_workers(client, scheduler: str) -> None:
    try:
        client.wait_for_workers(1, timeout=30)
    except TimeoutError:
        raise ClusterError(f"--scheduler {scheduler}: no worker joined within 30 s "
                           f"(start `dask worker {scheduler} --nthreads 1` on machines with l1b2 installed)") from None
    try:
        versions = client.run(package_version)
    except Exception as exc:  # noqa: BLE001 - a worker without the package fails to unpickle the call
        raise ClusterError(f"--scheduler {scheduler}: a worker cannot run l1b2 ({type(exc).__name__}: {exc}); "
                           f"install this package on every worker machine") from None
    other = {w: v for w, v in versions.items() if v != __version__}
    if other:
        w, v = next(iter(other.items()))
        raise ClusterError(f"--scheduler {scheduler}: worker {w} runs l1b2 {v}, this process {__version__}")


def run_tasks(fn: Callable[..., Any], arglists: Sequence[tuple], *, client=None, retries: int = 1,
              name: str = "l1b2") -> Iterator[tuple[int, Any]]:
    """Run ``fn(*args)`` for every tuple of ``arglists``; yield ``(index, result)`` as tasks finish.

    With ``client=None`` the tasks run in this process, in order. On a
    cluster, every task is submitted at once (Dask balances them over the
    workers); closing the generator early (an interrupt) cancels the tasks
    not yet finished.
    """
    if client is None:
        for i, args in enumerate(arglists):
            yield i, fn(*args)
        return
    from dask.distributed import as_completed
    from distributed.scheduler import KilledWorker
    futures, index = [], {}
    for i, args in enumerate(arglists):
        fut = client.submit(fn, *args, key=f"{name}-{i}-{os.urandom(6).hex()}", retries=retries, pure=False)
        futures.append(fut)
        index[fut.key] = i
    try:
        for fut in as_completed(futures):
            try:
                result = fut.result()
            except KilledWorker as exc:
                raise ClusterError(f"{name} task {index[fut.key]} killed every worker it ran on ({exc}); "
                                   f"giving up") from None
            yield index[fut.key], result
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
