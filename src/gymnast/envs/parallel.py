"""Run independent episodes in parallel, one process per core, on this machine or a Ray cluster.

MuJoCo stepping and software rendering are single-threaded and CPU-bound, so processes (not
threads) are what scale. The processes are `gymnast.envs.workers.Workers`: spawned here (the
default) or Ray actors, chosen by the runner setting. Each worker keeps its environments between
jobs (`cached_env`), because building a Meta-World scene costs far more than an episode step.

A `parallel_map` starts its processes and stops them when done; inside ``with kept_workers(...)``
every `parallel_map` of this process shares one set of processes instead, started by the first
that needs them. Starting a worker (importing torch and Meta-World, building its scenes) costs
seconds, which adds up over an experiment's dozens of short evaluations.
"""

from __future__ import annotations

import contextlib
import functools
import os
from typing import Any, Callable, Iterable, Iterator, TypeVar

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
    if _kept is not None and _kept.runner == runner:
        yield from _kept.map(fn, items)
        return
    with Workers(runner, min(workers, len(items)), Apply, (fn,)) as pool:
        yield from pool.map("__call__", items)


@contextlib.contextmanager
def kept_workers(workers: int, runner: str = "local") -> Iterator[None]:
    """Within the block, every `parallel_map` on `runner` that runs in parallel uses the same
    `workers` processes (started at the first such call, stopped at the end of the block).

    The processes keep what they cache between calls (scenes, the last policy loaded from a run
    directory), so use it where the runs they read do not change in between, as an experiment's
    evaluations of its finished arms. A call that fails or is stopped early leaves jobs under way;
    the processes are then stopped and the next call starts new ones.
    """
    global _kept
    if _kept is not None:  # nested: the outer block's processes serve
        yield
        return
    _kept = _KeptWorkers(workers, runner)
    try:
        yield
    finally:
        _kept.close()
        _kept = None


class _KeptWorkers:
    """The processes of a `kept_workers` block, hosting `ApplyAny`."""

    def __init__(self, count: int, runner: str) -> None:
        self.count, self.runner = count, runner
        self._pool: Workers | None = None

    def map(self, fn: Callable[[Item], Result], items: list[Item]) -> Iterator[Result]:
        if self._pool is None:
            self._pool = Workers(self.runner, self.count, ApplyAny)
        finished = False
        try:
            yield from self._pool.map("__call__", [(fn, item) for item in items])
            finished = True
        finally:
            if not finished:
                self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None


_kept: _KeptWorkers | None = None


class Apply:
    """What a worker of `parallel_map` hosts: the function it applies to each item."""

    def __init__(self, fn: Callable[[Item], Result]) -> None:
        self._fn = fn

    def __call__(self, item: Item) -> Result:
        return self._fn(item)


class ApplyAny:
    """What a kept worker hosts: it applies whichever function each job brings."""

    def __call__(self, job: tuple[Callable[[Any], Any], Any]) -> Any:
        fn, item = job
        return fn(item)
