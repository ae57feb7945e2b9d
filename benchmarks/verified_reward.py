"""The verified reward's perceptual distance on one GRPO group: every rollout against its own copy of
the shared reference (pairwise, what the reward computed before) and against the reference's
features computed once (`PerceptualDistance.against_references`, what it computes now). A group of
8 rollouts of 150 frames at 96x96, the two ways taking turns for three rounds (medians compared, so
a busy machine slows both alike); the distances must agree.

    .venv/bin/python benchmarks/verified_reward.py   # -> benchmarks/results/verified_reward.json
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

from gymnast.utils.atomic import write_json
from gymnast.world_model.metrics import PerceptualDistance


def timed(work) -> tuple[float, torch.Tensor]:
    start = time.perf_counter()
    result = work()
    return time.perf_counter() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--group", type=int, default=8)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "verified_reward.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    generator = torch.Generator().manual_seed(0)
    perceptual = PerceptualDistance()
    rollouts = torch.rand(args.group, args.frames, 3, 96, 96, generator=generator)
    reference = torch.rand(1, args.frames, 3, 96, 96, generator=generator)
    index = torch.zeros(args.group, dtype=torch.long)  # the group shares one reference
    rounds = {"pairwise": [], "shared_reference": []}
    for _ in range(3):
        seconds, pairwise = timed(lambda: perceptual(rollouts, reference[index]))
        rounds["pairwise"].append(seconds)
        seconds, shared = timed(lambda: perceptual.against_references(rollouts, reference, index))
        rounds["shared_reference"].append(seconds)
    before, after = (statistics.median(rounds[name]) for name in ("pairwise", "shared_reference"))
    result = {
        "threads": args.threads,
        "group": args.group,
        "frames": args.frames,
        "pairwise_s": round(before, 3),
        "shared_reference_s": round(after, 3),
        "speedup": round(before / after, 3),
        "max_abs_difference": float((pairwise - shared).abs().max()),
        "rounds": {name: [round(t, 3) for t in times] for name, times in rounds.items()},
    }
    print(result)
    write_json(args.out, result)


if __name__ == "__main__":
    main()
