"""The worker pool that projects the motions of a batch in parallel processes."""

from __future__ import annotations

import os

import pytest

from physmotion.errors import PhysmotionError
from physmotion.physics.workers import map_in_workers, worker_count


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def _die(x: int) -> int:
    os._exit(3)  # a worker killed mid-task, as by the out-of-memory killer


def test_worker_count_never_exceeds_the_jobs() -> None:
    assert worker_count(0, 1) == 1
    assert worker_count(4, 2) == 2
    assert worker_count(1, 16) == 1
    assert worker_count(0, 1000) == (os.cpu_count() or 1)


def test_results_come_back_in_order_from_other_processes() -> None:
    out = map_in_workers(_square_and_pid, list(range(12)), workers=2)
    assert [v for v, _ in out] == [x * x for x in range(12)]
    assert os.getpid() not in {pid for _, pid in out}
    # One worker: everything runs here.
    assert {pid for _, pid in map_in_workers(_square_and_pid, [1, 2], workers=1)} == {os.getpid()}


def test_a_dead_worker_is_one_clear_error_and_the_next_call_works() -> None:
    with pytest.raises(PhysmotionError, match="worker process died"):
        map_in_workers(_die, [1, 2], workers=2)
    assert [v for v, _ in map_in_workers(_square_and_pid, [3, 4], workers=2)] == [9, 16]


def _map_from_a_daemon(x: int) -> list[int]:
    return [pid for _, pid in map_in_workers(_square_and_pid, [x, x + 1], workers=2)]


def test_inside_a_daemonic_worker_everything_runs_in_that_worker() -> None:
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:  # multiprocessing.Pool's workers are daemons
        pids = pool.map_async(_map_from_a_daemon, [1]).get(timeout=60)[0]  # without the check: a hang
    assert len(set(pids)) == 1 and os.getpid() not in pids


def test_callers_on_several_threads_share_the_pool() -> None:
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(4) as threads:
        results = list(threads.map(lambda k: map_in_workers(_square_and_pid, [k, k + 1, k + 2], 2), range(8)))
    assert [[v for v, _ in r] for r in results] == [[k * k, (k + 1) ** 2, (k + 2) ** 2] for k in range(8)]
    assert len({pid for r in results for _, pid in r}) <= 2  # one pool of two workers served them all


def _sleep_and_mark(job: tuple[str, int]) -> int:
    import time
    from pathlib import Path

    folder, x = job
    time.sleep(0.2)
    (Path(folder) / f"{x}.done").touch()
    return x


def test_stopping_early_cancels_the_items_not_started(tmp_path) -> None:
    import time

    from physmotion.physics.workers import imap_in_workers

    items = [(str(tmp_path), x) for x in range(40)]
    for _ in imap_in_workers(_sleep_and_mark, items, workers=2):
        break  # a caller past its deadline
    # Long enough for all 40 to finish (40 x 0.2 s on 2 workers) had they not been cancelled; what had
    # started finishes too, more of it on a loaded machine (7 were seen under the test suite).
    time.sleep(4.5)
    done = len(list(tmp_path.glob("*.done")))
    assert 1 <= done <= 12, done  # 40 would mean every queued item ran anyway
    # the pool still works
    assert [v for v, _ in map_in_workers(_square_and_pid, [5, 6], workers=2)] == [25, 36]
