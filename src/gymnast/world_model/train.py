"""`gymnast train-wm`: fit the embedded world model to every episode of a dataset.

Each step draws B clips of C real context frames followed by F future frames, imagines the F
frames open-loop from the context under the clip's real actions, and minimises the mean squared
error of every imagined frame, backpropagating through the whole recurrence. Training on long
open-loop clips is what keeps errors from compounding at test time: the model sees (and learns to
correct) its own drift, never real frames it would not have in a rollout.

Legend: B batch, C context frames, F future frames, H/W image size.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.utils.checkpoint import resolve_checkpoint, resume_training, save_training, saved_settings, write_run_config
from gymnast.utils.metrics import MetricsLog
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.world_model.data import ClipBatch, EpisodeBank, split_episodes
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.metrics import psnr, to_unit_float
from gymnast.world_model.videos import write_side_by_side

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class WorldModelTrainConfig:
    """World-model training settings."""

    steps: int = 4000
    """Optimizer steps (about 40 minutes on 2 CPU cores at the default size)."""
    batch_size: int = 8
    """Clips per step."""
    future: int = 32
    """Frames F imagined open-loop per clip (the backpropagation-through-time length)."""
    warmup_future: float = 0.5
    """Share of training over which the clip length grows from 4 frames to `future` (short clips first
    teach the model what one action does; long ones then teach it not to drift)."""
    lr: float = 1e-3
    """Peak learning rate (AdamW, linear warm-up then cosine decay)."""
    warmup_steps: int = 100
    """Linear warm-up steps."""
    heldout_fraction: float = 0.1
    """Share of scenes (task, seed) kept out of training for eval-wm."""
    validate_every: int = 250
    """Steps between held-out PSNR checks (a fixed set of held-out clips)."""
    video_every: int = 1000
    """Steps between side-by-side videos of a held-out episode (RUN/videos/)."""
    checkpoint_every: int = 250
    """Steps between checkpoints."""
    log_every: int = 25
    """Steps between metrics lines."""
    seed: int = 0
    """Seed of initialisation and clip sampling."""
    model: EmbeddedWorldModelConfig = field(default_factory=EmbeddedWorldModelConfig)
    """Architecture."""


WM_PRESETS: dict[str, WorldModelTrainConfig] = {
    "debug": WorldModelTrainConfig(
        steps=4, batch_size=2, future=4, warmup_steps=1, validate_every=2, video_every=4, checkpoint_every=2, log_every=1,
        model=EmbeddedWorldModelConfig(latent_channels=16, widths=(8, 16), blocks=1, action_width=16),
    ),
    "demo": WorldModelTrainConfig(steps=600, video_every=300, validate_every=100),
    "full": WorldModelTrainConfig(),
}

_VALIDATION_CLIPS = 32


def train_world_model(data: Path, out: Path, config: WorldModelTrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Trains (or resumes) a world-model run in `out`; returns the final checkpoint directory."""
    dataset = EpisodeDataset(data)
    if dataset.image_shape[0] != config.model.image_size:
        config = dataclasses.replace(config, model=dataclasses.replace(config.model, image_size=dataset.image_shape[0]))
    train_ids, heldout_ids = split_episodes(dataset.episodes, config.heldout_fraction)
    logger.info("training on %d episodes, %d held out", len(train_ids), len(heldout_ids))
    bank = EpisodeBank(dataset, train_ids, progress=progress)
    heldout = EpisodeBank(dataset, heldout_ids) if heldout_ids else None
    context = config.model.context_frames

    torch.manual_seed(config.seed)
    model = EmbeddedWorldModel(config.model)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=0.0)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    validation = heldout.sample(_VALIDATION_CLIPS, context, config.future, torch.Generator().manual_seed(1)) if heldout else None
    resolved = {"train": dataclasses.asdict(config), "model": model.spec(), "data": str(data),
                "train_episodes": len(train_ids), "heldout_episodes": len(heldout_ids)}
    start = resume_training(out, model, optimizer, schedule, sampler) if resume else 0
    if resume:
        logger.info("resumed %s at step %d", out, start)
    write_run_config(out, resolved)
    metrics = MetricsLog(out, resume_step=start if resume else None)
    bar = tqdm(range(start, config.steps), initial=start, total=config.steps, desc="train-wm", disable=not progress)
    started = time.perf_counter()
    checkpoint = None
    for step in bar:
        model.train()
        future = future_at(step, config)
        loss, values = clip_loss(model, bank.sample(config.batch_size, context, future, sampler))
        values["train/future"] = future
        values["train/grad_norm"] = gradient_step(loss, model, optimizer, schedule)
        done = step + 1
        if validation is not None and (done % config.validate_every == 0 or done == config.steps):
            values |= validate(model, validation)
        if done % config.log_every == 0 or done == config.steps:
            values |= {"train/lr": schedule.get_last_lr()[0], "time/step_s": (time.perf_counter() - started) / (done - start)}
            metrics.log(done, values)
            bar.set_postfix(psnr=f"{values['train/psnr']:.1f}", **({"val": f"{values['wm/val_psnr']:.1f}"} if "wm/val_psnr" in values else {}))
        if heldout is not None and (done % config.video_every == 0 or done == config.steps):
            _write_video(model, heldout, out / "videos" / f"step_{done:06d}.mp4", dataset.fps)
        if done % config.checkpoint_every == 0 or done == config.steps:
            checkpoint = save_training(out, done, model, resolved, optimizer, schedule, sampler)
    return checkpoint or resolve_checkpoint(out)


def future_at(step: int, config: WorldModelTrainConfig) -> int:
    """Clip length F at `step`: from 4 up to `config.future` over the first `warmup_future` of training."""
    ramp = config.warmup_future * config.steps
    if step >= ramp:
        return config.future
    return max(min(4, config.future), round(4 + (config.future - 4) * step / ramp))


def clip_loss(model: EmbeddedWorldModel, clips: ClipBatch) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean squared error of the F frames imagined open-loop from the context; (loss, metrics)."""
    target = to_unit_float(clips.future)  # (B, F, 3, H, W)
    with model.autocast():
        _, imagined = model.imagine(model.encode(to_unit_float(clips.context)), clips.actions)
    error = (imagined.float() - target).square()
    loss = error.mean()
    return loss, {"train/loss": loss.item(), "train/psnr": -10 * math.log10(max(loss.item(), 1e-10))}


@torch.no_grad()
def validate(model: EmbeddedWorldModel, clips: ClipBatch) -> dict[str, float]:
    """PSNR of held-out clips imagined open-loop: at the first and the last future frame, and overall."""
    model.eval()
    imagined = to_unit_float(model.step(model.init_state(clips.context), clips.actions)[1])
    values = psnr(imagined, to_unit_float(clips.future))  # (B, F)
    return {"wm/val_psnr": values.mean().item(), "wm/val_psnr_h1": values[:, 0].mean().item(),
            f"wm/val_psnr_h{values.shape[1]}": values[:, -1].mean().item()}


@torch.no_grad()
def _write_video(model: EmbeddedWorldModel, heldout: EpisodeBank, path: Path, fps: int) -> None:
    """The longest held-out episode, imagined from its first frame under its real actions."""
    model.eval()
    k = max(range(len(heldout)), key=lambda i: len(heldout.actions[i]))
    frames, actions = heldout.frames[k], heldout.actions[k]
    imagined = model.step(model.init_state(frames[None, :1]), actions[None])[1][0]  # (T, H, W, 3)
    write_side_by_side(path, frames[1:].numpy(), imagined.numpy(), fps)


def saved_train_config(run: Path) -> WorldModelTrainConfig:
    """The settings a run was started with (from RUN/config.json), for ``--resume``."""
    saved = saved_settings(run, "train")
    model = {**saved["model"], "widths": tuple(saved["model"]["widths"])}
    return WorldModelTrainConfig(**{**saved, "model": EmbeddedWorldModelConfig(**model)})

