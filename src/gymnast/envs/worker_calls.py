"""How a worker process answers a call, whichever runner started it (`gymnast.envs.workers`).

A call's outcome travels back as a plain tuple, so that both runners carry it the same way and
the caller raises a worker's exception as itself, with the worker's traceback attached.
"""

from __future__ import annotations

import pickle
import traceback
from typing import Any


class WorkerDied(RuntimeError):
    """A worker's process ended before answering a call."""


def answer(hosted: Any, method: str, args: tuple[Any, ...]) -> tuple[Any, ...]:
    """Runs a call in a worker: ``("ok", value)``, or ``("error", exception, traceback text)``."""
    try:
        return "ok", getattr(hosted, method)(*args)
    except Exception as error:  # noqa: BLE001  (every failure goes back to the caller, which raises it)
        text = traceback.format_exc()
        try:
            pickle.dumps(error)
        except Exception:  # noqa: BLE001  (an exception that cannot travel is sent as its text)
            error = RuntimeError(repr(error))
        return "error", error, text


def unpack(reply: tuple[Any, ...]) -> Any:
    """The value in a worker's `answer`, or its exception raised here (the worker's traceback as its cause)."""
    if reply[0] == "ok":
        return reply[1]
    _, error, text = reply
    raise error from RuntimeError(f"in the worker process:\n{text}")


