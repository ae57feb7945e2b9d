"""An imagined RL step with the image encoder frozen: each observation encoded once (the tokens of
the rollout's call reused by the update and the reference's KL) against encoded at every use.

The experiment's RL recipe (`--freeze vision`, KL 0.1 to the SFT policy) with the world model and
judge given, `RLConfig.remember_vision` on and off taking turns for `--rounds` rounds of
`benchmarks/rl_step.py`'s measurement (the median of the timed steps), so a busy machine slows both
alike. The update's share of the step is where the difference shows.

    .venv/bin/python benchmarks/frozen_vision.py --policy results/sft/three/policy \\
        --wm results/headline_three/world_model --judge results/headline_three/judge \\
        --data data/calibration_three --out benchmarks/results/frozen_vision_three.json

Prints and writes benchmarks/results/frozen_vision.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

from gymnast.utils.atomic import write_json
from gymnast.utils.device import bf16_used
# A sibling script (the script's folder is on the path).
from rl_step import JUDGE, POLICY, ROOT, WORLD_MODEL, time_setting

RESULTS = Path(__file__).parent / "results" / "frozen_vision.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, default=POLICY)
    parser.add_argument("--wm", type=Path, default=WORLD_MODEL)
    parser.add_argument("--judge", type=Path, default=JUDGE)
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of start states")
    parser.add_argument("--tasks", default="reach-v3,push-v3")
    parser.add_argument("--starts", type=int, default=4, help="start states per step (8 rollouts each)")
    parser.add_argument("--steps", type=int, default=3, help="RL steps per round (the first is not timed)")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    rounds: dict[str, list[dict]] = {"encoded_once": [], "encoded_at_every_use": []}
    for _ in range(args.rounds):
        for name, remember in (("encoded_once", True), ("encoded_at_every_use", False)):
            rounds[name].append(time_setting("imagined", f"judge:{args.judge}", args.data, args.steps, args.tasks,
                                             policy=args.policy, wm=args.wm, starts_per_step=args.starts,
                                             freeze=("vision",), kl_coef=0.1, remember_vision=remember))
    result = {
        **{key: {name: [round(r[key], 2) for r in runs] for name, runs in rounds.items()}
           for key in ("step_s", "update_s", "policy_s")},
        "rounds": rounds,
        "tasks": args.tasks,
        "policy": str(args.policy),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "bf16": bf16_used("cpu")},
        "command": " ".join(["benchmarks/frozen_vision.py", *sys.argv[1:]]),
    }
    print(json.dumps({key: result[key] for key in ("step_s", "update_s", "policy_s")}, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
