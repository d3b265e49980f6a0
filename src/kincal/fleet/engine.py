"""The distributed engine of a fleet: Dask's ``distributed`` runs the units.

Why Dask (measured here, see docs/fleet.md): its ``distributed`` package and its
dependencies install in about 35 MB of pure Python, a LocalCluster of worker processes
starts in about 1 s, and the same Client code runs on a LocalCluster (``--workers N``) or on
any running scheduler (``--scheduler ADDRESS``); tests start a LocalCluster in-process. Ray
would bring a much larger binary install and a slower start for what is here a map over
independent units.

It is an optional dependency (``pip install "kincal[fleet]"``): only ``kincal fleet`` needs it.
"""

from __future__ import annotations

import logging
from typing import Callable, Iterable

from kincal.errors import OptionError

WORKER_MEMORY = "2GiB"  # a local worker's memory limit (Dask pauses, then restarts it beyond)
INSTALL = 'pip install "kincal[fleet]"'


def available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def _client(workers: int, scheduler: str | None):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise OptionError("kincal fleet runs its units on Dask's distributed engine, which "
                          f"is not installed: {INSTALL}") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="10s"), None
        except OSError as e:
            raise OptionError(f"--scheduler {scheduler}: no Dask scheduler answers there "
                              f"({e}); start one (dask scheduler) or use --workers N") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, memory_limit=WORKER_MEMORY,
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


def run(fn: Callable, jobs: Iterable, on_result: Callable, workers: int = 1,
        scheduler: str | None = None, on_error: Callable | None = None) -> None:
    """fn(job) for every job on the engine; on_result(outcome) as each one finishes (in the
    order they finish). An exception a worker raises goes to on_error(job, exc) and the
    others go on. Ctrl-C cancels what is not finished and re-raises."""
    from distributed import as_completed

    jobs = list(jobs)
    client, cluster = _client(workers, scheduler)
    try:
        futures = client.map(fn, jobs, pure=False)
        index = {f.key: j for f, j in zip(futures, jobs)}
        try:
            for f in as_completed(futures):
                if f.status == "error":
                    exc = f.exception()
                    if on_error is None:
                        raise exc
                    on_error(index[f.key], exc)
                else:
                    on_result(f.result())
        except KeyboardInterrupt:
            client.cancel(futures)
            raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def worker_memory(client) -> dict:
    """{worker address: resident memory [bytes]} (for the benchmark)."""
    import psutil

    return client.run(lambda: psutil.Process().memory_info().rss)
