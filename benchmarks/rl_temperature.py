"""The SFT policy's real-world success at each rollout temperature (greedy = 0): why `gymnast rl`
samples at 1.0 rather than World-Gymnast's 1.6.

The policy runs 4 times from each of 4 dataset scenes of 6 MT10 tasks (96 rollouts per
temperature, 150-action horizon) through the RL loop's own rollout code, in the real world.

    .venv/bin/python benchmarks/rl_temperature.py [--policy results/sft/policy] [--data data/mt10]

Prints and writes results/rl/temperature.json.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.policy.load import load_policy
from gymnast.rl.rollout import collect_rollouts, dataset_starts
from gymnast.utils.atomic import write_json

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl" / "temperature.json"
TASKS = ("reach-v3", "push-v3", "pick-place-v3", "door-open-v3", "drawer-open-v3", "window-open-v3")
TEMPERATURES = (0.0, 1.0, 1.3, 1.6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, default=ROOT / "results/sft/policy")
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of start states (96 px)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy = load_policy(args.policy)
    scenes = dataset_starts(args.data, TASKS)
    starts = [s for task in TASKS for s in [s for s in scenes if s.task == task][:4] for _ in range(4)]
    report = {"policy": str(args.policy), "rollouts": len(starts), "tasks": list(TASKS), "temperatures": {}}
    with SimVectorEnv(len(starts), policy.chunk_size, EnvConfig(image_size=96, horizon=150), workers=args.workers) as env:
        for temperature in TEMPERATURES:
            began = time.perf_counter()
            rollouts = collect_rollouts(env, policy, starts, temperature, torch.Generator().manual_seed(0))
            per_task = {task: rollouts.success[[i for i, s in enumerate(starts) if s.task == task]].float().mean().item()
                        for task in TASKS}
            report["temperatures"][str(temperature)] = {"success": rollouts.success.float().mean().item(),
                                                        "per_task": per_task, "wall_s": time.perf_counter() - began}
            print(f"temperature {temperature}: success {rollouts.success.float().mean().item():.1%}", flush=True)
    write_json(RESULTS, report)
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
