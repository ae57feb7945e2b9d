"""Giving freed memory back to the operating system.

A long-lived simulator process builds and closes Meta-World scenes by the hundred. A closed scene's
objects refer to each other, so its MuJoCo model and data wait for Python's cycle collector, and
once freed their memory goes to the C heap, which keeps the pages, fragmented: the process's
resident memory only ever grows until both are done (tests/utils/test_memory.py shows the
mechanism). In an experiment two such workers grew to several GB each and the machine ran out of
memory; a process that had built 40 two-camera scenes held 1.4 GB after closing them with the heap
trimmed alone, 0.5 GB with the cycles collected first (benchmarks/scene_memory.py).

The opposite problem is time, not memory: by default glibc maps every large block (over 128 KB, its
threshold growing up to 32 MB as such blocks are freed) fresh from the operating system and unmaps
it when it is freed, so the kernel faults in and zeroes each of its pages again. A torch model on
the CPU allocates blocks of that size in every layer of every call: in the three-camera headline's
practice on new scenes about 40% of the machine's CPU time was the kernel's (perf), and a
three-camera world model imagining 12 chunks of 32 rollouts took 782,000 page faults, 1.6x the time
of the 130,000 it takes once `reuse_large_blocks` lets the heap keep the blocks for the next call
(benchmarks/heap_reuse.py).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import gc
import os


@functools.cache
def _libc_function(name: str):
    """glibc's function `name` (``malloc_trim``, ``mallopt``), or None where the C library has none
    (musl, macOS, Windows)."""
    library = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(library) if library else None
    except OSError:
        return None
    return getattr(libc, name, None)


HEAP_REUSE_VARIABLE = "GYMNAST_HEAP_REUSE"
"""``auto`` (the default): `reuse_large_blocks` keeps large blocks in the heap; ``off``: glibc's
own behaviour (what a process that does not call it gets)."""

GLIBC_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "GLIBC_TUNABLES")
"""glibc's own settings of its heap: a user who set one of them chose, and is left alone."""

KEPT_BLOCK_BYTES = 256 * 2**20
"""Blocks up to this size come from the heap, and up to this much free memory stays at its top: a
three-camera world model's largest activations at a batch of 32 are under it
(benchmarks/heap_reuse.py)."""

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameter numbers (malloc.h)


def reuse_large_blocks(size: int = KEPT_BLOCK_BYTES) -> bool:
    """Lets glibc's heap serve and keep blocks up to `size` bytes, so that a freed tensor's pages
    serve the next one without the kernel faulting and zeroing them again (module docstring);
    True if it did.

    It does nothing with ``GYMNAST_HEAP_REUSE=off``, where a glibc variable of the heap is set, or
    without glibc. The memory it keeps is what the process used at its peak, less the blocks over
    `size`; `release_freed_memory` still returns it.

    Raises:
        ValueError: ``GYMNAST_HEAP_REUSE`` holds something other than auto or off.
    """
    wanted = os.environ.get(HEAP_REUSE_VARIABLE, "auto").strip().lower()
    if wanted not in ("auto", "off"):
        raise ValueError(f"{HEAP_REUSE_VARIABLE}={wanted!r}: use auto (keep large blocks in the heap) or off "
                         "(glibc's own behaviour)")
    mallopt = _libc_function("mallopt")
    if wanted == "off" or mallopt is None or any(name in os.environ for name in GLIBC_VARIABLES):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, size)) and bool(mallopt(_M_TRIM_THRESHOLD, size))


def release_freed_memory() -> bool:
    """Frees unreachable reference cycles, then returns the C heap's free pages to the operating
    system; True if it could return them (glibc)."""
    gc.collect()
    trim = _libc_function("malloc_trim")
    if trim is None:
        return False
    trim(0)
    return True
