"""Worker processes, each hosting one object and answering calls on it: spawned here, or Ray actors.

Every parallel job in the project runs through `Workers`: `gymnast.envs.parallel.parallel_map`
(evaluation, collection, the gap report) hands independent jobs to whichever worker is free, and
`gymnast.envs.sim_vector.SimVectorEnv` (RL rollouts in the real world or the simulator) calls its
workers in lockstep. Where the processes run is the *runner*, a setting parsed by `parse_runner`:

- ``local`` (the default): processes spawned on this machine (`gymnast.envs.local_workers`),
  which never outlive their parent.
- ``ray``: Ray actors (`gymnast.envs.ray_workers`), on a Ray instance started on this machine, or
  on the cluster named by ``RAY_ADDRESS``; ``ray:ADDRESS`` joins the cluster at ADDRESS. Ray is
  imported only then, so everything else works without it installed.

The two differ only in how a worker is started, called and waited for; scheduling, error
reporting and recovery are this module's, shared. A worker whose process dies (killed, out of
memory, its machine lost) is replaced by a new one and `Workers.map` reruns the job it held, so
every job's result is yielded exactly once. That is sound because the jobs here are episodes,
deterministic given their (task, seed): a rerun returns what the lost run would have.
"""

from __future__ import annotations

import collections
import functools
import importlib.util
import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, Self

from gymnast.envs.local_workers import LocalBackend
from gymnast.envs.worker_calls import WorkerDied

logger = logging.getLogger(__name__)

MAX_ATTEMPTS = 3
"""Workers a job may lose before `Workers.map` gives up on it (a job that kills every worker it
runs on would otherwise be retried forever)."""


@dataclass(frozen=True)
class Runner:
    """Where workers run: spawned processes here, or Ray actors (at `address`, or Ray's default)."""

    ray: bool = False
    address: str | None = None


def parse_runner(spec: str) -> Runner:
    """The runner a ``--runner`` setting names: ``local``, ``ray`` or ``ray:ADDRESS``.

    Raises:
        ValueError: `spec` is none of these.
        ModuleNotFoundError: a Ray runner, and Ray is not installed.
    """
    if spec == "local":
        return Runner()
    if spec != "ray" and not (spec.startswith("ray:") and spec[len("ray:"):]):
        raise ValueError(f"runner must be local, ray or ray:ADDRESS (e.g. ray:auto, ray:ray://head:10001), got {spec!r}")
    if importlib.util.find_spec("ray") is None:
        raise ModuleNotFoundError(f"runner {spec!r} needs Ray: pip install 'world-gymnast[ray]' (or use runner local)")
    return Runner(ray=True, address=spec[len("ray:"):] or None)


class Worker(Protocol):
    """One worker process hosting an object: one call at a time, started by `call`, ended by `result`."""

    def call(self, method: str, args: tuple[Any, ...]) -> None:
        """Starts ``hosted.method(*args)``."""

    def result(self) -> Any:
        """Waits for the started call's return value; raises its exception, or `WorkerDied`."""

    def pid(self) -> int:
        """The worker's process id (on its own machine)."""

    def close(self) -> None:
        """Stops the worker, at once if it is busy."""


class Backend(Protocol):
    """How workers of one runner are started and waited for."""

    def start(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> Worker:
        """A new worker hosting ``factory(*args)``."""

    def wait(self, workers: Sequence[Worker]) -> list[int]:
        """Blocks until at least one of the busy `workers` can give its result; their indices."""


class Workers:
    """`count` workers, each hosting its own ``factory(*args)``, on `runner`.

    Args:
        runner: ``local``, ``ray`` or ``ray:ADDRESS`` (see `parse_runner`).
        count: workers to start.
        factory: builds the hosted object in each worker; with ``factory(*args)``, it must be
            picklable (module-level), and it is called again in a replacement worker.
        args: the factory's arguments.
    """

    def __init__(self, runner: str, count: int, factory: Callable[..., Any], args: tuple[Any, ...] = ()) -> None:
        if count < 1:
            raise ValueError(f"need at least one worker, got {count}")
        where = parse_runner(runner)
        if where.ray:
            from gymnast.envs.ray_workers import RayBackend

            self._backend: Backend = RayBackend(where.address)
        else:
            self._backend = LocalBackend()
        self._start = functools.partial(self._backend.start, factory, args)
        self._workers: list[Worker] = []
        try:
            for _ in range(count):
                self._workers.append(self._start())
        except BaseException:
            self.close()
            raise

    def pids(self) -> list[int]:
        """Each worker's process id, in order."""
        return [worker.pid() for worker in self._workers]

    def call_each(self, method: str, args: Sequence[tuple[Any, ...]]) -> list[Any]:
        """Calls ``method`` on every worker at once, with its own args; returns the results in order.

        Raises:
            RuntimeError: naming the first worker that failed (its error, or its death, as the cause).
        """
        if not self._workers:
            raise RuntimeError("the workers are closed")
        for worker, worker_args in zip(self._workers, args, strict=True):
            worker.call(method, worker_args)
        results, failures = [], []
        for index, worker in enumerate(self._workers):  # take every answer: the next call starts clean
            try:
                results.append(worker.result())
            except Exception as error:  # noqa: BLE001  (reported below, after the others have answered)
                failures.append((index, error))
        if failures:
            index, error = failures[0]
            raise RuntimeError(f"worker {index} failed in {method}(): {error}") from error
        return results

    def map(self, method: str, items: Iterable[Any]) -> Iterator[Any]:
        """Yields ``method(item)`` for every item, in completion order, one item per worker at a time.

        An item whose worker dies is rerun on a replacement worker, so each item's result is
        yielded exactly once. One item at a time keeps little in flight when a run is interrupted
        and loses at most one item's work per dead worker.

        Raises:
            RuntimeError: an item's workers died `MAX_ATTEMPTS` times.
            Exception: whatever ``method`` raised for an item, with the worker's traceback as its cause.
        """
        todo = collections.deque(enumerate(items))
        deaths: collections.Counter[int] = collections.Counter()
        running: dict[int, tuple[int, Any]] = {}  # worker index -> (item index, item)
        while todo or running:
            for index, worker in enumerate(self._workers):
                if todo and index not in running:
                    running[index] = todo.popleft()
                    worker.call(method, (running[index][1],))
            busy = sorted(running)
            for index in (busy[i] for i in self._backend.wait([self._workers[i] for i in busy])):
                number, item = running.pop(index)
                try:
                    result = self._workers[index].result()
                except WorkerDied as died:
                    deaths[number] += 1
                    if deaths[number] >= MAX_ATTEMPTS:
                        raise RuntimeError(f"{item!r} lost its worker {MAX_ATTEMPTS} times; the last: {died}") from died
                    logger.warning("%s; its job %r reruns on a new worker", died, item)
                    todo.appendleft((number, item))
                    self._replace(index)
                    continue
                yield result

    def close(self) -> None:
        """Stops every worker (a busy one at once); closing twice does nothing."""
        workers, self._workers = self._workers, []
        for worker in workers:
            worker.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _replace(self, index: int) -> None:
        self._workers[index].close()
        self._workers[index] = self._start()


