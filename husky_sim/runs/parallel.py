"""One way to run independent episodes in parallel, for the suite and the sweep alike:
`parallel_map` on local worker processes (`process_map`) or on a Dask cluster (`dask_map`).

Local workers are started with `spawn` (CasADi/IPOPT and PyBullet hold threads and native state that
`fork` would copy half-alive) and ignore SIGINT: a Ctrl-C in a terminal reaches the whole process
group, and the parent alone decides. The parent, on a signal (husky_sim.interrupts), cancels what
has not started and sends the workers SIGTERM instead of waiting for their episodes: each ends
the episode in hand as `interrupted` (its summary written) and exits, so a suite ends within a
second too.
Results come back in input order; an item whose worker died (a crash, out of memory) or whose
function raised comes back as the exception, for the caller to report, never as a lost run.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Literal, TypeVar

from husky_sim import interrupts
from husky_sim.extras import missing

T = TypeVar("T")
R = TypeVar("R")

#: Where items run: local worker processes, or a Dask cluster (distributed).
Backend = Literal["local", "dask"]
BACKENDS: tuple[Backend, ...] = ("local", "dask")


def _init_worker() -> None:
    """SIGTERM (the parent stopping the pool) ends the episode in hand as `interrupted`, with its
    summary written; SIGINT is the parent's to handle."""
    interrupts.install()
    interrupts.begin_run()
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _in_worker(fn: Callable[[T], R], item: T) -> R:
    """fn(item) in a worker; a worker whose episode was interrupted exits instead of taking the
    next item from the queue."""
    try:
        return fn(item)
    except interrupts.RunInterrupted as exc:
        os._exit(exc.exit_code)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started, terminate the workers and let the pool's manager thread finish
    (Python 3.11 has no public call; `shutdown` forgets the processes, so they are taken first)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=1.0)
    # the pool's manager thread drops its queues once the workers are gone, and their semaphores
    # are unlinked as it does; a quick exit in the middle of that leaks one (resource_tracker warns)
    if manager is not None:
        manager.join(timeout=0.5)


def process_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    jobs: int,
    on_done: Callable[[int, R | BaseException], None] | None = None,
) -> list[R | BaseException]:
    """fn over items on `jobs` processes (in this process when jobs <= 1 or one item), in item
    order. `on_done(index, result)` is called as each finishes. An exception fn raises, or a
    worker's death, is returned in its item's place (signals, being BaseExceptions, propagate)."""
    results: list[R | BaseException | None] = [None] * len(items)
    if jobs <= 1 or len(items) <= 1:
        for i, item in enumerate(items):
            try:
                results[i] = fn(item)
            except Exception as exc:  # noqa: BLE001 - reported in the item's place, as from a worker
                results[i] = exc
            if on_done is not None:
                on_done(i, results[i])
        return results  # type: ignore[return-value]
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(
        max_workers=min(jobs, len(items)), mp_context=context, initializer=_init_worker
    )
    try:
        futures: dict[Future, int] = {pool.submit(_in_worker, fn, item): i for i, item in enumerate(items)}
        for future in as_completed(futures):
            i = futures[future]
            try:
                results[i] = future.result()
            except Exception as exc:  # noqa: BLE001 - a dead worker (crash, out of memory)
                results[i] = exc
            if on_done is not None:
                on_done(i, results[i])
    except BaseException:  # a signal or an error in on_done: do not wait for running episodes
        _stop_workers(pool)
        raise
    pool.shutdown(wait=True)
    return results  # type: ignore[return-value]


def dask_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    jobs: int,
    scheduler: str | None = None,
    on_done: Callable[[int, R | BaseException], None] | None = None,
) -> list[R | BaseException]:
    """fn over items with distributed.Client.map, with process_map's contract (item order, an
    exception in its item's place): on the cluster at `scheduler`, or on a LocalCluster of `jobs`
    single-threaded worker processes (IPOPT's linear solver is not thread-safe)."""
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise missing("distributed", "cluster", "backend dask") from None
    results: list[R | BaseException | None] = [None] * len(items)
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=max(min(jobs, len(items)), 1),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=40,  # logging.ERROR
        )
    try:
        with Client(cluster if cluster is not None else scheduler) as client:
            futures = client.map(fn, list(items), pure=False)
            index = {future.key: i for i, future in enumerate(futures)}
            for future in as_completed(futures):
                i = index[future.key]
                try:
                    results[i] = future.result()
                except Exception as exc:  # noqa: BLE001 - reported in the item's place
                    results[i] = exc
                if on_done is not None:
                    on_done(i, results[i])
    finally:
        if cluster is not None:
            cluster.close()
    return results  # type: ignore[return-value]


def parallel_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    jobs: int,
    on_done: Callable[[int, R | BaseException], None] | None = None,
    backend: Backend = "local",
    scheduler: str | None = None,
) -> list[R | BaseException]:
    """fn over items on `backend` (process_map or dask_map; `scheduler` is a Dask address)."""
    if backend == "local":
        if scheduler is not None:
            raise ValueError("scheduler: needs backend dask")
        return process_map(fn, items, jobs, on_done)
    if backend == "dask":
        return dask_map(fn, items, jobs, scheduler, on_done)
    raise ValueError(f"backend: must be one of {BACKENDS}, got {backend!r}")
