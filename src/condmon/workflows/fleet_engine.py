"""The engine of a fleet run: a dask.distributed cluster, and records sent through it.

This module holds :func:`local_cluster` (worker processes that ignore Ctrl-C,
their logs silenced), the connection to an existing scheduler, and
:func:`_run_tasks`, which keeps a few records per worker queued and yields
their outcomes as they come back. It also holds the SIGINT guards a run uses
so that a Ctrl-C never cuts a transaction or a cluster's shutdown in two.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError, ConfigError
from condmon.io.raw import one_line
from condmon.workflows.fleet_work import RecordOutcome, RecordTask, _named, process_records

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["EngineError", "BLAS_ENV", "local_cluster", "chunk_size", "MAX_CHUNK"]

#: Environment of a local cluster's workers: one BLAS thread per worker process.
BLAS_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class EngineError(CondmonError, RuntimeError):
    """The distributed engine cannot be started or reached."""



@contextmanager
def _sigint_held() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) back while the block runs, raising it as
    KeyboardInterrupt when the block ends (a transaction, a cluster's
    shutdown are never cut in two)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    hit: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: hit.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old if old is not None else signal.default_int_handler)
        if hit:
            raise KeyboardInterrupt


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while the block runs: processes started in it ignore it for
    good (the disposition is inherited), so a Ctrl-C sent to the whole process
    group, as a terminal does, stops the client alone, which then shuts its
    workers down in order. A Ctrl-C meanwhile is lost."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old if old is not None else signal.default_int_handler)


#: Level of the ``distributed`` loggers (client, nanny, workers) of a local
#: cluster: above CRITICAL, as a record's failure is its outcome and a
#: cluster's shutdown after Ctrl-C is no news.
QUIET = logging.CRITICAL + 10


@contextmanager
def local_cluster(workers: int | None = None) -> Iterator[Client]:
    """A dask.distributed client of a local cluster: ``workers`` processes
    (default: the machine's cores), one thread each, BLAS limited to one
    thread (:data:`BLAS_ENV`); its HTTP endpoints on a free port (never the
    dashboard's 8787, which another cluster may hold); its logs silenced; shut
    down when the block ends.

    Its worker processes ignore SIGINT, so a Ctrl-C sent to the whole process
    group (as a terminal does) stops the client alone; a Ctrl-C while the
    cluster starts is ignored, and one while it shuts down is raised once it
    is down.

    Example
    -------
    >>> with local_cluster(1) as client:                       # doctest: +SKIP
    ...     client.submit(process_record, task).result()
    """
    from distributed import Client, LocalCluster

    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise ConfigError(f"workers must be >= 1, got {n}")
    import dask

    # dask gives its workers MALLOC_TRIM_THRESHOLD_=65536 (long-lived workers hand
    # memory back); setting it turns off glibc's adaptive mmap threshold, so every
    # array over 128 KB (a record's columns) is a fresh mmap: ~35 % slower
    # estimates. These workers live for one run: glibc's default is kept.
    spawn_env = {k: v for k, v in
                 dict(dask.config.get("distributed.nanny.pre-spawn-environ", {})).items()
                 if k != "MALLOC_TRIM_THRESHOLD_"}
    with _sigint_ignored(), dask.config.set({"distributed.nanny.pre-spawn-environ": spawn_env}):
        try:
            cluster = LocalCluster(n_workers=n, threads_per_worker=1,  # type: ignore[no-untyped-call]
                                   processes=True, dashboard_address=":0",
                                   silence_logs=QUIET, env=dict(BLAS_ENV))
        except (OSError, RuntimeError, TimeoutError) as exc:
            raise EngineError(f"cannot start a local cluster of {n} worker(s): "
                              f"{one_line(exc, None)}") from None
        client = Client(cluster, set_as_default=False)  # type: ignore[no-untyped-call]
    try:
        yield client
    finally:
        with _sigint_held():
            client.close()  # type: ignore[no-untyped-call]
            cluster.close()


def _connect(scheduler: str) -> Client:
    """A client of an existing scheduler; a client that fails to connect is
    marked closed at once (else its finaliser waits 20 s for a loop that has
    stopped and prints a TimeoutError at exit)."""
    from distributed import Client

    class _Client(Client):
        def start(self, **kwargs: Any) -> None:
            try:
                super().start(**kwargs)  # type: ignore[no-untyped-call]
            except BaseException:
                self.status = "closed"
                self._loop_runner.stop()  # type: ignore[no-untyped-call]
                raise

    try:
        return _Client(scheduler, set_as_default=False, timeout="10s")  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError, ValueError) as exc:
        raise EngineError(f"cannot reach the scheduler {scheduler!r}: {one_line(exc, None)}") from None


@contextmanager
def _engine(workers: int | None, scheduler: str | None) -> Iterator[Client]:
    if scheduler is None:
        with local_cluster(workers) as client:
            yield client
        return
    with _connect(scheduler) as client:
        yield client


def _threads(client: Client) -> int:
    """Worker threads of the cluster."""
    return sum(client.nthreads().values())  # type: ignore[no-untyped-call]


#: Records per unit of work at most: enough to share the engine's cost per
#: task (a few ms of the client's and scheduler's CPU, which on a small
#: machine is taken from the workers), few enough to balance the workers.
MAX_CHUNK = 8


def chunk_size(records: int, workers: int) -> int:
    """Records per task: at least 8 tasks per worker, at most :data:`MAX_CHUNK` records each.

    Example
    -------
    >>> chunk_size(23, 1), chunk_size(1000, 2), chunk_size(100, 2)
    (2, 8, 6)
    """
    return max(1, min(MAX_CHUNK, records // (8 * max(1, workers))))


def _run_tasks(client: Client, tasks: Sequence[RecordTask],
               chunk: int | None = None) -> Iterator[RecordOutcome]:
    """Outcomes as workers finish them, a bounded number of tasks queued at a
    time (a unit's records finish close together), ``chunk`` records per task
    (default :func:`chunk_size`). The queue holds more work than the client's
    longest commit takes (a batch of results written while no task is
    submitted), so the workers never wait on the database."""
    from distributed import as_completed

    threads = _threads(client)
    size = chunk or chunk_size(len(tasks), threads)
    chunks = [tuple(tasks[i:i + size]) for i in range(0, len(tasks), size)]
    window = max(2, max(64, 16 * threads) // size)
    todo = iter(chunks)
    by_future: dict[Any, tuple[RecordTask, ...]] = {}
    running = as_completed(loop=client.loop)  # type: ignore[no-untyped-call]

    def submit(part: tuple[RecordTask, ...]) -> None:
        fut = client.submit(process_records, part, pure=False)
        by_future[fut] = part
        running.add(fut)  # type: ignore[no-untyped-call]

    for part in todo:
        submit(part)
        if len(by_future) >= window:
            break
    for fut in running:
        part = by_future.pop(fut)
        try:
            outcomes = list(fut.result())
        except Exception as exc:  # noqa: BLE001 - a worker lost, a task cancelled
            outcomes = [RecordOutcome(task.unit, task.path, error=_named(
                task.path, f"not processed: {type(exc).__name__}: {exc}")) for task in part]
        fut.release()
        nxt = next(todo, None)
        if nxt is not None:
            submit(nxt)
        yield from outcomes
