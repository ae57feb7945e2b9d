"""Run independent episodes in parallel, one process per core.

MuJoCo stepping and software rendering are single-threaded and CPU-bound, so processes (not
threads) are what scale. Workers are started with ``spawn``: forking a process that already holds
a GL context is unsafe. Each worker keeps its environments between jobs, because building a
Meta-World scene costs far more than an episode step.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Callable, Iterable, Iterator, TypeVar

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv

Item = TypeVar("Item")
Result = TypeVar("Result")


@functools.lru_cache(maxsize=16)
def cached_env(
    task: str,
    config: EnvConfig,
    gap: str = "none",
    perturbation: str = "none",
    instruction_split: str = "train",
) -> MetaWorldEnv:
    """This process's environment for the arguments, built once and reused across episodes."""
    return MetaWorldEnv(task, config, gap=gap, perturbation=perturbation, instruction_split=instruction_split)


def default_workers() -> int:
    """One worker per available core."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def parallel_map(fn: Callable[[Item], Result], items: Iterable[Item], workers: int) -> Iterator[Result]:
    """Yields ``fn(item)`` for every item, in completion order.

    Args:
        fn: a picklable (module-level) function.
        items: picklable job descriptions.
        workers: processes to use; 1 runs everything in this process.
    """
    items = list(items)
    if workers <= 1 or len(items) <= 1:
        yield from map(fn, items)
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(workers, len(items)), mp_context=context) as pool:
        # Keep only a few jobs queued per worker, so an interrupted run has little in flight.
        pending = iter(items)
        running = {pool.submit(fn, item) for item in _take(pending, 2 * workers)}
        while running:
            done, running = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                yield future.result()
            running |= {pool.submit(fn, item) for item in _take(pending, len(done))}


def _take(iterator: Iterator[Item], n: int) -> list[Item]:
    return [item for _, item in zip(range(n), iterator)]
