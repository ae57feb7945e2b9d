"""Run independent episodes in parallel, one process per core.

MuJoCo stepping and software rendering are single-threaded and CPU-bound, so processes (not
threads) are what scale. Workers are started with ``spawn``: forking a process that already holds
a GL context is unsafe. Each worker keeps its environments between jobs, because building a
Meta-World scene costs far more than an episode step. Workers never outlive their parent
(`exit_with_parent`), even when it is killed with SIGKILL and has no chance to stop them.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import threading
import time
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


PARENT_CHECK_S = 0.5
"""How often a worker checks that its parent is still alive."""


def exit_with_parent(parent: int) -> None:
    """Ends this worker process as soon as process `parent` is gone.

    Called first thing in a worker. A killed parent cannot stop its workers, and each holds a
    Meta-World scene and often a model (over a GB), so a watchdog thread polls the parent's pid:
    once the worker has been re-parented, it exits at once, without cleanup (its parent's files are
    written atomically, so nothing is left half-written).
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


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
    with ProcessPoolExecutor(max_workers=min(workers, len(items)), mp_context=context,
                             initializer=exit_with_parent, initargs=(os.getpid(),)) as pool:
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
