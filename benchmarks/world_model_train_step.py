"""Seconds per embedded world-model training step: a frame per action against a frame per chunk.

One step is what `gymnast train-wm` does per batch: imagine B clips open-loop from their context
under their actions, score the frames, backpropagate through the whole recurrence and update.
A model of one frame per N actions (`--actions-per-frame`) takes F / N latent steps and decodes
F / N frames per clip (its clips are F rounded up to whole chunks). The two are timed in
alternating rounds on random clips of the default architecture's size, so a busy machine slows
both alike; the medians are reported.

    .venv/bin/python benchmarks/world_model_train_step.py [--actions-per-frame 5] [--future 32] [--out JSON]

Prints and writes --out (default benchmarks/results/world_model_train_step.json).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import time
from pathlib import Path

import torch

from gymnast.utils.atomic import write_json
from gymnast.world_model.data import ClipBatch
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.train import WorldModelTrainConfig, clip_loss, future_at

RESULTS = Path(__file__).parent / "results" / "world_model_train_step.json"


def random_clips(config: EmbeddedWorldModelConfig, batch: int, future: int) -> ClipBatch:
    """B random clips: C context frames, F actions and their F target frames."""
    size, generator = config.image_size, torch.Generator().manual_seed(0)
    frames = torch.randint(0, 256, (batch, config.context_frames + future, size, size, 3), dtype=torch.uint8, generator=generator)
    actions = torch.rand(batch, future, config.action_dim, generator=generator) * 2 - 1
    return ClipBatch(frames[:, : config.context_frames], actions, frames[:, config.context_frames :], torch.zeros(batch, future + 1, 0))


def seconds_per_step(model: EmbeddedWorldModel, clips: ClipBatch, steps: int) -> float:
    """Mean wall seconds of `steps` training steps (one warm-up step first)."""
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    model.train()

    def step() -> None:
        loss, _ = clip_loss(model, clips)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    step()
    started = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions-per-frame", type=int, default=5, help="N of the model of one frame per chunk")
    parser.add_argument("--future", type=int, default=32, help="actions per training clip (train-wm's --future)")
    parser.add_argument("--batch", type=int, default=8, help="clips per step (train-wm's batch_size)")
    parser.add_argument("--steps", type=int, default=5, help="timed steps per round")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the JSON to write")
    args = parser.parse_args()

    per_action = EmbeddedWorldModelConfig()
    per_chunk = dataclasses.replace(per_action, actions_per_frame=args.actions_per_frame)
    runs = {}
    for name, config in (("per_action", per_action), ("per_chunk", per_chunk)):
        future = future_at(1, WorldModelTrainConfig(future=args.future, warmup_future=0.0, model=config))
        torch.manual_seed(0)
        runs[name] = (EmbeddedWorldModel(config), random_clips(config, args.batch, future), future)
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(args.rounds):
        for name, (model, clips, _) in runs.items():
            times[name].append(seconds_per_step(model, clips, args.steps))
    medians = {name: statistics.median(values) for name, values in times.items()}
    result = {
        "seconds_per_step_per_action": round(medians["per_action"], 4),
        "seconds_per_step_per_chunk": round(medians["per_chunk"], 4),
        "speedup": round(medians["per_action"] / medians["per_chunk"], 2),
        "actions_per_frame": args.actions_per_frame,
        "clip_actions": {name: future for name, (_, _, future) in runs.items()},
        "batch": args.batch,
        "rounds": {name: [round(t, 4) for t in values] for name, values in times.items()},
        "bf16": per_action.bf16,
        "torch_threads": torch.get_num_threads(),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
