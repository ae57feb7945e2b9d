"""Giving freed memory back to the operating system.

A long-lived simulator process builds and closes Meta-World scenes by the hundred. Closing a scene
frees its memory to the C heap, but the heap keeps the pages, fragmented, so the process's
resident memory only ever grows until they are released (tests/utils/test_memory.py shows the
mechanism). In an experiment two such workers grew to several GB each and the machine ran out of
memory.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


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
    """Returns the C heap's free pages to the operating system; True if it could (glibc)."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
