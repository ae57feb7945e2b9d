"""What an extra camera costs: rendered environment steps per second with one camera, two and three.

Every step is MuJoCo physics (5 substeps), Meta-World's reward and one RGB render per camera at the
default image size, with random actions, in one process (environment construction not counted).
The setups (each view alone, front + gripper, and the three) take turns for a few rounds, so that load
from other processes on the machine hits them alike; each keeps its best and median round. Then one
episode of the horizon's length is recorded from the three cameras and each camera's frames are
encoded with the dataset codec, for the disk cost of a view.

    .venv/bin/python benchmarks/render_cameras.py [--steps 600] [--rounds 3] [--task pick-place-v3]

Prints and writes benchmarks/results/render_cameras.json.
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

import numpy as np

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.utils.atomic import write_json
from gymnast.utils.video import DEFAULT_CODEC, encode_video

RESULTS = Path(__file__).parent / "results" / "render_cameras.json"
SETUPS = {"front": ("front",), "gripper": ("gripper",), "hand": ("hand",), "front+gripper": ("front", "gripper"),
          "front+gripper+hand": ("front", "gripper", "hand")}


def steps_per_second(env: MetaWorldEnv, actions: np.ndarray) -> float:
    """Steps `env` through `actions` (resetting at the horizon); returns rendered steps per second."""
    env.reset(seed=0)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def kib_per_frame(env: MetaWorldEnv, actions: np.ndarray) -> dict[str, float]:
    """Each camera's encoded size per frame over one recorded episode (KiB, dataset codec)."""
    obs, _ = env.reset(seed=0)
    views = {name: [frame] for name, frame in obs["images"].items()}
    for action in actions[: env.config.horizon]:
        obs, *_ = env.step(action)
        for name, frame in obs["images"].items():
            views[name].append(frame)
    sizes = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, frames in views.items():
            path = Path(folder) / f"{name}.mp4"
            encode_video(path, np.stack(frames), env.metadata["render_fps"], DEFAULT_CODEC)
            sizes[name] = round(path.stat().st_size / 1024 / len(frames), 2)
    return sizes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="pick-place-v3")
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--image-size", type=int, default=EnvConfig().image_size)
    args = parser.parse_args()
    envs = {name: MetaWorldEnv(args.task, EnvConfig(image_size=args.image_size, cameras=cameras))
            for name, cameras in SETUPS.items()}
    actions = np.random.default_rng(0).uniform(-1, 1, size=(args.steps, 4)).astype(np.float32)
    rounds: dict[str, list[float]] = {name: [] for name in SETUPS}
    for _ in range(args.rounds):
        for name, env in envs.items():
            rounds[name].append(steps_per_second(env, actions))
    encoded = kib_per_frame(envs["front+gripper+hand"], actions)
    for env in envs.values():
        env.close()
    best = {name: max(values) for name, values in rounds.items()}
    setups = {
        name: {
            "steps_per_s": round(best[name], 1),
            "steps_per_s_median": round(statistics.median(rounds[name]), 1),
            "frames_per_s": round(best[name] * len(SETUPS[name]), 1),
            "ms_per_step": round(1000 / best[name], 2),
        }
        for name in SETUPS
    }
    result = {
        "setups": setups,
        "extra_view_ms_per_step": round(1000 / best["front+gripper"] - 1000 / best["front"], 2),
        "two_cameras_steps_vs_one": round(best["front+gripper"] / best["front"], 2),
        "three_cameras_steps_vs_one": round(best["front+gripper+hand"] / best["front"], 2),
        "three_cameras_steps_vs_two": round(best["front+gripper+hand"] / best["front+gripper"], 2),
        "encoded_kib_per_frame": encoded,
        "task": args.task,
        "image_size": args.image_size,
        "steps_per_round": args.steps,
        "rounds": args.rounds,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
