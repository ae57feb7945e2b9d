"""Run independent episodes in parallel, one process per core, on this machine or a Ray cluster.

MuJoCo stepping and software rendering are single-threaded and CPU-bound, so processes (not
threads) are what scale. The processes are `gymnast.envs.workers.Workers`: spawned here (the
default) or Ray actors, chosen by the runner setting. Each worker keeps its environments between
jobs (`cached_env`), because building a Meta-World scene costs far more than an episode step.
"""

from __future__ import annotations

import functools
import os
from typing import Callable, Iterable, Iterator, TypeVar

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.workers import Workers

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


def parallel_map(fn: Callable[[Item], Result], items: Iterable[Item], workers: int,
                 runner: str = "local") -> Iterator[Result]:
    """Yields ``fn(item)`` for every item, in completion order, each exactly once.

    An item whose worker dies is rerun on a new worker (see `gymnast.envs.workers.Workers.map`).

    Args:
        fn: a picklable (module-level) function.
        items: picklable job descriptions.
        workers: processes to use; 1 runs everything in this process.
        runner: where the processes run: local, ray or ray:ADDRESS (`gymnast.envs.workers.parse_runner`).
    """
    items = list(items)
    if workers <= 1 or len(items) <= 1:
        yield from map(fn, items)
        return
    with Workers(runner, min(workers, len(items)), Apply, (fn,)) as pool:
        yield from pool.map("__call__", items)


class Apply:
    """What a worker of `parallel_map` hosts: the function it applies to each item."""

    def __init__(self, fn: Callable[[Item], Result]) -> None:
        self._fn = fn

    def __call__(self, item: Item) -> Result:
        return self._fn(item)
