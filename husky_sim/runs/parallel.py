"""One way to run independent episodes on local worker processes (the suite and the sweep).

Workers are started with `spawn` (CasADi/IPOPT and PyBullet hold threads and native state that
`fork` would copy half-alive) and ignore SIGINT: a Ctrl-C in a terminal reaches the whole process
group, and the parent alone decides. The parent, on a signal (husky_sim.interrupts), cancels what
has not started and sends the workers SIGTERM instead of waiting for their episodes: each ends
the episode in hand as `interrupted` (its summary written) and exits, so a suite ends within a
second too.
Results come back in input order; an item whose worker died (a crash, out of memory) comes back
as the exception, for the caller to report, never as a lost run.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import TypeVar

from husky_sim import interrupts

T = TypeVar("T")
R = TypeVar("R")


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
    """Cancel what has not started and terminate the workers (Python 3.11 has no public call;
    `shutdown` forgets the processes, so they are taken first)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=1.0)


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
