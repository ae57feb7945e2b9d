"""`gymnast` commands that train, serve and measure success judges."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Literal

import tyro

from gymnast.cli.flags import GPUPreset, KeyFlags, feature_keys, key_overrides
from gymnast.cli.settings import resolve, saved_inputs
from gymnast.config import CameraNames
from gymnast.data.frames import Fit
from gymnast.reward.chat.server import ChatLimits
from gymnast.reward.spec import RewardSpec
from gymnast.utils.trackers import TrackerNames

API_KEY_VARIABLE = "GYMNAST_JUDGE_API_KEY"
"""The environment variable `gymnast serve-judge` reads its API key from when --api-key is not given."""


def train_judge(
    out: Path,
    data: Path | None = None,
    wm: Path | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    steps: int | None = None,
    kind: Literal["frames", "video", "progress"] | None = None,
    extra_data: tuple[Path, ...] = (),
    init: Path | None = None,
    camera: str | None = None,
    cameras: CameraNames = (),
    fit: Fit | None = None,
    threshold_tpr: float | None = None,
    hard_negatives: float | None = None,
    hold_steps: int | None = None,
    device: str | None = None,
    tracker: TrackerNames | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train the embedded success judge on real episodes (and their re-imaginings with --wm), choose
    its threshold on validation scenes, then report its TPR and FPR on held-out real and imagined videos.

    Args:
        out: run directory: checkpoints, metrics.jsonl, metrics.json (the held-out figures).
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        wm: world-model run: also train and measure on its re-imagining of every episode; or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        preset: debug (seconds), demo (minutes), full or gpu (a wider judge for one GPU; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings, data and world model
            saved there.
        steps: override the preset's optimizer steps.
        kind: frames (judge every frame; the default), video (four frames of the whole video) or progress
            (every frame's dense reward; a video scores its mean: a continuous reward, no threshold).
        extra_data: more datasets to train and measure on (e.g. a policy's recorded rollouts).
        init: a judge run (or checkpoint) to fine-tune instead of starting from random weights.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras the per-frame judges see side by side, the primary first
            (e.g. front,gripper; with --wm, a world model of the same cameras). Default: --camera alone.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        threshold_tpr: choose the threshold for this TPR on the validation scenes (the highest that
            passes this share of their successes) instead of the most TPR - FPR; e.g. 0.95.
        hard_negatives: share of each batch's negative frames chosen as those the judge rates highest
            of four times as many random ones (its near misses); default 0, all random.
        hold_steps: steps in a row a per-frame judge must see the task done to call a video a success
            (a run reaching the video's end counts as held); default 5; 1 believes any single frame.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N; --resume may change it.
        tracker: where the run also logs its settings, metrics and held-out figures: none, or any of tensorboard and
            wandb, comma-separated (wandb: the [wandb] extra; WANDB_MODE=offline keeps it on disk);
            default: none; --resume may change it.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.reward.judges.train import JUDGE_PRESETS, saved_judge_config
    from gymnast.reward.judges.train import train_judge as train

    config, inputs = resolve(
        "train-judge", out, resume, JUDGE_PRESETS[preset], inputs={"data": data, "wm": wm}, required=("data",),
        overrides={"steps": steps, "kind": kind, "extra_data": extra_data or None, "init": init, "camera": camera,
                   "cameras": cameras or None, "fit": fit, "threshold_tpr": threshold_tpr,
                   "hard_negatives": hard_negatives, "hold_steps": hold_steps, "device": device, "tracker": tracker,
                   **key_overrides(keys)},
        saved=lambda: (saved_judge_config(out), saved_inputs(out, "data", "wm")))
    report = train(inputs["data"], out, config, wm=inputs["wm"], resume=resume)
    print(json.dumps({k: v for k, v in report.items() if k.startswith(("real", "imagined"))}, indent=2))
    print(f"judge: {out}")


def calibrate_judge(
    judge: Path,
    data: tuple[Path, ...],
    out: Path,
    max_fpr: float = 0.02,
    hold_steps: tuple[int, ...] = (),
    checkpoints: tuple[int, ...] = (),
) -> None:
    """Choose a per-frame judge's threshold, and optionally its hold rule and checkpoint, on labelled
    real episodes it never saw (more than its validation scenes), then measure the chosen judge on
    the run's held-out real videos. Writes a judge run that --reward judge:OUT loads.

    Args:
        judge: a per-frame judge run, from `gymnast train-judge`.
        data: datasets of real episodes recorded apart from the judge's (`gymnast collect` with
            another --first-seed, a policy's rollouts with --policy), with the judge's cameras.
        out: the calibrated judge run: its checkpoint, config.json, calibration.json (every option
            tried) and metrics.json (the held-out real TPR/FPR).
        max_fpr: the share of the calibration failures the threshold may pass as successes; the
            lowest threshold within it is chosen (the most successes passed).
        hold_steps: hold rules to try (e.g. 5 8 12); default: the judge's own.
        checkpoints: steps of the run's earlier checkpoints to try besides its newest (e.g. 1000 1500).
    """
    from gymnast.reward.judges.calibrate import CalibrationConfig
    from gymnast.reward.judges.calibrate import calibrate_judge as calibrate

    report = calibrate(judge, data, out, CalibrationConfig(max_fpr, hold_steps, checkpoints))
    chosen = {key: report[f"calibration_{key}"] for key in ("checkpoint", "hold_steps", "threshold", "tpr", "fpr")}
    heldout = {key: report[key] for key in ("real_tpr", "real_fpr", "real_positives", "real_negatives")}
    print(json.dumps({"chosen on the calibration episodes": chosen, "held-out real": heldout}, indent=2))
    print(f"judge: {out}")


def serve_judge(
    judge: Path,
    port: int = 8000,
    host: str = "127.0.0.1",
    api_key: str | None = None,
    limits: Annotated[ChatLimits, tyro.conf.arg(name="")] = ChatLimits(),
) -> None:
    """Serve the learned judge over the OpenAI chat-completions protocol (POST /v1/chat/completions).

    A malformed request, one past the limits, or one that stalls past the read timeout gets a 4xx
    JSON error in the OpenAI shape naming the field at fault; the server logs it and serves on.
    GET /v1/models says which cameras, image size and order the judge expects.

    Args:
        judge: judge run (or checkpoint) directory, from `gymnast train-judge`.
        port: TCP port to listen on.
        host: address to bind (127.0.0.1: this machine only; any other needs an API key).
        api_key: the key every request must carry as 'Authorization: Bearer KEY' (an OpenAI client's
            api_key); others get 401. Default: the GYMNAST_JUDGE_API_KEY environment variable, which
            keeps the key out of the process list; neither: no key, this machine only.
        limits: the largest request body and `n`, and the read timeout.
    """
    import os
    import time

    from gymnast.reward.chat.serve import judge_server

    key = api_key if api_key is not None else os.environ.get(API_KEY_VARIABLE) or None
    with judge_server(judge, host, port, limits=limits, api_key=key) as server:
        needs = "; requests need the API key" if key else ""
        print(f"judge: {judge} at {server.url} (model gymnast-judge{needs}); Ctrl-C stops", flush=True)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass


def eval_judge(
    reward: str,
    data: Path,
    out: Path,
    wm: Path | None = None,
    heldout_fraction: float = 0.1,
    device: str = "auto",
    camera: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Measure a 0/1 judge (judge:RUN or vlm:MODEL@BASE_URL) on held-out episodes: TPR and FPR on
    real videos and, with --wm, on the world model's re-imagining of the same episodes.

    Args:
        reward: the judge, e.g. judge:runs/judge or vlm:gpt-4o@https://api.openai.com/v1 (key from OPENAI_API_KEY).
        data: dataset directory; the episodes of its held-out scenes are judged.
        out: report JSON.
        wm: world-model run whose imagined videos are judged too; or your own: python:MODULE:FACTORY[@ARG] or
            plugin:NAME[@ARG] (gymnast check-wm --help).
        heldout_fraction: the held-out share of scenes (the world model's, so its videos are unseen); 1 judges
            every episode (but those of evaluation seeds), for a dataset of new scenes (`gymnast collect --first-seed`).
        device: where a learned judge and the world model run: auto (CUDA when torch sees a GPU), cpu, cuda or cuda:N.
        camera: the dataset camera to judge, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        keys: which dataset features are the actions (re-imagined with --wm) and the states (default:
            LeRobot's action and observation.state).
    """
    from gymnast.reward.select import measure_judge

    report = measure_judge(RewardSpec.parse(reward), data, out, wm, heldout_fraction, device, camera,
                           feature_keys(keys))
    print(json.dumps(report, indent=2))
