"""GPU figures: imagination through the imagined env, training steps, and one RL step with the judge.

What it measures, each on the device with the library's own settings (bf16 autocast where the
models use it):
- ``imagined_fps_b1024`` / ``_b4096``: frames per second through `BatchedImaginedEnv` (the env RL
  runs in, frames copied back to the host every step, not just the model) with the committed
  world model, batches of 1024 and 4096 rollouts of random action chunks;
  ``model_fps_b*``: the world model's own `step` at the same batches, nothing copied to the host
  (what the env could reach);
  ``imagined_obs_per_s_two_cameras_b*`` / ``_three_cameras_b*``: the same with two (front, gripper)
  and three (and hand) cameras' views of every rollout (observations of all views per second);
- ``wm_train_step_s``: one optimizer step of `gymnast train-wm` (clips of 32 future frames,
  backpropagated through the rollout) at batch 64, for the default model and for the larger
  model of the embedded backend's gpu preset when it has one;
- ``policy_train_obs_per_s`` / ``policy_sample_obs_per_s``: observations per second through one SFT
  update (the imitation loss, backward and AdamW) and through RL's sampling of the default policy at
  batch 4096, for each view setup of benchmarks/policy_cameras.py (one, two or three cameras, with or
  without the robot's state);
- ``rl_step_s``: one `gymnast rl --env imagined` step of 256 rollouts (32 starts x 8) of 150
  actions with the committed judge's reward, policy update included (the median of the timed steps);
  ``rl_segment_step``: the same number of rollouts as short segments, 20 actions from uniformly drawn
  real keyframes, with the committed state-model ensemble's reward (segment practice, docs/rl.md);
- ``chunk_model``: the same imagination (actions per second: the model imagines one frame per 5
  actions and repeats it), training step and judge RL step for the committed frame-per-chunk model
  (results/world_model/chunks/wm, `train-wm --actions-per-frame 5`), measured in the same run as
  the committed model's figures above so that the two compare;
- with ``--profile``: the profiler's table of two more judge steps (the ops that take the most host and
  device time), written beside ``--out`` as ``<out>.profile.txt``.

Goals on one H100: imagination >= 250,000 frames/s at batch 4096, an RL step <= 2 s.

    .venv/bin/python benchmarks/gpu.py [--data data/mt10]

It needs a CUDA device and refuses without one: CPU figures live in the other benchmarks. With
``--device cpu --small`` it runs every measurement at toy sizes (what the test suite does to keep
this script working) and writes only to ``--out``. Prints and writes benchmarks/results/gpu.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.atomic import write_json
from gymnast.utils.device import resolve_device
from gymnast.utils.optim import gradient_step
from gymnast.world_model.base import load_world_model
from gymnast.world_model.data import ClipBatch
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.train import WM_PRESETS, clip_loss
from gymnast.world_model.views import model_views, with_cameras
# Sibling scripts (the script's folder is on the path).
from policy_cameras import SETUPS as POLICY_SETUPS
from rl_step import time_setting

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "gpu.json"
WORLD_MODEL, JUDGE = ROOT / "results/world_model/wm", ROOT / "results/judge/video_judge"
STATE_ENSEMBLE = ROOT / "results/world_model/state_v5"
CHUNK_MODEL = ROOT / "results/world_model/chunks/wm"
SEVERAL_CAMERAS = {"two_cameras": ("front", "gripper"), "three_cameras": ("front", "gripper", "hand")}
SKIPPABLE = ("imagine", "wm", "policy", "rl", "chunk")


@dataclasses.dataclass(frozen=True)
class Sizes:
    """How big each measurement is."""

    imagine_batches: tuple[int, ...] = (1024, 4096)
    imagine_steps: int = 20
    wm_batch: int = 64
    wm_future: int = 32
    policy_batch: int = 4096
    rl_starts: int = 32
    rl_group: int = 8
    rl_horizon: int = 150
    rl_segment: int = 20
    rl_steps: int = 3
    repeats: int = 5


SMALL = Sizes(imagine_batches=(4, 8), imagine_steps=2, wm_batch=2, wm_future=4, policy_batch=4, rl_starts=2, rl_group=2,
              rl_horizon=10, rl_segment=5, rl_steps=2, repeats=1)


def synchronize(device: torch.device) -> None:
    """Waits for the device's queued work (timings would otherwise end before the GPU does)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(fn, device: torch.device, repeats: int) -> float:
    """Median seconds of `repeats` calls of `fn`, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        synchronize(device)
        started = time.perf_counter()
        fn()
        synchronize(device)
        times.append(time.perf_counter() - started)
    return sorted(times)[len(times) // 2]


def imagined_env_fps(model, batch: int, steps: int, chunk: int = 5) -> float:
    """Observations per second of `steps` env steps of `batch` rollouts (after one warm-up step)."""
    rng = np.random.default_rng(0)
    size = model.image_size
    env = BatchedImaginedEnv(model, batch, chunk_size=chunk, horizon=(steps + 1) * chunk)
    # Several cameras' views side by side (gymnast.world_model.views): one observation is all of them.
    frames = rng.integers(0, 256, (batch, model.context_frames, size, size * model_views(model), 3), dtype=np.uint8)
    env.reset(seed=0, options={"frames": frames, "instructions": ["reach the goal"] * batch})
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = rng.uniform(low, high, (steps + 1, batch, *low.shape)).astype(np.float32)
    env.step(actions[0])
    started = time.perf_counter()
    for k in range(1, steps + 1):
        env.step(actions[k])  # returns host frames, so the device has finished
    return batch * chunk * steps / (time.perf_counter() - started)


def model_fps(model, batch: int, device: torch.device, repeats: int, chunk: int = 5) -> float:
    """Frames per second of the world model's own `step` (no env, nothing copied to the host)."""
    torch.manual_seed(0)
    size = model.image_size
    context = torch.randint(0, 256, (batch, model.context_frames, size, size * model_views(model), 3),
                            dtype=torch.uint8, device=device)
    actions = torch.rand(batch, chunk, model.action_dim, device=device) * 2 - 1
    with torch.inference_mode():
        state = model.init_state(context)
        return batch * chunk / timed(lambda: model.step(state, actions), device, repeats)


def wm_train_step_s(config: EmbeddedWorldModelConfig, sizes: Sizes, device: torch.device) -> float:
    """Seconds of one train-wm optimizer step at `sizes.wm_batch` clips of `sizes.wm_future` frames
    (rounded up to whole chunks for a model of one frame per chunk, as train-wm does)."""
    torch.manual_seed(0)
    model = EmbeddedWorldModel(config).to(device).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: 1.0)
    b, c, size = sizes.wm_batch, config.context_frames, config.image_size
    f = -(-sizes.wm_future // config.actions_per_frame) * config.actions_per_frame
    clips = ClipBatch(torch.randint(0, 256, (b, c, size, size, 3), dtype=torch.uint8, device=device),
                      torch.rand(b, f, config.action_dim, device=device) * 2 - 1,
                      torch.randint(0, 256, (b, f, size, size, 3), dtype=torch.uint8, device=device),
                      torch.zeros(b, f, 0, device=device))
    return timed(lambda: gradient_step(clip_loss(model, clips)[0], model, optimizer, schedule), device, sizes.repeats)


def policy_obs_per_s(config: VLAConfig, sizes: Sizes, device: torch.device) -> dict[str, int]:
    """Observations per second through one SFT update and through RL's sampling of a policy of
    `config` at `sizes.policy_batch` (untrained weights: the speed does not depend on them)."""
    torch.manual_seed(0)
    model = EmbeddedVLA(config, pretrained_vision=False).to(device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: 1.0)
    b, size, views = sizes.policy_batch, config.image_size, len(config.cameras)
    # Several cameras' views side by side, as the datasets' loader hands them to the policy.
    images = torch.randint(0, 256, (b, size, views * size, 3), dtype=torch.uint8)
    texts = ["open the drawer", "push the puck to the goal"] * (b // 2) + ["reach the goal"] * (b % 2)
    chunks = torch.rand(b, config.chunk_size, model.action_dim) * 2 - 1
    valid = torch.ones(b, config.chunk_size, dtype=torch.bool)
    states = {"states": torch.rand(b, model.state_dim)} if model.state_dim else {}

    def update() -> None:
        model.train()
        loss, _ = model.imitation_loss(images, texts, chunks, valid, bf16=True, **states)
        gradient_step(loss, model, optimizer, schedule)

    def sample() -> None:
        model.eval()
        with torch.inference_mode():
            model.sample(images, texts, temperature=1.0, **states)

    return {"train": round(b / timed(update, device, sizes.repeats)), "sample": round(b / timed(sample, device, sizes.repeats))}


def rl_step(data: Path, sizes: Sizes, device: torch.device, tasks: str, wm: Path = WORLD_MODEL) -> dict:
    """The timings of one imagined RL step with the judge's reward (benchmarks/rl_step.py's measurement)."""
    return time_setting("imagined", f"judge:{JUDGE}", data, sizes.rl_steps, tasks, wm=wm, starts_per_step=sizes.rl_starts,
                        group_size=sizes.rl_group, horizon=sizes.rl_horizon, device=str(device))


def chunk_model_figures(data: Path, sizes: Sizes, device: torch.device, tasks: str, skip: set[str]) -> dict:
    """The committed frame-per-chunk model's imagination, training step and judge RL step (each
    part unless `skip` names its measurement)."""
    model = load_world_model(CHUNK_MODEL).to(device).eval()
    figures: dict = {"actions_per_frame": model.config.actions_per_frame}
    if "imagine" not in skip:
        figures |= {f"imagined_actions_per_s_b{b}": round(imagined_env_fps(model, b, sizes.imagine_steps))
                    for b in sizes.imagine_batches}
        figures |= {f"model_actions_per_s_b{b}": round(model_fps(model, b, device, sizes.repeats))
                    for b in sizes.imagine_batches}
    if "wm" not in skip:
        figures["wm_train_step_s"] = round(wm_train_step_s(model.config, sizes, device), 4)
    if "rl" not in skip:
        figures["rl_step"] = rl_step(data, sizes, device, tasks, wm=CHUNK_MODEL)
        figures["rl_step_s"] = round(figures["rl_step"]["step_s"], 3)
    return figures


def rl_segment_step(data: Path, sizes: Sizes, device: torch.device, tasks: str) -> dict:
    """The timings of one imagined RL step of short segments from real keyframes with the state ensemble's reward."""
    return time_setting("imagined", f"state:{STATE_ENSEMBLE}", data, sizes.rl_steps, tasks,
                        starts_per_step=sizes.rl_starts, group_size=sizes.rl_group, horizon=sizes.rl_segment,
                        eval_horizon=sizes.rl_horizon, keyframes="uniform", device=str(device))


def profile_rl_step(data: Path, sizes: Sizes, device: torch.device, tasks: str, out: Path) -> None:
    """Writes the profiler's tables (by host time and by device time) of two judge RL steps to `out`."""
    from torch.profiler import ProfilerActivity, profile

    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with profile(activities=activities) as profiler:
        rl_step(data, dataclasses.replace(sizes, rl_steps=2), device, tasks)  # the first step is a warm-up
    table = profiler.key_averages()
    sort_keys = ["self_cpu_time_total"] + (["self_cuda_time_total"] if device.type == "cuda" else [])
    out.write_text("\n\n".join(f"sorted by {key}\n{table.table(sort_by=key, row_limit=40)}" for key in sort_keys))


def gpu_device(name: str, small: bool, out: Path, results: Path, script: str) -> torch.device:
    """The device a GPU benchmark runs on; exits unless it is a GPU or the run is `small` (toy
    sizes, which must not overwrite the committed `results`)."""
    device = resolve_device(name)
    if device.type != "cuda" and not small:
        sys.exit(f"{script} measures a GPU, and --device {name} is not one; "
                 "on the CPU run the other benchmarks (or add --small to check this script)")
    if small and out == results:
        sys.exit("--small measures nothing worth keeping: give --out somewhere other than " + str(results))
    return device


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", help="cuda or cuda:N (cpu only with --small)")
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of RL start states (96 px)")
    parser.add_argument("--tasks", default="reach-v3,push-v3,drawer-open-v3,window-open-v3")
    parser.add_argument("--small", action="store_true", help="toy sizes: checks the script runs, measures nothing")
    parser.add_argument("--skip", default="", help=f"measurements to leave out, comma-separated, of {SKIPPABLE} "
                        "(policy and rl need the sentence encoder's package, for the policy's instructions)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--profile", action="store_true", help="also profile two judge RL steps (<out>.profile.txt)")
    args = parser.parse_args()
    skip = {name for name in args.skip.split(",") if name}
    if skip - set(SKIPPABLE):
        sys.exit(f"--skip {args.skip}: unknown {sorted(skip - set(SKIPPABLE))}; the measurements are {SKIPPABLE}")
    device = gpu_device(args.device, args.small, args.out, RESULTS, "benchmarks/gpu.py")
    sizes = SMALL if args.small else Sizes()

    world_model = load_world_model(WORLD_MODEL).to(device).eval()
    result: dict = {}
    if "imagine" not in skip:
        result |= {f"imagined_fps_b{b}": round(imagined_env_fps(world_model, b, sizes.imagine_steps))
                   for b in sizes.imagine_batches}
        result |= {f"model_fps_b{b}": round(model_fps(world_model, b, device, sizes.repeats))
                   for b in sizes.imagine_batches}
        # The same model imagining several cameras' views of each rollout (train-wm --cameras front,gripper).
        for name, cameras in SEVERAL_CAMERAS.items():
            several = with_cameras(world_model, cameras)
            result |= {f"imagined_obs_per_s_{name}_b{b}": round(imagined_env_fps(several, b, sizes.imagine_steps))
                       for b in sizes.imagine_batches}
    if "wm" not in skip:
        default_wm = dataclasses.replace(EmbeddedWorldModelConfig(), image_size=world_model.image_size)
        result["wm_train_step_s"] = {"default": round(wm_train_step_s(default_wm, sizes, device), 4)}
        if "gpu" in WM_PRESETS:
            large = dataclasses.replace(WM_PRESETS["gpu"].model, image_size=world_model.image_size)
            result["wm_train_step_s"]["gpu_preset"] = round(wm_train_step_s(large, sizes, device), 4)
    if "policy" not in skip:
        speeds = {name: policy_obs_per_s(config, sizes, device) for name, config in POLICY_SETUPS.items()}
        result["policy_train_obs_per_s"] = {name: speed["train"] for name, speed in speeds.items()}
        result["policy_sample_obs_per_s"] = {name: speed["sample"] for name, speed in speeds.items()}
    if "rl" not in skip:
        rl = rl_step(args.data, sizes, device, args.tasks)
        result |= {"rl_step_s": round(rl["step_s"], 3), "rl_step": rl,
                   "rl_segment_step": rl_segment_step(args.data, sizes, device, args.tasks)}
        if args.profile:
            profile_rl_step(args.data, sizes, device, args.tasks, args.out.with_suffix(".profile.txt"))
    if "chunk" not in skip:
        result["chunk_model"] = chunk_model_figures(args.data, sizes, device, args.tasks, skip)
    if skip:
        result["not_measured"] = sorted(skip)
    result |= {
        "sizes": dataclasses.asdict(sizes),
        "goals": {"imagined_fps_b4096": 250_000, "rl_step_s": 2.0},
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "torch": torch.__version__,
        "platform": platform.platform(),
        "command": " ".join(["benchmarks/gpu.py", *sys.argv[1:]]),
    }
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
