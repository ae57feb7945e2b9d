"""Workers as processes spawned on this machine: the ``local`` runner of `gymnast.envs.workers`.

Processes are started with ``spawn``: forking a process that already holds a GL context is
unsafe. Each talks to its parent over a pipe, so its death reads as the end of the pipe. Workers
never outlive their parent (`exit_with_parent`), even when it is killed with SIGKILL and has no
chance to stop them.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as wait_for_connections
from typing import Any

from gymnast.envs.worker_calls import WorkerDied, answer, unpack

PARENT_CHECK_S = 0.5
"""How often a worker checks that its parent is still alive."""


def exit_with_parent(parent: int) -> None:
    """Ends this worker process as soon as process `parent` is gone.

    Called first thing in a local worker. A killed parent cannot stop its workers, and each holds a
    Meta-World scene and often a model (over a GB), so a watchdog thread polls the parent's pid:
    once the worker has been re-parented, it exits at once, without cleanup (its parent's files are
    written atomically, so nothing is left half-written).
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _serve(conn: Connection, factory: Callable[..., Any], args: tuple[Any, ...], parent: int) -> None:
    """A local worker's loop: answers ``(method, args)`` messages until told to stop (None) or orphaned."""
    exit_with_parent(parent)
    hosted = factory(*args)
    try:
        while (message := conn.recv()) is not None:
            conn.send(answer(hosted, *message))
    except (EOFError, KeyboardInterrupt):  # the parent is gone or interrupted: just exit
        pass
    finally:
        if hasattr(hosted, "close"):
            hosted.close()
        conn.close()


class LocalWorker:
    """A process spawned on this machine, talking over a pipe."""

    def __init__(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> None:
        context = multiprocessing.get_context("spawn")  # forking a process holding GL is unsafe
        self.conn, child = context.Pipe()
        self._process = context.Process(target=_serve, args=(child, factory, args, os.getpid()), daemon=True)
        self._process.start()
        child.close()  # only the worker holds its end, so its death reads as EOF here
        self._busy = False

    def call(self, method: str, args: tuple[Any, ...]) -> None:
        self._busy = True
        with contextlib.suppress(OSError):  # a dead worker; result() reports it
            self.conn.send((method, args))

    def result(self) -> Any:
        try:
            reply = self.conn.recv()
        except (EOFError, OSError) as error:
            self._process.join(timeout=5)
            raise WorkerDied(f"worker process {self._process.pid} died (exit code {self._process.exitcode})") from error
        finally:
            self._busy = False
        return unpack(reply)

    def pid(self) -> int:
        return self._process.pid

    def close(self) -> None:
        if not self._busy:
            with contextlib.suppress(OSError):  # already dead
                self.conn.send(None)
            self._process.join(timeout=10)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join()
        self.conn.close()


class LocalBackend:
    """Workers spawned on this machine."""

    def start(self, factory: Callable[..., Any], args: tuple[Any, ...]) -> LocalWorker:
        return LocalWorker(factory, args)

    def wait(self, workers: Sequence[LocalWorker]) -> list[int]:
        ready = wait_for_connections([worker.conn for worker in workers])
        return [index for index, worker in enumerate(workers) if worker.conn in ready]
