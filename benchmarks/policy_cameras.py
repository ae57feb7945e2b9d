"""What more cameras and the robot's state cost the embedded VLA: an SFT step, a greedy call and RL's sampling.

    .venv/bin/python benchmarks/policy_cameras.py [--rounds 3]

The one-camera, the two-camera (front + gripper, side by side), the three-camera (and hand) and the
two-camera policy that also reads the robot's state (`--robot-state`, one more token) of the default
architecture take turns for a few rounds, in one process, and each keeps its best time, so that a
noisy shared machine shows in all alike. An SFT step is the imitation loss forward and backward
on a batch of 64 with the image encoder under bfloat16 autocast where the CPU computes it natively,
as `gymnast sft` trains. Untrained weights: speed does not depend on them. Prints and writes
benchmarks/results/policy_cameras.json.
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
from gymnast.utils.device import bf16_status

RESULTS = Path(__file__).parent / "results" / "policy_cameras.json"
SETUPS = {"front": VLAConfig(), "front+gripper": VLAConfig(cameras=("front", "gripper")),
          "front+gripper+hand": VLAConfig(cameras=("front", "gripper", "hand")),
          "front+gripper+state": VLAConfig(cameras=("front", "gripper"), state_dim=4)}


def best_seconds(fn, repeats: int) -> float:
    """The fastest of `repeats` calls, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(model: EmbeddedVLA, repeats: int) -> dict[str, float]:
    size, views = model.config.image_size, len(model.config.cameras)
    generator = torch.Generator().manual_seed(0)

    def images(batch: int) -> torch.Tensor:
        return torch.randint(0, 256, (batch, size, views * size, 3), dtype=torch.uint8, generator=generator)

    def states(batch: int) -> dict[str, torch.Tensor]:  # hand xyz and gripper, for a policy that reads them
        return {"states": torch.rand(batch, model.state_dim, generator=generator)} if model.state_dim else {}

    train_images, texts = images(64), ["open the drawer"] * 64
    chunks, valid = torch.rand(64, model.chunk_size, model.action_dim) * 2 - 1, torch.ones(64, model.chunk_size, dtype=torch.bool)

    def sft_step() -> None:
        model.train()
        loss, _ = model.imitation_loss(train_images, texts, chunks, valid, bf16=True, **states(64))
        loss.backward()
        model.zero_grad(set_to_none=True)

    one, many = images(1), images(256)
    step = best_seconds(sft_step, repeats)
    model.eval()
    one_state, many_states = states(1), states(256)
    act = best_seconds(lambda: model.act(one, ["open the drawer"], **one_state), 5 * repeats)
    sample = best_seconds(lambda: model.sample(many, ["open the drawer"] * 256, temperature=1.0, **many_states), repeats)
    return {"sft_step_s_b64": step, "act_latency_ms_b1": 1000 * act, "sample_obs_per_s_b256": 256 / sample}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    torch.manual_seed(0)
    models = {name: EmbeddedVLA(config) for name, config in SETUPS.items()}
    best: dict[str, dict[str, float]] = {}
    for _ in range(args.rounds):
        for name, model in models.items():
            for key, value in measure(model, args.repeats).items():
                keep = max if key.endswith("per_s_b256") else min
                best.setdefault(name, {})[key] = keep(best.get(name, {}).get(key, value), value)
    rounded = {name: {key: round(value, 4) for key, value in figures.items()} for name, figures in best.items()}
    ratio = {key: round(best["front+gripper"][key] / best["front"][key], 2) for key in best["front"]}
    three = {key: round(best["front+gripper+hand"][key] / best["front"][key], 2) for key in best["front"]}
    state = {key: round(best["front+gripper+state"][key] / best["front+gripper"][key], 2) for key in best["front"]}
    result = {"setups": rounded, "two_over_one": ratio, "three_over_one": three, "state_over_none": state,
              "parameters": {name: sum(p.numel() for p in model.parameters()) for name, model in models.items()},
              "bf16": bf16_status(), "threads": torch.get_num_threads(),
              "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()}}
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
