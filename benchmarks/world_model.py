"""Imagined frames per second against the real env's rendered steps per second, on this machine.

The world model imagines B rollouts at once (one `step` call per chunk of K actions, one frame per
action); the real env renders one step at a time. A frame is one observation: for a world model of
several cameras, every camera's view of it (the real env then renders those cameras too). Both are measured in the same run, so the
ratio is not fooled by a busy machine: batch-64 imagination and the real env alternate for a few
rounds and the medians are compared. The real env is also measured in as many processes as the
world model has threads (the same cores), a stricter comparison reported beside it.

    .venv/bin/python benchmarks/world_model.py [--wm RUN] [--against RUN] [--chunk 5] [--steps 40] [--out JSON]

Without --wm, an untrained model of the default architecture is timed (the speed does not depend
on the weights). With --state, a grounded state model (`gymnast train-state`) imagines the state
and reads the reward of the same batch-64 rollouts beside the video model, in the same rounds
(`imagined_fps_b64_grounded`: frames per second with both). With --against, a second world model (another backend, say) is timed at batch 64
in the same rounds, so the two compare on equal terms. Prints and writes --out (default
benchmarks/results/world_model.json).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import time
from pathlib import Path

import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.utils.atomic import write_json
from gymnast.world_model.base import load_world_model
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.state_model import load_state_model
from gymnast.world_model.views import model_views, replay_cameras


RESULTS = Path(__file__).parent / "results" / "world_model.json"


def random_context(model, batch: int) -> torch.Tensor:
    """(B, C, H, V*W, 3) uint8 noise frames of the model's views side by side."""
    size = model.image_size
    return torch.randint(0, 256, (batch, model.context_frames, size, model_views(model) * size, 3), dtype=torch.uint8)


def imagined_fps(model, batch: int, chunk: int, steps: int) -> tuple[float, float]:
    """(frames per second, the process's peak resident memory so far in MiB) for `steps` chunks of a
    batch of rollouts."""
    actions = torch.rand(steps, batch, chunk, model.action_dim) * 2 - 1
    state = model.init_state(random_context(model, batch))
    model.step(state, actions[0])  # warm-up: first calls allocate and pick kernels
    started = time.perf_counter()
    for k in range(steps):
        state, _ = model.step(state, actions[k])
    elapsed = time.perf_counter() - started
    return batch * chunk * steps / elapsed, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def grounded_fps(model, state_model, batch: int, chunk: int, steps: int) -> float:
    """Frames per second of imagining `steps` chunks of a batch with the video model and, for the
    same actions, the state model's states and rewards (as `--reward state:RUN` scores a rollout)."""
    context = random_context(model, batch)
    actions = torch.rand(steps, batch, chunk, model.action_dim) * 2 - 1
    start, text = torch.randn(batch, state_model.config.state_dim), torch.randn(batch, state_model.config.text_dim)
    state = model.init_state(context)
    model.step(state, actions[0])  # warm-up
    started = time.perf_counter()
    for k in range(steps):
        state, _ = model.step(state, actions[k])
    state_model.imagine(start, actions.permute(1, 0, 2, 3).flatten(1, 2), text)  # (B, steps x chunk, A)
    return batch * chunk * steps / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wm", type=Path, default=None, help="world-model run to time (default: an untrained default model)")
    parser.add_argument("--chunk", type=int, default=5, help="actions per step call (the policy's chunk)")
    parser.add_argument("--steps", type=int, default=40, help="step calls per batch size")
    parser.add_argument("--real-steps", type=int, default=1500, help="real env steps per process")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of the batch-64 and real-env measurements")
    parser.add_argument("--against", type=Path, default=None, help="another world-model run timed at batch 64 in the same rounds")
    parser.add_argument("--state", type=Path, default=None, help="a state-model run timed beside the video model")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the JSON to write")
    args = parser.parse_args()
    from real_env import steps_per_second  # the same measurement as benchmarks/real_env.py

    model = load_world_model(args.wm) if args.wm else EmbeddedWorldModel(EmbeddedWorldModelConfig()).eval()
    threads = torch.get_num_threads()
    cameras = replay_cameras(model)  # the real env renders what the model imagines
    result: dict = {}
    fps, peak = imagined_fps(model, 1, args.chunk, args.steps * 8)
    result |= {"imagined_fps_b1": round(fps, 1), "peak_rss_mib_b1": round(peak, 1)}
    # The headline ratio: imagination at batch 64 and the real env, measured in alternation so a
    # noisy neighbour slows both alike; the medians of the rounds are reported.
    other = load_world_model(args.against) if args.against else None
    state_model = load_state_model(args.state) if args.state else None
    imagined, real, against, grounded = [], [], [], []
    for _ in range(args.rounds):
        if other is not None:
            against.append(imagined_fps(other, 64, args.chunk, args.steps)[0])
        if state_model is not None:
            grounded.append(grounded_fps(model, state_model, 64, args.chunk, args.steps))
        fps, peak = imagined_fps(model, 64, args.chunk, args.steps)
        imagined.append(fps)
        real.append(steps_per_second("drawer-open-v3", args.real_steps, model.image_size, 1, cameras))
    result["imagined_fps_b64"] = round(statistics.median(imagined), 1)
    result["peak_rss_mib_b64"] = round(peak, 1)
    real_one = statistics.median(real)
    fps, peak = imagined_fps(model, 256, args.chunk, args.steps)  # last: the peak memory only grows
    result |= {"imagined_fps_b256": round(fps, 1), "peak_rss_mib_b256": round(peak, 1)}
    real_all = steps_per_second("drawer-open-v3", args.real_steps, model.image_size, threads, cameras)
    result |= {
        "real_env_fps": round(real_one, 1),
        f"real_env_fps_{threads}proc": round(real_all, 1),
        "ratio_b64": round(result["imagined_fps_b64"] / real_one, 2),
        "rounds": {"imagined_fps_b64": [round(x, 1) for x in imagined], "real_env_fps": [round(x, 1) for x in real]},
        f"ratio_b64_vs_{threads}proc": round(result["imagined_fps_b64"] / real_all, 2),
        "torch_threads": threads,
        "image_size": model.image_size,
        "cameras": list(cameras),
        "chunk": args.chunk,
        "model": str(args.wm) if args.wm else "untrained default architecture",
        "parameters": sum(p.numel() for p in model.parameters()),
        "bf16": getattr(getattr(getattr(model, "model", model), "config", None), "bf16", None),  # a multi-view model's backend's
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    if other is not None:  # (its memory is in the peaks above from batch 64 on)
        result |= {"against": str(args.against), "against_imagined_fps_b64": round(statistics.median(against), 1),
                   "ratio_b64_vs_against": round(result["imagined_fps_b64"] / statistics.median(against), 2)}
        result["rounds"]["against_imagined_fps_b64"] = [round(x, 1) for x in against]
    if state_model is not None:
        result |= {"state": str(args.state), "imagined_fps_b64_grounded": round(statistics.median(grounded), 1),
                   "ratio_b64_grounded": round(statistics.median(grounded) / real_one, 2)}
        result["rounds"]["imagined_fps_b64_grounded"] = [round(x, 1) for x in grounded]
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
