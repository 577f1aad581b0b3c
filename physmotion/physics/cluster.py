"""Ray beyond one machine: P's motions as Ray tasks, one CPU each (docs/cluster.md says how to run a cluster).

Ray is an optional extra (``pip install physmotion[ray]``); without it, local worker processes do the same
work (:func:`physmotion.physics.workers.imap_in_workers`). A task returns what it wrote; a task whose worker
dies loses its motion only, and the caller's re-run skips what is written.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING, TypeVar

from physmotion.errors import PhysmotionError

if TYPE_CHECKING:
    from physmotion.physics.projection import ProjectionConfig

T = TypeVar("T")
R = TypeVar("R")


@contextmanager
def ray_session(address: str = "local") -> Iterator[None]:
    """Ray for the block: "local" starts one on this machine (every core), any other value joins a running
    cluster ("auto", "ray://host:10001", "host:6379"). A session this started is stopped after; one already
    running is left as it was, so :func:`map_on_ray` calls inside the block share it."""
    try:
        import ray
    except ImportError:
        raise PhysmotionError("--ray needs Ray: pip install 'physmotion[ray]' (or use --workers N)") from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=None if address == "local" else address, include_dashboard=False,
                     log_to_driver=False, logging_level="WARNING")  # fmt: skip
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise PhysmotionError(f"cannot reach a Ray cluster at {address!r}: {e}") from None
    try:
        yield
    finally:
        if started:
            ray.shutdown()


def map_on_ray(fn: Callable[[T], R], items: Sequence[T], address: str = "local") -> Iterator[tuple[int, R]]:
    """``(index, fn(item))`` for every item, in the order they finish, as Ray tasks of one CPU each, in a
    :func:`ray_session` at ``address``. ``fn`` and the items must pickle (cloudpickle: a module-level
    function or a partial of one)."""
    with ray_session(address):
        import ray

        task = ray.remote(num_cpus=1, max_retries=1)(_call)  # a partial is no function to Ray: wrap it
        pending = {task.remote(fn, x): i for i, x in enumerate(items)}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            ref = done[0]
            index = pending.pop(ref)
            try:
                value = ray.get(ref)
            except ray.exceptions.RayTaskError as e:  # the task's own exception, as a local run raises it
                raise e.as_instanceof_cause() from None
            yield index, value


def one_core(config: ProjectionConfig) -> ProjectionConfig:
    """P's ``config`` for a task of one CPU: the search's rollout threads (one per core by default) at one."""
    if config.controller == "search" and not config.search.threads:
        return replace(config, search=replace(config.search, threads=1), workers=1)
    return config


def _call(fn: Callable[[T], R], item: T) -> R:
    return fn(item)
