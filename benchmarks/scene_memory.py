"""What a simulator process's scenes cost and what closing them gives back: a slice of 40
two-camera MT10 episodes (`gymnast.envs.sim_vector._Episodes`, as in a worker) is reset and
stepped, its scenes closed, then the freed memory released in two parts, the heap trimmed without
and then with Python's cycle collector first (`gymnast.utils.memory.release_freed_memory`).
Also the seconds to build one scene, which an idle pool pays again when it is used next.

    .venv/bin/python benchmarks/scene_memory.py   # -> benchmarks/results/scene_memory.json
"""

from __future__ import annotations

import argparse
import gc
import os
import time
from pathlib import Path

import numpy as np

import gymnast  # noqa: F401  (sets MUJOCO_GL before Meta-World imports mujoco)
from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.sim_vector import _Episodes
from gymnast.envs.tasks import resolve_tasks
from gymnast.utils.atomic import write_json
from gymnast.utils.memory import _libc_function, release_freed_memory


def resident_gb() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "scene_memory.json")
    args = parser.parse_args()
    config = EnvConfig(cameras=("front", "gripper"), horizon=150)
    tasks = resolve_tasks("mt10")
    began = time.perf_counter()
    built = [MetaWorldEnv(task, config=config) for task in tasks]
    build_s = (time.perf_counter() - began) / len(built)
    for env in built:
        env.close()
    del built
    release_freed_memory()
    figures = {"cameras": list(config.cameras), "episodes": args.episodes, "seconds_to_build_a_scene": build_s,
               "start_gb": resident_gb()}
    gc.disable()  # as between two automatic collections, so the two parts of the release separate
    episodes = _Episodes(config, "none", "train")
    episodes.reset([tasks[i % len(tasks)] for i in range(args.episodes)], list(range(args.episodes)),
                   [None] * args.episodes)
    for _ in range(6):
        episodes.step(np.random.default_rng(0).uniform(-1, 1, (args.episodes, 5, 4)).astype(np.float32))
    figures["with_scenes_gb"] = resident_gb()
    for env in episodes._envs.values():  # what `_Episodes.close` does, its release taken apart
        env.close()
    episodes._envs.clear()
    episodes._episodes = []
    _libc_function("malloc_trim")(0)
    figures["closed_heap_trimmed_gb"] = resident_gb()
    gc.collect()
    _libc_function("malloc_trim")(0)
    figures["closed_cycles_collected_and_trimmed_gb"] = resident_gb()
    gc.enable()
    print(figures)
    write_json(args.out, figures)


if __name__ == "__main__":
    main()
