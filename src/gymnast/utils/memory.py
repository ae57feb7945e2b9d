"""Giving freed memory back to the operating system.

A long-lived simulator process builds and closes Meta-World scenes by the hundred. A closed scene's
objects refer to each other, so its MuJoCo model and data wait for Python's cycle collector, and
once freed their memory goes to the C heap, which keeps the pages, fragmented: the process's
resident memory only ever grows until both are done (tests/utils/test_memory.py shows the
mechanism). In an experiment two such workers grew to several GB each and the machine ran out of
memory; a process that had built 40 two-camera scenes held 1.4 GB after closing them with the heap
trimmed alone, 0.5 GB with the cycles collected first (benchmarks/scene_memory.py).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import gc


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS, Windows)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    return getattr(libc, "malloc_trim", None)


def release_freed_memory() -> bool:
    """Frees unreachable reference cycles, then returns the C heap's free pages to the operating
    system; True if it could return them (glibc)."""
    gc.collect()
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
