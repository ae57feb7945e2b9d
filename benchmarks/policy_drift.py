"""How far RL moved a tokenized policy from where it started, read off its action-token
distributions on the evaluation seeds' first frames: why the greedy policy can fall while the
sampled one stands still.

For each policy against the base (the SFT policy), on the first frames of `--episodes` evaluation
seeds of `--task`: the mean token entropy of each, the share of tokens whose argmax changed, the
mean absolute change of the greedy actions (actions in [-1, 1]), KL(base || policy) per token,
and the probability each gives to the base's argmax token.

    .venv/bin/python benchmarks/policy_drift.py --policies runs/push_16x4 runs/push_t05 \
        --task push-v3 --out results/rl/push_scenes/drift.json

Prints the table and writes the JSON.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.envs.starts import evaluation_starts
from gymnast.policy.load import load_policy, policy_env_config
from gymnast.utils.atomic import write_json

ROOT = Path(__file__).resolve().parents[1]


def token_distributions(policy, images: torch.Tensor, instructions: list[str]) -> torch.Tensor:
    """(B, N, V) action-token probabilities at temperature 1."""
    if not hasattr(policy, "logits"):
        raise ValueError(f"{type(policy).__name__} has no action tokens to compare; this measures tokenized policies")
    with torch.no_grad():
        return policy.logits(images, instructions).float().softmax(-1)


def drift(base, policy, images: torch.Tensor, instructions: list[str]) -> dict[str, float]:
    """The statistics of the module docstring, for one policy against `base`."""
    before, after = token_distributions(base, images, instructions), token_distributions(policy, images, instructions)
    greedy_before, greedy_after = before.argmax(-1), after.argmax(-1)  # (B, N)

    def entropy(p: torch.Tensor) -> float:
        return -(p * p.clamp_min(1e-12).log()).sum(-1).mean().item()

    return {
        "entropy_base": entropy(before),
        "entropy": entropy(after),
        "argmax_changed": (greedy_before != greedy_after).float().mean().item(),
        "greedy_action_change": (base.act(images, instructions) - policy.act(images, instructions)).abs().mean().item(),
        "kl_base_to_policy": (before * (before.clamp_min(1e-12).log() - after.clamp_min(1e-12).log())).sum(-1).mean().item(),
        "base_argmax_mass_base": before.gather(-1, greedy_before[..., None]).mean().item(),
        "base_argmax_mass": after.gather(-1, greedy_before[..., None]).mean().item(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, default=Path("results/sft/policy"))
    parser.add_argument("--policies", type=Path, nargs="+", required=True, help="RL runs (their newest checkpoints)")
    parser.add_argument("--task", default="push-v3")
    parser.add_argument("--episodes", type=int, default=50, help="evaluation seeds whose first frames are read")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    base = load_policy(args.base).eval()
    # The views the base policy acts on (several cameras side by side), at its size.
    starts = evaluation_starts([args.task], args.episodes, policy_env_config(EnvConfig(), args.base))
    images = torch.from_numpy(np.stack([start.frames[0] for start in starts]))
    instructions = [start.instruction for start in starts]
    report = {"base": str(args.base), "task": args.task, "episodes": args.episodes, "policies": {}}
    for path in args.policies:
        report["policies"][str(path)] = drift(base, load_policy(path).eval(), images, instructions)
    print(json.dumps(report, indent=1))
    write_json(args.out, report)


if __name__ == "__main__":
    main()
