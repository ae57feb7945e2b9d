"""Worker processes never outlive their parent, even one killed with SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

PARENTS = {
    # A process pool (eval, collect, the gap report) busy with long jobs.
    "process pool": "import time\nfrom gymnast.envs.parallel import parallel_map\nlist(parallel_map(time.sleep, [600, 600], 2))",
    # The vector env's workers (RL and its evaluations), idle between steps.
    "vector env": ("import time\nfrom gymnast.config import EnvConfig\nfrom gymnast.envs.sim_vector import SimVectorEnv\n"
                   "env = SimVectorEnv(2, chunk_size=1, config=EnvConfig(image_size=32), workers=2)\ntime.sleep(600)"),
}


def _children(pid: int) -> set[int]:
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited; only its entry waits to be reaped


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
@pytest.mark.parametrize("kind", sorted(PARENTS))
def test_workers_exit_within_seconds_of_their_parent_being_killed(kind):
    parent = subprocess.Popen([sys.executable, "-c", PARENTS[kind]], env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 120
        while len(workers := _children(parent.pid)) < 2:  # spawned workers start slowly (imports)
            assert parent.poll() is None, f"the {kind} parent exited early with {parent.returncode}"
            assert time.monotonic() < deadline, f"the {kind} parent started no workers"
            time.sleep(0.2)
        time.sleep(3)  # let them finish starting (the watchdog is set up first thing)
        workers = _children(parent.pid)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 10
        while (survivors := {pid for pid in workers if _alive(pid)}) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not survivors, f"{kind}: workers {sorted(survivors)} outlived their killed parent"
    finally:
        if parent.poll() is None:
            parent.kill()
