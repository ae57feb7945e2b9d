"""Workers as Ray actors: the ``ray`` and ``ray:ADDRESS`` runners of `gymnast.envs.workers`.

Imported only when such a runner is asked for, so the project works without Ray installed.

Ray is started on first use in this process (`init_ray`): on this machine (or the cluster in
``RAY_ADDRESS``), or at the address of ``ray:ADDRESS``. A Ray already initialised in this process,
say by a script that chose its own resources, is used as it is. Every node of a cluster needs the
project installed, in the same version, as its workers import it.

Placement: an actor keeps Ray's default resources (one CPU to be placed, none while it runs) and
is spread over the nodes. Holding a CPU for its lifetime would be the textbook way to get one
process per core, but a run holds several groups of workers at once (RL's own env, its real-world
evaluation env, the watch's), and on a cluster with fewer free cores than workers the later
groups' actors would wait for a core forever; as with local processes, ``workers`` says how many
run and they share the cores.

Cleanup: the actors belong to this driver's Ray job, which Ray ends, actors and all, when the
driver exits, even when it is killed: a Ray instance the driver started on this machine shares its
fate (its processes are told to exit with it), and a cluster's head sees the driver's connection
drop. `tests/envs/test_orphans.py` kills a driver to check it.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from typing import Any

import ray
from ray.exceptions import NodeDiedError, OutOfMemoryError, RayActorError, WorkerCrashedError

from gymnast.envs.worker_calls import WorkerDied, answer, unpack


class Host:
    """The actor: hosts ``factory(*args)`` and answers calls on it."""

    def __init__(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self._hosted = factory(*args)

    def answer(self, method: str, args: tuple[Any, ...]) -> tuple[Any, ...]:
        return answer(self._hosted, method, args)

    def pid(self) -> int:
        return os.getpid()


_Actor = ray.remote(Host)
DEATHS = (RayActorError, OutOfMemoryError, WorkerCrashedError, NodeDiedError)
"""How Ray reports an actor's process gone: killed, crashed, ended by Ray's memory monitor, or its node lost."""


class RayWorker:
    """One Ray actor, with at most one call in flight."""

    def __init__(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self._actor = _Actor.options(scheduling_strategy="SPREAD").remote(factory, args)
        self.pending: ray.ObjectRef | None = None

    def call(self, method: str, args: tuple[Any, ...]) -> None:
        self.pending = self._actor.answer.remote(method, args)

    def result(self) -> Any:
        try:
            reply = ray.get(self.pending)
        except DEATHS as error:
            raise WorkerDied(f"Ray actor {self._actor._actor_id.hex()} died: {error}") from error
        finally:
            self.pending = None
        return unpack(reply)

    def pid(self) -> int:
        return ray.get(self._actor.pid.remote())

    def close(self) -> None:
        ray.kill(self._actor)


def init_ray(address: str | None = None, num_cpus: int | None = None) -> None:
    """Connects this process to Ray, unless it already is.

    Args:
        address: the cluster to join; None: Ray's default (``RAY_ADDRESS``, else a new instance
            on this machine).
        num_cpus: the cores a new instance on this machine may use (None: all of them).

    A new instance on this machine runs its workers at this process's priority. Ray's default
    lowers them (nice 15) to keep its own services responsive, which on a busy machine leaves the
    actors a fraction of the CPU that the local runner's processes get.
    """
    if ray.is_initialized():
        return
    options: dict[str, Any] = {"address": address, "include_dashboard": False, "logging_level": logging.WARNING}
    if address is None and "RAY_ADDRESS" not in os.environ:  # a cluster keeps its own settings
        options |= {"num_cpus": num_cpus, "_system_config": {"worker_niceness": os.getpriority(os.PRIO_PROCESS, 0)}}
    ray.init(**options)


class RayBackend:
    """Workers as Ray actors, on the Ray this process is connected to (`init_ray` first).

    Args:
        address: the cluster to join; None: Ray's default (``RAY_ADDRESS``, else a new local instance).
    """

    def __init__(self, address: str | None) -> None:
        init_ray(address)

    def start(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> RayWorker:
        return RayWorker(factory, args)

    def wait(self, workers: Sequence[RayWorker]) -> list[int]:
        ready, _ = ray.wait([worker.pending for worker in workers], num_returns=1)
        return [index for index, worker in enumerate(workers) if worker.pending in ready]
