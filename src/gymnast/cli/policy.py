"""`gymnast` commands that train and measure a policy: behaviour cloning and real-world evaluation."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated, Literal

import tyro

from gymnast.cli.flags import KeyFlags, Preset, key_overrides
from gymnast.cli.settings import resolve, saved_inputs
from gymnast.config import CameraNames
from gymnast.data.frames import Fit
from gymnast.utils.trackers import TrackerNames
from gymnast.eval.evaluate import EvalConfig


def sft(
    out: Path,
    data: Path | None = None,
    preset: Preset = "full",
    resume: bool = False,
    demos_per_task: int | None = None,
    steps: int | None = None,
    vision: Literal["cnn", "efficientnet"] | None = None,
    tasks: str | None = None,
    seed: int | None = None,
    camera: str | None = None,
    cameras: CameraNames = (),
    policy_type: Literal["tokens", "flow"] | None = None,
    robot_state: bool | None = None,
    fit: Fit | None = None,
    device: str | None = None,
    tracker: TrackerNames | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
    init: Path | None = None,
    imagined_by: Path | None = None,
) -> None:
    """Behaviour-clone a VLA on N successful expert demonstrations per task.

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json.
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        preset: debug (seconds), demo (minutes) or full (the default policy).
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        demos_per_task: override the preset's demonstrations per task.
        steps: override the preset's optimizer steps.
        vision: override the image encoder.
        tasks: restrict to these tasks (comma-separated).
        seed: override the seed.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras the policy sees side by side, the primary first (e.g.
            front,gripper); saved with the policy, so eval and rl render the same views. Default: --camera alone.
        policy_type: the policy family: tokens (the tokenized VLA, the default) or flow (the
            flow-matching VLA of VLA-RFT). Saved with the checkpoint; rl and eval read it there.
        robot_state: True: the policy also reads the robot's state (the dataset's observation.state,
            e.g. hand xyz and gripper); eval and rl give it the simulator's, imagination a state model's.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N; --resume may change it.
        tracker: where the run also logs its settings, metrics: none, or any of tensorboard and
            wandb, comma-separated (wandb: the [wandb] extra; WANDB_MODE=offline keeps it on disk);
            default: none; --resume may change it.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
        init: start from this policy run's weights (its architecture kept) instead of a fresh
            model: fine-tuning.
        imagined_by: a world-model run: half of every batch is then the demonstrations as it
            imagines them under their own actions (the frames a policy reads, one per action chunk),
            so that the policy learns to act on imagined frames as on real ones, the sight it has
            when it practises in that world model.
    """
    from gymnast.policy.sft import SFT_PRESETS, SamplesFrom, saved_sft_config, train_sft

    config, inputs = resolve(
        "sft", out, resume, SFT_PRESETS[preset], inputs={"data": data, "init": init, "imagined_by": imagined_by},
        required=("data",),
        overrides={"demos_per_task": demos_per_task, "steps": steps, "tasks": tasks, "seed": seed,
                   "vla.vision": vision, "camera": camera, "cameras": cameras or None, "policy": policy_type,
                   "robot_state": robot_state, "fit": fit, "device": device, "tracker": tracker,
                   **key_overrides(keys)},
        saved=lambda: (saved_sft_config(out), saved_inputs(out, "data", "init", "imagined_by")))
    samples_from = None
    if inputs["imagined_by"] is not None:
        from gymnast.utils.device import resolve_device
        from gymnast.world_model.reimagine import imagined_demos

        wm = inputs["imagined_by"]
        samples_from = SamplesFrom(functools.partial(imagined_demos, wm=wm, device=resolve_device(config.device)),
                                   {"imagined_by": str(wm)})
    checkpoint = train_sft(inputs["data"], out, config, resume=resume, init=inputs["init"], samples_from=samples_from)
    print(f"policy: {checkpoint}")


def evaluate_command(
    policy: str,
    out: Path,
    config: Annotated[EvalConfig, tyro.conf.arg(name="")] = EvalConfig(),
) -> None:
    """Evaluate a policy in the real world on held-out seeds: success per task with 95% CIs.

    Args:
        policy: an SFT/RL run directory (its newest checkpoint), 'expert' for the scripted reference,
            lerobot:PATH for a LeRobot pretrained_model folder, python:MODULE:FACTORY[@ARG] for your own
            (FACTORY(ARG) returns it) or plugin:NAME[@ARG] for a factory an installed package registers in
            the entry-point group gymnast.policies (the last three act in this process: --workers 1).
        out: JSON report (per-episode records included); videos are saved beside it in <name>_videos/.
        config: tasks, episodes, perturbation, gap and workers.
    """
    from gymnast.eval.evaluate import evaluate, format_summary
    from gymnast.policy.load import is_lerobot, load_policy
    from gymnast.utils.plugins import is_plugin

    # A LeRobot folder or a user's factory is no run directory for the workers to load: it acts in this process.
    report = evaluate(load_policy(policy) if is_lerobot(policy) or is_plugin(policy) else policy, config, out)
    print(format_summary(report))
    print(f"report: {out}")


def check_policy(policy: str, batch: int = 2, seed: int = 0) -> None:
    """Check a policy against the Policy contract that RL and evaluation rely on, and name each breach
    with what to change: log_prob of the sampled tokens equal to the logp sample() returned (GRPO's
    ratio starts at 1), a deterministic greedy act(), actions of the declared chunk_size and
    action_dim, sampling reproducible from the generator given, and the robot state where
    state_dim > 0. Exits with status 1 when it finds a breach.

    Args:
        policy: the policy: RUN (an SFT or RL run or checkpoint directory), lerobot:PATH (a LeRobot
            pretrained_model folder), python:MODULE:FACTORY[@ARG] (your own: FACTORY(ARG) returns it) or
            plugin:NAME[@ARG] (a factory an installed package registers in the entry-point group
            gymnast.policies).
        batch: images per call.
        seed: of the synthetic images and of the generators.
    """
    from gymnast.policy.check import check_policy as check
    from gymnast.policy.load import load_policy
    from gymnast.utils.plugins import format_breaches

    breaches = check(load_policy(policy), batch=batch, seed=seed)
    print(format_breaches(f"policy {policy}", breaches))
    if breaches:
        raise SystemExit(1)
