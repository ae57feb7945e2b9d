"""`gymnast eval` on Ray actors: the serial run's episodes, once each, even when a worker is killed."""

from __future__ import annotations

import dataclasses
import logging
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.eval.evaluate import EvalConfig, evaluate

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.slow
# Episodes long enough that a worker is still busy when the test kills it.
CONFIG = EvalConfig(tasks="reach-v3,drawer-close-v3", episodes=3, workers=1, videos_per_task=0,
                    env=EnvConfig(image_size=48, horizon=120))


@pytest.fixture(scope="module")
def serial(tmp_path_factory) -> dict:
    return evaluate("expert", CONFIG, tmp_path_factory.mktemp("serial") / "eval.json", progress=False)


@pytest.fixture(scope="module")
def ray_here():
    from gymnast.envs.ray_workers import init_ray

    init_ray(num_cpus=2)
    yield
    ray.shutdown()


def _descendants(pid: int) -> set[int]:
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parents[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except OSError:
            continue
    found, todo = set(), [pid]
    while todo:
        pid = todo.pop()
        children = {child for child, parent in parents.items() if parent == pid}
        found |= children
        todo.extend(children)
    return found


def _title(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return ""


def _kill_a_busy_actor(killed: list[int], deadline_s: float = 120) -> None:
    """SIGKILLs the first of this process's Ray actors seen running an episode (Ray titles it ``ray::Host.answer``)."""
    deadline = time.monotonic() + deadline_s
    while not killed and time.monotonic() < deadline:
        for pid in _descendants(os.getpid()):  # only the Ray this test started
            if _title(pid).startswith("ray::Host.answer"):
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
        time.sleep(0.05)


def _per_episode(report: dict) -> list[tuple]:
    return [(r["task"], r["seed"], r["instruction"], r["success"], r["steps"]) for r in report["records"]]


def test_ray_evaluation_gives_the_serial_runs_episodes(serial, ray_here, tmp_path):
    report = evaluate("expert", dataclasses.replace(CONFIG, workers=2, runner="ray"), tmp_path / "eval.json",
                      progress=False)
    assert _per_episode(report) == _per_episode(serial)
    assert report["config"]["seeds"] == serial["config"]["seeds"]


def test_a_ray_worker_killed_mid_evaluation_has_its_episode_rerun_once(serial, ray_here, tmp_path, caplog):
    killed: list[int] = []
    killer = threading.Thread(target=_kill_a_busy_actor, args=(killed,), daemon=True)
    killer.start()
    with caplog.at_level(logging.WARNING, logger="gymnast.envs.workers"):
        report = evaluate("expert", dataclasses.replace(CONFIG, workers=2, runner="ray"), tmp_path / "eval.json",
                          progress=False)
    killer.join()
    assert killed, "no actor was seen running an episode"
    assert "reruns on a new worker" in caplog.text
    assert _per_episode(report) == _per_episode(serial)  # every episode once, none lost or doubled
    assert report["episodes"] == serial["episodes"] and report["real_interactions"] == serial["real_interactions"]
