"""Freed heap memory goes back to the operating system when asked (glibc's malloc_trim)."""

from __future__ import annotations

import gc
import sys

import numpy as np
import pytest
from process_memory import resident_bytes

from gymnast.utils.memory import release_freed_memory


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
