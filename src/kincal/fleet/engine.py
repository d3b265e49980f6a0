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

import asyncio
import contextlib
import functools
import logging
import signal
import threading
from typing import Callable, Iterable

from kincal.errors import OptionError

WORKER_MEMORY = "2GiB"  # a local worker's memory limit (Dask pauses, then restarts it beyond)
INSTALL = 'pip install "kincal[fleet]"'
MAX_BATCH = 8  # units per task at most
TASKS_PER_WORKER = 4  # tasks per worker at least, when there are units enough
CONNECT_TIMEOUT = 10.0  # [s] for a --scheduler to answer Dask's handshake


async def _handshake(address: str) -> None:
    """Connect to ``address`` and exchange Dask's handshake, within CONNECT_TIMEOUT in all.
    Dask's own connect bounds only the TCP connection, not the handshake after it: a
    server that accepts and never answers (a web server, the dashboard's port) made the
    Client wait forever, and one that answers other bytes failed deep in Dask (a
    malformed address too) with a traceback."""
    from distributed.comm import connect

    comm = await asyncio.wait_for(connect(address, timeout=CONNECT_TIMEOUT), CONNECT_TIMEOUT)
    await comm.close()


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
            asyncio.run(_handshake(scheduler))
            return Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s"), None
        except Exception as e:  # noqa: BLE001 - whatever the address gave, one line naming it
            reason = (f"no answer to Dask's handshake within {CONNECT_TIMEOUT:g} s"
                      if isinstance(e, asyncio.TimeoutError) else str(e)
                      if isinstance(e, (OSError, ValueError))  # refused, malformed address
                      else f"what answered is not a Dask scheduler: {type(e).__name__}: {e}")
            raise OptionError(f"--scheduler {scheduler}: no Dask scheduler answers there "
                              f"({reason}); expected the address of a running scheduler "
                              "(tcp://HOST:8786, as dask scheduler prints it), or use "
                              "--workers N") from None
    # the workers print nothing of the engine's own: a failure reaches the command through
    # the tasks' results, which it reports itself, and after Ctrl-C a busy worker's heartbeat
    # logged the closed scheduler with a traceback below the command's one line
    with _workers_ignore_sigint():
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", memory_limit=WORKER_MEMORY,
                               silence_logs=logging.CRITICAL)
    return Client(cluster), cluster


@contextlib.contextmanager
def _workers_ignore_sigint():
    """Start worker processes that ignore SIGINT. Ctrl-C in a terminal reaches every process
    of the foreground group: the command (which cancels the run and closes the cluster) and
    its local workers, which would otherwise die mid-unit printing tracebacks. An ignored
    signal stays ignored across the spawn's exec (Python then installs no handler of its
    own); the command's own handler is back once the workers are up (a Ctrl-C during those
    ~1 s of start-up is lost)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


class Engine:
    """The engine of one fleet run: a client of a LocalCluster of ``workers`` processes, or
    of the scheduler at ``scheduler``; one for every round of the fleet (workers start, and
    import kincal and load the robot, once). A context manager: the cluster closes on exit."""

    def __init__(self, workers: int = 1, scheduler: str | None = None):
        self.client, self.cluster = _client(workers, scheduler)

    def __enter__(self) -> "Engine":
        return self

    def __exit__(self, kind, value, tb) -> None:
        if kind is not None and not issubclass(kind, Exception):
            _quiet_engine_logs()  # Ctrl-C or SIGTERM
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def n_workers(self) -> int:
        return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))

    def run(self, fn: Callable, jobs: Iterable, on_result: Callable,
            on_error: Callable | None = None, batch: int | None = None) -> None:
        """fn(job) for every job; on_result(outcome) as each one finishes (in the order they
        finish; the units of one task together). An exception fn raises goes to
        on_error(job, exc) and the others go on. Ctrl-C cancels what is not finished and
        re-raises. batch: jobs per task (None: :func:`batch_size`)."""
        from distributed import as_completed

        jobs = list(jobs)
        size = batch or batch_size(len(jobs), self.n_workers())
        chunks = [jobs[i:i + size] for i in range(0, len(jobs), size)]
        futures = self.client.map(functools.partial(_each, fn), chunks, pure=False)
        index = {f.key: c for f, c in zip(futures, chunks)}
        try:
            for f in as_completed(futures):
                if f.status == "error":  # the task itself failed (a worker lost, ...)
                    got = [(False, f.exception())] * len(index[f.key])
                else:
                    got = f.result()
                for job, (ok, value) in zip(index[f.key], got):
                    if ok:
                        on_result(value)
                    elif on_error is None:
                        raise value
                    else:
                        on_error(job, value)
        except BaseException as exc:  # Ctrl-C or SIGTERM: cancel what is not finished
            if not isinstance(exc, Exception):
                _quiet_engine_logs()
                self.client.cancel(futures)
            raise
        finally:  # released here, where a Ctrl-C raises: left to Future.__del__ at the return,
            for f in futures:  # the release met a Ctrl-C there and Python dropped it
                f.release()  # ("Exception ignored in ... __del__"): the run went on, exit 0


def _quiet_engine_logs() -> None:
    """Silence the engine's loggers (distributed, tornado, asyncio and their children, some
    of which set levels of their own) from here on: after Ctrl-C or SIGTERM the cancelled
    tasks make the engine's event loop log errors of its own on the way down and after the
    command's last line (distributed's cancel callback has raised a NameError there), and
    the command's one line says what is complete. The process is ending."""
    engine = ("distributed", "tornado", "asyncio")
    for name in [*engine, *logging.root.manager.loggerDict]:
        if name.split(".")[0] in engine:
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def batch_size(n_jobs: int, n_workers: int) -> int:
    """Jobs per task: enough to spread the Dask overhead of a task (measured in docs/fleet.md:
    ~15 ms of CPU between the command and the worker against ~50 ms for a unit), few
    enough that every worker gets TASKS_PER_WORKER tasks (balance) and progress moves."""
    return max(1, min(MAX_BATCH, n_jobs // (TASKS_PER_WORKER * n_workers)))


def _each(fn: Callable, jobs: list) -> list:
    """fn over one task's jobs on a worker: (True, outcome) or (False, exception) each."""
    out = []
    for job in jobs:
        try:
            out.append((True, fn(job)))
        except Exception as e:  # noqa: BLE001 - reported per job, the others go on
            out.append((False, e))
    return out
