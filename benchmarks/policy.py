"""Embedded VLA speed: greedy-act latency at batch 1 and sampling throughput at batch 256.

    .venv/bin/python benchmarks/policy.py [--vision cnn] [--repeats 30]

Batch 1 is what a real-world rollout pays per policy call (every K steps); batch 256 is what RL
pays per imagined step over a whole group of rollouts. Untrained weights: speed does not depend
on them. Prints and writes benchmarks/results/policy.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import torch

from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.atomic import write_json

RESULTS = Path(__file__).parent / "results" / "policy.json"


def seconds_per_call(fn, repeats: int) -> float:
    """Median wall time of `repeats` calls after two warm-up calls."""
    fn(), fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vision", default=VLAConfig().vision)
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    torch.manual_seed(0)
    config = VLAConfig(vision=args.vision)
    model = EmbeddedVLA(config).eval()
    size = config.image_size

    def images(batch: int) -> torch.Tensor:
        return torch.randint(0, 256, (batch, size, size, 3), dtype=torch.uint8)

    one, texts_one = images(1), ["open the drawer"]
    many, texts_many = images(256), ["open the drawer"] * 256
    latency = seconds_per_call(lambda: model.act(one, texts_one), args.repeats)
    batch_time = seconds_per_call(lambda: model.sample(many, texts_many, temperature=1.6), max(3, args.repeats // 5))
    result = {
        "vision": args.vision,
        "parameters": sum(p.numel() for p in model.parameters()),
        "act_latency_ms_b1": round(1000 * latency, 2),
        "sample_throughput_b256_obs_per_s": round(256 / batch_time, 1),
        "sample_ms_b256": round(1000 * batch_time, 1),
        "threads": torch.get_num_threads(),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
