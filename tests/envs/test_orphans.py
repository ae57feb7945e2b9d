"""Worker processes never outlive their parent, even one killed with SIGKILL."""

from __future__ import annotations

import importlib.util
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


def _stat_fields(stat: Path) -> list[str] | None:
    """A /proc/PID/stat file's fields after the command name (state first), or None once it is gone."""
    try:
        return stat.read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _children(pid: int) -> set[int]:
    return {int(stat.parent.name) for stat in Path("/proc").glob("[0-9]*/stat")
            if (fields := _stat_fields(stat)) and int(fields[1]) == pid}


def _descendants(pid: int) -> set[int]:
    found, todo = set(), [pid]
    while todo:
        children = _children(todo.pop())
        found |= children
        todo.extend(children)
    return found


def _title(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _alive(pid: int) -> bool:
    fields = _stat_fields(Path(f"/proc/{pid}/stat"))
    return fields is not None and fields[0] != "Z"  # a zombie has exited; only its entry waits to be reaped  # a zombie has exited; only its entry waits to be reaped


def _cpu_ticks(pid: int) -> int:
    """The CPU time `pid` has used so far, in clock ticks (user + system), or -1 once it is gone."""
    fields = _stat_fields(Path(f"/proc/{pid}/stat"))
    return -1 if fields is None else int(fields[11]) + int(fields[12])  # utime, stime: the stat file's 14th and 15th fields


def _wait_until_idle(pids: set[int], seconds: float) -> None:
    """Waits until none of `pids` used CPU for a whole second: started (imports, the watchdog set up
    first thing in a worker) and waiting on its job or its pipe, however loaded the machine is."""
    deadline, before = time.monotonic() + seconds, {pid: _cpu_ticks(pid) for pid in pids}
    while time.monotonic() < deadline:
        time.sleep(1)
        now = {pid: _cpu_ticks(pid) for pid in pids}
        if now == before:
            return
        before = now
    raise AssertionError(f"workers {sorted(pids)} were still starting after {seconds} s")


def _survivors_of_killing(parent: subprocess.Popen, pids, seconds: float) -> set[int]:
    """SIGKILLs `parent`, then waits up to `seconds` for `pids` to exit; returns those still alive."""
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + seconds
    while (survivors := {pid for pid in pids if _alive(pid)}) and time.monotonic() < deadline:
        time.sleep(0.2)
    return survivors


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
@pytest.mark.parametrize("kind", sorted(PARENTS))
def test_workers_exit_within_seconds_of_their_parent_being_killed(kind):
    parent = subprocess.Popen([sys.executable, "-c", PARENTS[kind]], env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 120
        while len(_children(parent.pid)) < 2:  # spawned workers start slowly (imports)
            assert parent.poll() is None, f"the {kind} parent exited early with {parent.returncode}"
            assert time.monotonic() < deadline, f"the {kind} parent started no workers"
            time.sleep(0.2)
        workers = _children(parent.pid)
        _wait_until_idle(workers, seconds=120)
        survivors = _survivors_of_killing(parent, workers, seconds=10)
        assert not survivors, f"{kind}: workers {sorted(survivors)} outlived their killed parent"
    finally:
        if parent.poll() is None:
            parent.kill()


# A driver that started Ray on this machine, its two actors busy with long jobs.
RAY_PARENT = ("import time\nfrom gymnast.envs.parallel import parallel_map\nfrom gymnast.envs.ray_workers import init_ray\n"
              "init_ray(num_cpus=2)\nlist(parallel_map(time.sleep, [600, 600], 2, 'ray'))")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray is not installed")
def test_ray_actors_and_ray_itself_exit_within_seconds_of_their_driver_being_killed():
    parent = subprocess.Popen([sys.executable, "-c", RAY_PARENT], env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 180
        while len([pid for pid in _descendants(parent.pid) if "ray::Host" in _title(pid)]) < 2:
            assert parent.poll() is None, f"the Ray driver exited early with {parent.returncode}"
            assert time.monotonic() < deadline, "the Ray driver started no actors"
            time.sleep(0.5)
        # Ray's dashboard and runtime-env agents poll for their raylet and follow it within about a
        # minute; they hold no scene or model, so only the actors and Ray's core are timed here.
        processes = {pid for pid in _descendants(parent.pid) if "Agent" not in _title(pid)}
        survivors = _survivors_of_killing(parent, processes, seconds=15)
        assert not survivors, f"{[_title(pid)[:60] for pid in survivors]} outlived their killed driver"
    finally:
        if parent.poll() is None:
            parent.kill()
