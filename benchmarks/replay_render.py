"""Replaying actions in the real world for an outcome alone: rendering only each chunk's last frame
against rendering every frame.

A replay whose frames no reward reads (the simulator's success behind R3 of the learning ladder,
the truth measured beside an imagined run, the reward-hacking watch) renders each chunk's last
frame alone (`replay_actions(..., every_frame=False)`), the frame a policy would read there
(`--learn-on replays`). The reference in the same run renders every frame, as such replays did
before. Both replay the same random actions from the same scenes (door-open, two cameras, 150
actions, chunks of 5) and take turns for `--rounds` rounds, so a busy machine slows both alike.

    .venv/bin/python benchmarks/replay_render.py [--rollouts 16] [--rounds 3]

Prints and writes benchmarks/results/replay_render.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import torch

from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL
from gymnast.envs.starts import scene_starts
from gymnast.rl.evaluate import replay_actions
from gymnast.utils.atomic import write_json

RESULTS = Path(__file__).parent / "results" / "replay_render.json"
CHUNK, HORIZON = 5, 150


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="door-open-v3")
    parser.add_argument("--rollouts", type=int, default=16)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    config = EnvConfig(image_size=96, horizon=HORIZON, cameras=("front", "gripper"), terminate_on_success=False)
    starts = scene_starts([(args.task, 500_000 + i) for i in range(args.rollouts)], config)
    actions = torch.rand(args.rollouts, HORIZON, 4, generator=torch.Generator().manual_seed(0)) * 2 - 1
    lengths = torch.full((args.rollouts,), HORIZON)
    envs = EnvFactory(REAL, CHUNK, config, "mild", args.workers)
    seconds: dict[str, list[float]] = {"every_frame": [], "call_frames": []}
    outcomes = {}
    try:
        env = envs.get(REAL, args.rollouts)
        replay_actions(env, starts, actions, lengths, every_frame=False)  # builds the scenes: not timed
        for _ in range(args.rounds):
            for name, every_frame in (("every_frame", True), ("call_frames", False)):
                began = time.perf_counter()
                replay = replay_actions(env, starts, actions, lengths, every_frame=every_frame)
                seconds[name].append(time.perf_counter() - began)
                outcomes[name] = replay.success.tolist()
    finally:
        envs.close()
    if outcomes["every_frame"] != outcomes["call_frames"]:
        raise SystemExit("the two replays' outcomes differ: rendering changed what happened")
    every, calls = (statistics.median(seconds[name]) for name in ("every_frame", "call_frames"))
    result = {
        "task": args.task, "rollouts": args.rollouts, "actions": HORIZON, "cameras": list(config.cameras),
        "workers": args.workers, "cpus": os.cpu_count(), "machine": platform.processor() or platform.machine(),
        "every_frame_s": round(every, 2), "call_frames_s": round(calls, 2), "speedup": round(every / calls, 2),
        "same_outcomes": True, "rounds": {name: [round(t, 2) for t in times] for name, times in seconds.items()},
    }
    write_json(args.out, result)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
