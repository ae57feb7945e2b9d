"""One GRPO step of a full-size SmolVLA in imagination, timed on a GPU.

The policy is LeRobot's SmolVLA at its published size (`gymnast.policy.lerobot_init.new_smolvla`
with ``full_size``: the SmolVLM2-500M backbone cut to its first 16 layers, the action expert at
0.75 of its width, 512 px images, 10 flow steps, 50 actions predicted a call of which 5 are
executed) with random weights, since no model hub is reachable: the time depends on the
architecture, not on the weights. It acts through gymnast's LeRobot adapter (`--policy
lerobot:PATH`: the flow SDE with a learned noise network, exact log-probabilities) in the
committed world model, and the real `gymnast rl` loop (benchmarks/rl_step.py's `time_setting`)
runs B x G = 8 x 8 = 64 rollouts of 40 actions a step (8 policy calls each, World-Gymnast's
horizon) with the verified reward, then the GRPO update. Reported: the median of the timed steps
(the first warms up), split into imagination, the policy's sampling, the reward and the update.

    .venv/bin/python benchmarks/lerobot_gpu.py [--data data/mt10]

Needs a CUDA device and refuses without one; ``--device cpu --small`` runs a tiny SmolVLA at toy
sizes instead (what the test suite does to keep this script working) and writes only to
``--out``. Prints and writes benchmarks/results/lerobot_gpu.json.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import tempfile
from pathlib import Path

import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.utils.atomic import write_json
from gpu import gpu_device
from rl_step import time_setting

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "lerobot_gpu.json"
FULL = {"starts_per_step": 8, "group_size": 8, "horizon": 40, "steps": 3}
SMALL = {"starts_per_step": 2, "group_size": 2, "horizon": 10, "steps": 2}


def parameters(folder: Path) -> int:
    """The parameters of the LeRobot policy saved in `folder` (read from the file's header)."""
    from safetensors import safe_open

    with safe_open(str(folder / "model.safetensors"), "pt") as weights:
        return sum(math.prod(weights.get_slice(name).get_shape()) for name in weights.keys())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", help="cuda or cuda:N (cpu only with --small)")
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of start states (96 px)")
    parser.add_argument("--tasks", default="reach-v3,push-v3,drawer-open-v3,window-open-v3")
    parser.add_argument("--micro-batch", type=int, default=64, help="policy calls per backward pass of the update")
    parser.add_argument("--small", action="store_true", help="a tiny SmolVLA at toy sizes: measures nothing")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    device = gpu_device(args.device, args.small, args.out, RESULTS, "benchmarks/lerobot_gpu.py")
    from gymnast.policy.lerobot_init import new_smolvla

    sizes = SMALL if args.small else FULL
    with tempfile.TemporaryDirectory() as folder:
        policy = new_smolvla(Path(folder) / "smolvla", full_size=not args.small, chunk=5,
                             predicted=8 if args.small else 50, steps=3 if args.small else 10)
        count = parameters(policy)
        step = time_setting("imagined", "verified", args.data, sizes["steps"], args.tasks, policy=f"lerobot:{policy}",
                            starts_per_step=sizes["starts_per_step"], group_size=sizes["group_size"],
                            horizon=sizes["horizon"], micro_batch=args.micro_batch, device=str(device))
    result = {
        "grpo_step_s": round(step["step_s"], 3),
        "step": step,
        "policy": "SmolVLA (tiny)" if args.small else "SmolVLA, full size (SmolVLM2-500M backbone, 16 layers)",
        "parameters": count,
        "micro_batch": args.micro_batch,
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "torch": torch.__version__,
        "platform": platform.platform(),
        "command": " ".join(["benchmarks/lerobot_gpu.py", *sys.argv[1:]]),
    }
    if device.type == "cuda":
        result["peak_gpu_memory_gib"] = round(torch.cuda.max_memory_allocated(device) / 2**30, 2)
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
