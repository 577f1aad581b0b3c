"""Worker processes for batches of motions: each motion's projection runs whole in one process.

The tracker is Python at the simulation rate and holds the GIL, and so do retargeting and reference
shaping, so threads gain little on a batch; processes use every core (docs/decisions/projection.md: "worker
processes for a batch of motions"). Results are bit-identical whichever process runs a motion: each is
simulated on its own.

The pool is made on first use and kept, so its start-up (about 1 s) is paid once per Python session.
On Linux it forks, so a user's script needs no ``if __name__ == "__main__"`` guard; elsewhere it uses the
platform's default start method (spawn), with Python's usual requirement of that guard. The
projection's workers run only numpy, scipy and MuJoCo, never torch, so forking a process that has used
torch is safe for them.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

from physmotion.errors import PhysmotionError

T = TypeVar("T")
R = TypeVar("R")

_pool: ProcessPoolExecutor | None = None
_pool_size = 0
_lock = threading.Lock()  # callers on several threads share one pool


def worker_count(requested: int, jobs: int) -> int:
    """Processes to use for ``jobs`` items: ``requested`` (0: one per core), never more than the jobs."""
    return max(1, min(requested or os.cpu_count() or 1, jobs))


def map_in_workers(fn: Callable[[T], R], items: Sequence[T], workers: int = 0) -> list[R]:
    """``[fn(x) for x in items]``, in worker processes when there is more than one item and core.

    ``fn`` must be a module-level function (or a ``functools.partial`` of one) and the items picklable.
    Results come back in input order; an exception raised by ``fn`` is raised here. A worker that dies
    (killed, or crashed in C) raises :class:`PhysmotionError`, and the next call starts a fresh pool.
    """
    n = worker_count(workers, len(items))
    if n == 1 or multiprocessing.current_process().daemon:  # a daemonic process may not have children
        return [fn(x) for x in items]
    try:
        return list(_get_pool(n).map(fn, items))
    except BrokenProcessPool:
        _shutdown()
        raise PhysmotionError("a worker process died (out of memory, or killed); nothing returned") from None


def imap_in_workers(fn: Callable[[T], R], items: Sequence[T], workers: int = 0) -> Iterator[tuple[int, R]]:
    """``(index, fn(item))`` for every item, in the order they finish, in worker processes when there is more
    than one item and core (:func:`map_in_workers`' rules). An exception raised by ``fn`` is raised here
    once the item's turn comes; items finished before it have been yielded. Closing the iterator early
    cancels the items not yet started."""
    n = worker_count(workers, len(items))
    if n == 1 or multiprocessing.current_process().daemon:
        for i, x in enumerate(items):
            yield i, fn(x)
        return
    try:
        pool = _get_pool(n)
        futures = {pool.submit(fn, x): i for i, x in enumerate(items)}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:  # a caller that stops early (an error, a deadline) cancels the items not yet started
            for future in futures:
                future.cancel()
    except BrokenProcessPool:
        _shutdown()
        raise PhysmotionError("a worker process died (out of memory, or killed); what finished is written") from None


def _get_pool(size: int) -> ProcessPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size != size:
            _shutdown_locked()
            method = "fork" if sys.platform.startswith("linux") else None
            _pool = ProcessPoolExecutor(size, mp_context=multiprocessing.get_context(method))
            _pool_size = size
        return _pool


def _shutdown() -> None:
    with _lock:
        _shutdown_locked()


def _shutdown_locked() -> None:
    global _pool, _pool_size
    if _pool is not None:
        _pool.shutdown(wait=False, cancel_futures=True)
    _pool, _pool_size = None, 0
