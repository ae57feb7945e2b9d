"""Rendered real-world environment steps per second, in one process and in two.

Every step includes MuJoCo physics (5 substeps), the task's reward, and an RGB render at the
default image size: what data collection, evaluation and RL in the real world pay per step.
``steps_per_s_1proc_last_of_chunk``: the same, rendering only each chunk's last frame (chunks of
5, the policy's), as an evaluation without video does: the frames inside a chunk are never read.

    .venv/bin/python benchmarks/real_env.py [--steps 1500] [--task drawer-open-v3]

Prints and writes benchmarks/results/real_env.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.parallel import parallel_map
from gymnast.utils.atomic import write_json

RESULTS = Path(__file__).parent / "results" / "real_env.json"


def run_steps(job: tuple[str, int, int, tuple[str, ...], int]) -> tuple[int, float]:
    """Steps an env with random actions, rendering `cameras` every `render_every`-th step (and at an
    episode's end); returns (steps, seconds), env construction excluded."""
    task, steps, image_size, cameras, render_every = job
    env = MetaWorldEnv(task, EnvConfig(image_size=image_size, cameras=cameras))
    actions = np.random.default_rng(0).uniform(-1, 1, size=(steps, 4)).astype(np.float32)
    env.reset(seed=0)
    start = time.perf_counter()
    for i, action in enumerate(actions):
        _, _, terminated, truncated, _ = env.step(action, observe=(i + 1) % render_every == 0)
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps, elapsed


def steps_per_second(task: str, steps: int, image_size: int, processes: int, cameras: tuple[str, ...] = ("front",),
                     render_every: int = 1) -> float:
    """Total steps of all processes divided by the slowest process's stepping time (every
    `render_every`-th step rendering every one of `cameras`)."""
    results = list(parallel_map(run_steps, [(task, steps, image_size, cameras, render_every)] * processes, processes))
    return sum(n for n, _ in results) / max(t for _, t in results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="drawer-open-v3")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--image-size", type=int, default=EnvConfig().image_size)
    args = parser.parse_args()
    one = steps_per_second(args.task, args.steps, args.image_size, 1)
    two = steps_per_second(args.task, args.steps, args.image_size, 2)
    last_of_chunk = steps_per_second(args.task, args.steps, args.image_size, 1, render_every=5)
    result = {
        "steps_per_s_1proc": round(one, 1),
        "steps_per_s_2proc": round(two, 1),
        "scaling_2proc": round(two / one, 2),
        "steps_per_s_1proc_last_of_chunk": round(last_of_chunk, 1),
        "speedup_last_of_chunk": round(last_of_chunk / one, 2),
        "task": args.task,
        "image_size": args.image_size,
        "steps_per_process": args.steps,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
