"""Freed heap memory goes back to the operating system when asked (glibc's malloc_trim)."""

from __future__ import annotations

import gc
import os
import subprocess
import sys

import numpy as np
import pytest
from process_memory import resident_bytes

from gymnast.utils.memory import GLIBC_VARIABLES, HEAP_REUSE_VARIABLE, release_freed_memory, reuse_large_blocks


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="malloc_trim is glibc's")
def test_freed_heap_pages_leave_the_resident_memory_only_when_released():
    chunks = [np.ones(8000) for _ in range(3000)]  # 192 MB in 64 KB blocks: the heap, not mmap
    pinned = np.ones(8000)  # allocated last, it keeps the heap's top in use, as a live scene would
    held = resident_bytes()
    del chunks
    freed = resident_bytes()
    assert freed > held - 50e6  # freed to the heap, still resident
    assert release_freed_memory()
    assert resident_bytes() < freed - 150e6
    del pinned


class _Scene:
    """Stands for a closed scene whose objects refer to each other."""

    def __init__(self) -> None:
        self.me, self.data = self, [np.ones(8000) for _ in range(40)]  # 2.5 MB in 64 KB blocks


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="malloc_trim is glibc's")
def test_memory_held_in_reference_cycles_is_released_too():
    gc.disable()  # as between two automatic collections
    try:
        scenes = [_Scene() for _ in range(80)]  # 200 MB
        pinned = np.ones(8000)
        held = resident_bytes()
        del scenes  # unreachable, but each scene still refers to itself
        assert resident_bytes() > held - 50e6
        assert release_freed_memory()
        assert resident_bytes() < held - 150e6
        del pinned
    finally:
        gc.enable()


# A process that takes a 64 MB block from the C heap, gives it back and takes it again: the page
# faults of the second time, after the heap is set up as the `gymnast` command sets it.
_SECOND_ALLOCATION = """
import ctypes, resource
from gymnast.utils.memory import _libc_function, reuse_large_blocks
print(reuse_large_blocks())
malloc, free = _libc_function("malloc"), _libc_function("free")
malloc.restype, free.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
free(ctypes.memset(malloc(2**26), 1, 2**26))
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
ctypes.memset(malloc(2**26), 1, 2**26)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _second_allocation(**variables: str) -> tuple[str, int]:
    environment = {key: value for key, value in os.environ.items() if key not in GLIBC_VARIABLES}
    done = subprocess.run([sys.executable, "-c", _SECOND_ALLOCATION], env={**environment, **variables},
                          capture_output=True, text=True, check=True)
    reused, faults = done.stdout.split()
    return reused, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_a_freed_large_block_serves_the_next_one_without_the_kernel_faulting_its_pages_again():
    reused, faults = _second_allocation()
    assert reused == "True"
    assert faults < 100  # 64 MB is 16,384 pages of 4 KB
    assert _second_allocation(GYMNAST_HEAP_REUSE="off") == ("False", pytest.approx(16_384, rel=0.05))
    assert _second_allocation(MALLOC_MMAP_THRESHOLD_="131072")[0] == "False"  # the user's own setting stands


def test_an_unknown_heap_setting_is_named(monkeypatch):
    monkeypatch.setenv(HEAP_REUSE_VARIABLE, "always")
    with pytest.raises(ValueError, match="GYMNAST_HEAP_REUSE='always'"):
        reuse_large_blocks()
