"""What the test process holds in memory, for the tests that check freed memory leaves it."""

import os
from pathlib import Path


def resident_bytes() -> int:
    """The process's resident set size, from Linux's /proc (the tests that read it run on Linux only)."""
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
