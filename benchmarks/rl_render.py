"""A real-world RL step with the simulator's success reward: rendering only the frames that are read
against rendering every frame.

A step that writes no video, with a reward of the simulator's own outcome (`RewardNeeds.video`
False), renders each chunk's last frame alone, the one the policy reads (docs/rl.md). For the
reference in the same run, the reward is declared to read the video, which makes the simulator
render every frame as before. The two take turns for `--rounds` rounds of `benchmarks/rl_step.py`'s
measurement (the median of the timed steps), so a busy machine slows both alike.

    .venv/bin/python benchmarks/rl_render.py [--data data/mt10] [--tasks reach-v3] [--starts 2]

Prints and writes benchmarks/results/rl_render.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import gymnast.reward.sim as sim_rewards
from gymnast.reward.base import RewardNeeds
from gymnast.utils.atomic import write_json
# A sibling script (the script's folder is on the path).
from rl_step import ROOT, time_setting

RESULTS = Path(__file__).parent / "results" / "rl_render.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of start states (96 px)")
    parser.add_argument("--tasks", default="reach-v3")
    parser.add_argument("--starts", type=int, default=2, help="start states per step (8 rollouts each)")
    parser.add_argument("--steps", type=int, default=3, help="RL steps per round (the first is not timed)")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    rounds: dict[str, list[dict]] = {"read_frames_only": [], "every_frame": []}
    for _ in range(args.rounds):
        for name, video in (("read_frames_only", False), ("every_frame", True)):
            # The rewards are built in this process; the simulator workers only step episodes.
            sim_rewards.SimSuccess.needs = RewardNeeds(simulator_success=True, video=video)
            rounds[name].append(time_setting("real", "sim", args.data, args.steps, args.tasks,
                                             starts_per_step=args.starts))
    result = {
        "env_s": {name: [round(r["env_s"], 2) for r in runs] for name, runs in rounds.items()},
        "step_s": {name: [round(r["step_s"], 2) for r in runs] for name, runs in rounds.items()},
        "rounds": rounds,
        "tasks": args.tasks,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
        "command": " ".join(["benchmarks/rl_render.py", *sys.argv[1:]]),
    }
    print(json.dumps({key: result[key] for key in ("env_s", "step_s")}, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
