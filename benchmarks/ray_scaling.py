"""Evaluation episodes per second on Ray actors, with one worker and with two, in one run.

The scripted expert's real-world evaluation episodes (`gymnast.eval.evaluate.run_episode`, what
`gymnast eval --runner ray` runs), played four ways on the same episodes: serially in this
process (the reference), on 1 and 2 Ray actors, and on 2 local spawned workers. Episodes run the
full horizon (no early end on success), so each is the same amount of work. Every worker first
plays one episode of each task, so the figures leave out starting workers and building scenes
(reported apart as ``startup_s``, the median). The setups take turns for several rounds and each keeps its
best (the median too), so that other work on the machine weighs on all of them alike. The goal:
2 Ray workers at least 1.8x one, with every episode's result identical to the serial run's.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/ray_scaling.py [--episodes 8] [--address ADDRESS]

Prints and writes benchmarks/results/ray_scaling.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import ray

from gymnast.config import EnvConfig
from gymnast.envs.parallel import Apply
from gymnast.envs.ray_workers import init_ray
from gymnast.envs.workers import Workers
from gymnast.eval.evaluate import EvalConfig, EvalJob, plan_episodes, run_episode
from gymnast.utils.atomic import write_json

RESULTS = Path(__file__).parent / "results" / "ray_scaling.json"
GOAL = 1.8
"""Episodes/s of 2 Ray workers over 1 that the runner should reach on a 2-core machine."""


def _key(record: dict) -> tuple[str, int]:
    return record["task"], record["seed"]


class Serial:
    """The reference: episodes played one after another in this process."""

    def map(self, method: str, jobs: list[EvalJob]) -> list[dict]:
        return [run_episode(job) for job in jobs]

    def call_each(self, method: str, args: list[tuple[EvalJob]]) -> None:
        run_episode(*args[0])

    def close(self) -> None:
        pass


def start(runner: str, count: int, warm: list[EvalJob]) -> tuple[Workers | Serial, float]:
    """Workers (or `Serial` for count 0) that have played one episode of each task; with the seconds that took."""
    begin = time.perf_counter()
    pool = Serial() if count == 0 else Workers(runner, count, Apply, (run_episode,))
    for job in warm:  # every worker builds every task's scene
        pool.call_each("__call__", [(job,)] * max(count, 1))
    return pool, time.perf_counter() - begin


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", default="reach-v3,drawer-close-v3")
    parser.add_argument("--episodes", type=int, default=8, help="episodes per task")
    parser.add_argument("--rounds", type=int, default=3, help="timed passes over the episodes per setup (best kept)")
    parser.add_argument("--address", default=None, help="a Ray cluster to join (default: start Ray here)")
    parser.add_argument("--cpus", type=int, default=None, help="cores a local Ray may use (default: all)")
    args = parser.parse_args()
    init_ray(args.address, num_cpus=args.cpus)
    env = EnvConfig(terminate_on_success=False)
    config = EvalConfig(tasks=args.tasks, episodes=args.episodes + 1, videos_per_task=0, env=env)
    planned = plan_episodes(config, "expert", Path(tempfile.gettempdir()))
    warm = [job for i, job in enumerate(planned) if i % config.episodes == 0]  # each task's first seed
    jobs = [job for job in planned if job not in warm]
    load_before = os.getloadavg()
    setups = {"serial": ("local", 0), "ray_1": ("ray", 1), "ray_2": ("ray", 2), "local_2": ("local", 2)}
    # Rounds alternate the setups, so that a change in the machine's load falls on all of them alike;
    # each setup's workers are started afresh every round, so that only one setup holds memory at a time.
    seconds: dict[str, list[float]] = {name: [] for name in setups}
    startup: dict[str, list[float]] = {name: [] for name in setups}
    identical = {name: True for name in setups}
    reference = None
    for _ in range(args.rounds):
        for name, (runner, count) in setups.items():
            pool, took = start(runner, count, warm)
            startup[name].append(took)
            begin = time.perf_counter()
            records = sorted(pool.map("__call__", jobs), key=_key)
            seconds[name].append(time.perf_counter() - begin)
            pool.close()
            reference = reference or records
            identical[name] &= records == reference
    load_after = os.getloadavg()
    rate = {name: len(jobs) / min(times) for name, times in seconds.items()}
    result = {
        "episodes_per_s": {name: round(value, 3) for name, value in rate.items()},
        "episodes_per_s_median": {name: round(len(jobs) / statistics.median(times), 3)
                                  for name, times in seconds.items()},
        "startup_s": {name: round(statistics.median(times), 1) for name, times in startup.items()},
        "scaling_ray_2_over_1": round(rate["ray_2"] / rate["ray_1"], 2),
        "ray_2_over_serial": round(rate["ray_2"] / rate["serial"], 2),
        "goal_ray_2_over_1": GOAL,
        "identical_to_serial": identical,
        "episodes": len(jobs),
        "rounds": args.rounds,
        "tasks": args.tasks,
        "horizon": env.horizon,
        "image_size": env.image_size,
        "ray": ray.__version__,
        "ray_address": args.address or f"local, num_cpus={args.cpus or os.cpu_count()}",
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "load_average_1min_before_after": [round(load_before[0], 2), round(load_after[0], 2)]},
    }
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
