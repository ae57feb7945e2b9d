"""`gymnast train-wm`: fit a world model (embedded or flow) to every episode of a dataset.

The embedded backend: each step draws B clips of C real context frames followed by F future frames, imagines the F
frames open-loop from the context under the clip's real actions, and minimises the mean squared
error of every imagined frame, backpropagating through the whole recurrence. Training on long
open-loop clips is what keeps errors from compounding at test time: the model sees (and learns to
correct) its own drift, never real frames it would not have in a rollout.

The flow backend (`gymnast.world_model.flow`) trains on the same clips with its own loss
(`flow_clip_loss`): its autoencoder reconstructs every frame, and its velocity network learns
each future latent from the C before it, with noised context instead of backpropagation through
the rollout.

Three levers, all off by default: `moving_weight` makes the pixels that move (the arm, a puck) count
more than the static table, which otherwise dominates the error and lets small objects fade;
`init` fine-tunes an existing run's weights; `extra_data` trains on several datasets at once.

Legend: B batch, C context frames, F future frames, H/W image size.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import torch
from safetensors.torch import load_file
from tqdm import tqdm

from gymnast.data.action_stats import ActionStats
from gymnast.data.frames import Fit, model_image_size
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import begin_training, resolve_checkpoint, save_training
from gymnast.utils.device import resolve_device, to_device
from gymnast.utils.distributed import Parallel, data_parallel
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.utils.settings import from_json, saved_settings
from gymnast.utils.trackers import TrackerNames
from gymnast.world_model.base import WorldModel, grounded_state_dim, imagined_frame_mask, rollout
from gymnast.world_model.data import ClipBatch, EpisodeBank, split_episodes
from gymnast.world_model.views import with_cameras
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.flow import FlowWorldModel, FlowWorldModelConfig, flow_clip_loss
from gymnast.world_model.metrics import moving_mask, psnr, to_unit_float
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
    tracker: TrackerNames = ()
    """Where the run logs besides RUN/metrics.jsonl: none, or any of tensorboard and wandb,
    comma-separated (gymnast.utils.trackers)."""
    seed: int = 0
    """Seed of initialisation and clip sampling."""
    moving_weight: float = 0.0
    """Extra weight of moving pixels: a pixel's squared error counts 1 + moving_weight times where the
    target frame differs from the clip's last context frame (`metrics.moving_mask`, threshold 0.05),
    and the loss is divided by the mean weight, so it stays a weighted mean squared error on the
    usual scale (0 = plain mean squared error). train/psnr stays unweighted, comparable across runs."""
    init: Path | None = None
    """Start from the weights of this world-model run or checkpoint (fine-tuning) instead of a random
    initialisation; its model spec must match this run's. The optimizer and the learning-rate
    schedule start afresh. Saved as the checkpoint directory it resolved to."""
    extra_data: tuple[Path, ...] = ()
    """More datasets to train on besides DATA, with the same image size. Each is split by the same
    scene hash, so a scene held out of one is held out of all of them."""
    camera: str | None = None
    """Camera to read from the dataset (e.g. ``front``); default: the first camera whose frames exist."""
    cameras: tuple[str, ...] = ()
    """Several cameras to imagine side by side, the primary first (e.g. ``front,gripper``): one
    single-view model learns every camera's view (`gymnast.world_model.views`); default: `camera`
    alone. Saved with the model, so RL starts it from the same views a policy of those cameras sees."""
    keys: FeatureKeys = FeatureKeys()
    """Which dataset features are the actions and the states (--action-key, --state-key); saved with the run."""
    grounded: bool = False
    """Render every frame at the episode's recorded state (its environment state where recorded,
    else observation.state): a grounded model (`EmbeddedWorldModelConfig.state_dim`), which then
    imagines beside a state model that gives it the states (`gymnast rl --robot-state`). Embedded
    backend only."""
    state_noise: float = 0.0
    """Gaussian noise added to the recorded states a grounded model is trained at, in units of each
    number's spread: imagination gives it a state model's states, which are that far off."""
    fit: Fit = "resize"
    """How frames become the model's square image when they are not square or larger than 256 px
    (they are then fitted to the model's `image_size`): resize (the whole frame, aspect ratio not kept) or
    crop (the central square). Square frames up to 256 px, a multiple of 8, set the image size and
    are used as they are. Saved with the run, so everything reading real frames for it fits them alike."""
    backend: Literal["embedded", "flow"] = "embedded"
    """Which world model to train: embedded (deterministic, warp and paint) or flow (generative:
    latent flow matching, one sampled frame per action)."""
    device: str = "auto"
    """Where to train: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N."""
    model: EmbeddedWorldModelConfig = field(default_factory=EmbeddedWorldModelConfig)
    """Architecture of the embedded backend."""
    flow: FlowWorldModelConfig = field(default_factory=FlowWorldModelConfig)
    """Architecture of the flow backend."""


WM_PRESETS: dict[str, WorldModelTrainConfig] = {
    "debug": WorldModelTrainConfig(
        steps=4, batch_size=2, future=4, warmup_steps=1, validate_every=2, video_every=4, checkpoint_every=2, log_every=1,
        model=EmbeddedWorldModelConfig(latent_channels=16, widths=(8, 16), blocks=1, action_width=16),
    ),
    "demo": WorldModelTrainConfig(steps=600, video_every=300, validate_every=100),
    "full": WorldModelTrainConfig(),
    # 26x the parameters (9.9 M) at 8x the batch for one GPU: about 0.25 s a step on an H100 at
    # batch 64, so about 50 minutes (docs/gpu.md).
    "gpu": WorldModelTrainConfig(
        steps=12000, batch_size=64, lr=5e-4, warmup_steps=500, validate_every=1000, video_every=4000,
        checkpoint_every=1000, log_every=100,
        model=EmbeddedWorldModelConfig(latent_channels=256, widths=(64, 128), blocks=6, action_width=256),
    ),
}

FLOW_PRESETS: dict[str, WorldModelTrainConfig] = {
    "debug": WorldModelTrainConfig(
        backend="flow", steps=4, batch_size=2, future=4, warmup_steps=1, validate_every=2, video_every=4,
        checkpoint_every=2, log_every=1,
        flow=FlowWorldModelConfig(latent_channels=4, widths=(8, 16), width=16, blocks=1, condition_width=16, sample_steps=2),
    ),
    "demo": WorldModelTrainConfig(backend="flow", steps=300, future=8, warmup_future=0.0, video_every=300, validate_every=100),
    # 0.5-1 s a step on 2 shared CPU cores; clips of 8 teach one step at a time (the context noise, not
    # backpropagation through the rollout, is what should keep rollouts from drifting; at 3000 steps it did not
    # fully: results/world_model/generative/README.md).
    "full": WorldModelTrainConfig(backend="flow", steps=4000, future=8, warmup_future=0.0, validate_every=250, video_every=1000),
    "gpu": WorldModelTrainConfig(
        backend="flow", steps=20000, batch_size=32, future=16, warmup_future=0.0, lr=5e-4, warmup_steps=500,
        validate_every=1000, video_every=5000, checkpoint_every=1000, log_every=100,
        flow=FlowWorldModelConfig(latent_channels=16, widths=(64, 128), width=256, blocks=6, condition_width=256),
    ),
}

PRESETS = {"embedded": WM_PRESETS, "flow": FLOW_PRESETS}
"""Backend -> its named presets."""


def wm_preset(name: str, backend: str = "embedded") -> WorldModelTrainConfig:
    """The preset `name` of `backend`'s training settings.

    Raises:
        ValueError: an unknown backend, or a preset the backend does not have (the message lists its presets).
    """
    if backend not in PRESETS:
        raise ValueError(f"unknown world-model backend {backend!r}; choose one of {', '.join(PRESETS)}")
    if name not in PRESETS[backend]:
        raise ValueError(f"the {backend} backend has no preset {name!r}; choose one of {', '.join(PRESETS[backend])}")
    return PRESETS[backend][name]

_VALIDATION_CLIPS = 32


def train_world_model(data: Path, out: Path, config: WorldModelTrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Trains (or resumes) a world-model run in `out`; returns the final checkpoint directory.

    Under torchrun, the processes train one model together (`gymnast.utils.distributed`):
    `config.batch_size` is the global batch, and rank 0 writes the run.

    Raises:
        ValueError: the datasets' image sizes or action dimensions differ, or `config.init`'s model
            spec differs from this run's.
        FileNotFoundError: `config.init` has no checkpoint.
        DatasetError: a dataset lacks what training needs (the message names the file and field).
    """
    datasets = [EpisodeDataset(path, config.camera, config.cameras or None, keys=config.keys) for path in (data, *config.extra_data)]
    if config.init is not None and not resume:  # on resume the weights come from the run's own checkpoint
        config = dataclasses.replace(config, init=resolve_checkpoint(config.init))
    # A resumed run keeps the action range its weights were trained with, whatever `config` says.
    kept = _saved_pair(resolve_checkpoint(out), "action_low", "action_high") if resume else None
    config, datasets, stats = fit_to_data(config, datasets, action_range=kept)
    with data_parallel(resolve_device(config.device)) as parallel:
        return _train(data, out, config, datasets, stats, resume, progress, parallel)


def _train(data: Path, out: Path, config: WorldModelTrainConfig, datasets: list[EpisodeDataset], stats: ActionStats,
           resume: bool, progress: bool, parallel: Parallel) -> Path:
    """`train_world_model` from the fitted datasets on, in this process of the run."""
    if parallel.world_size > 1 and config.backend == "flow":
        raise ValueError("train-wm --backend flow draws its noise per clip and does not train under torchrun yet; "
                         "run it as one process")
    dataset = datasets[0]
    if config.grounded and config.backend != "embedded":
        raise ValueError(f"train-wm --grounded renders at recorded states with the embedded backend; the {config.backend} "
                         "backend is not grounded")
    if config.model.actions_per_frame != 1 and config.backend != "embedded":
        raise ValueError(f"train-wm --actions-per-frame imagines one frame per chunk with the embedded backend; the "
                         f"{config.backend} backend imagines one per action")
    bank, heldout, counts = load_banks(datasets, config.heldout_fraction, progress and parallel.is_main)
    if config.grounded:  # a resumed run keeps the normalisation its weights were trained with
        mean, std = _saved_pair(resolve_checkpoint(out), "state_mean", "state_std") if resume else bank.state_stats()
        config = with_architecture(config, dataclasses.replace(config.model, state_dim=len(mean), state_mean=mean, state_std=std))
    context = architecture(config).context_frames
    share, device = parallel.share(config.batch_size), parallel.device
    model = build_model(config if not resume else dataclasses.replace(config, init=None)).to(device)
    config = with_architecture(config, model.config)  # fine-tuning keeps the action range of its weights
    loss_of = parallel.loss(model, flow_clip_loss if config.backend == "flow" else clip_loss)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=0.0)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    # the final clip length, in whole chunks for a model of one frame per chunk
    validation = heldout.sample(_VALIDATION_CLIPS, context, future_at(config.steps, config),
                               torch.Generator().manual_seed(1)) if heldout else None
    resolved = {"train": _settings(config), "model": with_cameras(model, dataset.cameras).spec(), "data": str(data),
                "action_stats": stats.to_dict(), "datasets": counts,
                "train_episodes": sum(c["train_episodes"] for c in counts),
                "heldout_episodes": sum(c["heldout_episodes"] for c in counts)}
    start, metrics = begin_training(out, resolved, model, optimizer, schedule, sampler, resume, parallel.is_main,
                                    config.tracker, "train-wm")
    bar = tqdm(range(start, config.steps), initial=start, total=config.steps, desc="train-wm",
               disable=not (progress and parallel.is_main))
    started = time.perf_counter()
    checkpoint = None
    for step in bar:
        model.train()
        future = future_at(step, config)
        clips = bank.sample(config.batch_size, context, future, sampler)  # the global batch: every process draws it
        clips = ClipBatch(*(to_device(t[share], device) for t in (clips.context, clips.actions, clips.future, clips.states)))
        extra = (sampler,) if config.backend == "flow" else (config.state_noise,)
        loss, values = loss_of(clips, *extra, config.moving_weight)
        # Equal slices: the mean of the processes' means is the global batch's (with moving_weight,
        # each process weighs its pixels by its own mean weight, a slight difference).
        values = parallel.average(values)
        values["train/future"] = future
        values["train/grad_norm"] = gradient_step(loss, model, optimizer, schedule)
        done = step + 1
        if not parallel.is_main:
            continue
        if validation is not None and (done % config.validate_every == 0 or done == config.steps):
            values |= validate(model, validation)
        if done % config.log_every == 0 or done == config.steps:
            values |= {"train/lr": schedule.get_last_lr()[0], "time/step_s": (time.perf_counter() - started) / (done - start)}
            metrics.log(done, values)
            bar.set_postfix(psnr=f"{values['train/psnr']:.1f}", **({"val": f"{values['wm/val_psnr']:.1f}"} if "wm/val_psnr" in values else {}))
        if heldout is not None and (done % config.video_every == 0 or done == config.steps):
            video = _write_video(model, heldout, out / "videos" / f"step_{done:06d}.mp4", dataset.fps)
            metrics.video("wm/heldout_video", done, video, dataset.fps)
        if done % config.checkpoint_every == 0 or done == config.steps:
            checkpoint = save_training(out, done, model, resolved, optimizer, schedule, sampler)
    if metrics is not None:
        metrics.close()
    parallel.barrier()  # the others return rank 0's last checkpoint once it is written
    return checkpoint or resolve_checkpoint(out)


def fit_to_data(config: WorldModelTrainConfig, datasets: Sequence[EpisodeDataset],
                action_range: tuple | None = None) -> tuple[WorldModelTrainConfig, list[EpisodeDataset], ActionStats]:
    """`config` with the model's image size and action space taken from the datasets, the datasets
    with their frames fitted to that size (`gymnast.data.frames`), and their action statistics.

    The action range is `action_range` (low, high) when given (a resumed run's), else the
    datasets' per-dimension min and max.

    Raises:
        ValueError: the datasets' frames or action dimensions differ.
        DatasetError: a dataset's actions cannot be read (the message names the file and field).
    """
    first = datasets[0]
    for other in datasets[1:]:
        if other.camera_shape != first.camera_shape:
            size, wanted = "x".join(map(str, other.camera_shape[:2])), "x".join(map(str, first.camera_shape[:2]))
            raise ValueError(f"{other.root}: frames are {size}, but {first.root} has {wanted}; "
                             "every dataset of one world model needs one image size")
    size = model_image_size(first.camera_shape, architecture(config).image_size)
    stats = ActionStats.merge([d.action_stats for d in datasets])
    low, high = action_range if action_range is not None else stats.action_range()
    model = dataclasses.replace(architecture(config), image_size=size, action_dim=first.action_dim, action_low=low, action_high=high)
    return with_architecture(config, model), [d.fitted(size, config.fit) for d in datasets], stats


def architecture(config: WorldModelTrainConfig) -> EmbeddedWorldModelConfig | FlowWorldModelConfig:
    """The architecture of the backend `config` trains."""
    return config.flow if config.backend == "flow" else config.model


def with_architecture(config: WorldModelTrainConfig,
                      model: EmbeddedWorldModelConfig | FlowWorldModelConfig) -> WorldModelTrainConfig:
    """`config` with its backend's architecture replaced by `model`."""
    return dataclasses.replace(config, **{"flow" if config.backend == "flow" else "model": model})


def _saved_pair(checkpoint: Path, first: str, second: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Two fields of the model a checkpoint saved, as tuples (empty where it predates them): its
    action range (action_low, action_high, empty: the identity) or a grounded model's state
    normalisation (state_mean, state_std), which its weights were trained with."""
    saved = read_json(checkpoint / "config.json").get("model", {})
    return tuple(saved.get(first, ())), tuple(saved.get(second, ()))


def load_banks(datasets: Sequence[EpisodeDataset], heldout_fraction: float,
               progress: bool = False) -> tuple[EpisodeBank, EpisodeBank | None, list[dict]]:
    """The training and held-out episodes of several datasets, each split by scene.

    The datasets' frames are one size: `fit_to_data` checked their cameras and fitted them.

    Returns:
        The training bank, the held-out bank (None when nothing is held out) and, per dataset, its
        path and how many episodes went to each side.
    """
    splits = [split_episodes(d.episodes, heldout_fraction) for d in datasets]
    counts = [{"data": str(d.root), "train_episodes": len(t), "heldout_episodes": len(h)} for d, (t, h) in zip(datasets, splits)]
    logger.info("training on %d episodes, %d held out", sum(len(t) for t, _ in splits), sum(len(h) for _, h in splits))
    bank = EpisodeBank.union([(d, t) for d, (t, _) in zip(datasets, splits)], progress=progress)
    has_heldout = any(h for _, h in splits)
    heldout = EpisodeBank.union([(d, h) for d, (_, h) in zip(datasets, splits)]) if has_heldout else None
    return bank, heldout, counts


# Settings that change how the weights run, not what they are: a fine-tuning run may pick its own.
# The cameras too: one view's weights start a model of several (`gymnast.world_model.views`).
_WEIGHT_FREE = ("bf16", "reanchor_every", "sample_steps", "context_noise", "guidance", "cameras")
# Training settings a fine-tune may change; the weights they add (the embedded backend's "no action"
# embedding, with action dropout; its state embedding, grounded) start fresh.
# So may the actions per frame: a model of one frame per chunk starts from one of a frame per action,
# its chunk mixer fresh.
_TRAINING_ONLY = ("action_dropout", "state_dim", "state_mean", "state_std", "actions_per_frame")
_FRESH = ("no_action", "embed_state.", "mix_chunk.")  # the weights those settings add


def build_model(config: WorldModelTrainConfig) -> EmbeddedWorldModel | FlowWorldModel:
    """The model training starts from: seeded by `config.seed`, with `config.init`'s weights (and
    their action range) when given.

    Raises:
        FileNotFoundError: `config.init` has no checkpoint.
        ValueError: `config.init`'s model spec differs from the backend's architecture (the message names the fields).
    """
    torch.manual_seed(config.seed)
    backend = FlowWorldModel if config.backend == "flow" else EmbeddedWorldModel
    if config.init is None:
        return backend(architecture(config))
    checkpoint = resolve_checkpoint(config.init)
    # A field the checkpoint predates (say, the action range) had its default value then.
    defaults = json.loads(json.dumps(dataclasses.asdict(type(architecture(config))())))
    source = defaults | read_json(checkpoint / "config.json").get("model", {})
    # The weights were trained on actions normalised by their own range: it comes with them, and so
    # do a grounded model's state and its normalisation.
    kept = ("action_low", "action_high") + (("state_dim", "state_mean", "state_std") if source.get("state_dim") else ())
    model = backend(dataclasses.replace(architecture(config), **{name: _as_field(source[name]) for name in kept}))
    wanted = json.loads(json.dumps(model.spec()))  # tuples as JSON lists, like the saved spec
    differ = sorted(k for k in source.keys() | wanted.keys()
                    if k not in _WEIGHT_FREE + _TRAINING_ONLY and source.get(k) != wanted.get(k))
    if differ:
        fields = ", ".join(f"{k} ({source.get(k)!r} there, {wanted.get(k)!r} here)" for k in differ)
        raise ValueError(f"--init {config.init}: its model differs from this run's in {fields}")
    weights = load_file(checkpoint / "model.safetensors")
    if source.get("actions_per_frame", 1) != model.config.actions_per_frame:  # a chunk mixer of another length
        weights = {name: value for name, value in weights.items() if not name.startswith("mix_chunk.")}
    missing, unexpected = model.load_state_dict(weights, strict=False)
    if unexpected or {name for name in missing if not name.startswith(_FRESH)}:
        raise ValueError(f"--init {config.init}: its weights do not fit this model "
                         f"(missing here: {sorted(unexpected)}; missing there: {sorted(missing)})")
    logger.info("starting from the weights of %s", checkpoint)
    return model


def _as_field(value: Any) -> Any:
    """A saved spec's value as its config field holds it (JSON lists as tuples)."""
    return tuple(value) if isinstance(value, list) else value


def future_at(step: int, config: WorldModelTrainConfig) -> int:
    """Clip length F at `step`: from 4 (or `config.future` if shorter) up to `config.future` over the
    first `warmup_future` of training, rounded up to whole chunks for a model of one frame per chunk
    (`actions_per_frame`)."""
    ramp, first = config.warmup_future * config.steps, min(4, config.future)
    future = config.future if step >= ramp else round(first + (config.future - first) * step / ramp)
    chunk = getattr(architecture(config), "actions_per_frame", 1)
    return -(-future // chunk) * chunk


def clip_loss(model: EmbeddedWorldModel, clips: ClipBatch, state_noise: float = 0.0,
              moving_weight: float = 0.0) -> tuple[torch.Tensor, dict[str, float]]:
    """`frame_loss` of the F frames imagined open-loop from the context (a grounded model's at the
    recorded states, `state_noise` spreads off; one of a frame per chunk on the chunks' last frames,
    the others repeating an earlier one); (loss, metrics)."""
    imagined_at = imagined_frame_mask(model, clips.future.shape[1])
    target = to_unit_float(clips.future)[:, imagined_at]  # (B, F', 3, H, W)
    states = None
    if model.state_dim:
        states = clips.states + state_noise * torch.randn_like(clips.states) * model.state_std
    with model.autocast():
        _, imagined = model.imagine(model.encode(to_unit_float(clips.context)), clips.actions, states)
    return frame_loss(imagined[:, imagined_at].float(), target, to_unit_float(clips.context[:, -1:]), moving_weight)


def frame_loss(imagined: torch.Tensor, target: torch.Tensor, reference: torch.Tensor,
               moving_weight: float = 0.0) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean squared error of imagined frames, moving pixels weighted; (loss, metrics).

    The loss is sum(w * e) / sum(w) over pixels, e a pixel's squared error (mean over channels) and
    w = 1 + moving_weight where the target pixel moved (differs from `reference`), else 1. Frames
    where nothing moves, or moving_weight 0, give the plain mean squared error.

    Args:
        imagined: (B, F, 3, H, W) float in [0, 1].
        target: (B, F, 3, H, W) float in [0, 1], the real frames.
        reference: (B, 1, 3, H, W) float in [0, 1], the clip's last context frame.
        moving_weight: the extra weight of a moving pixel.

    Returns:
        The loss and {"train/loss": it, "train/psnr": PSNR of the unweighted mean squared error}.
    """
    error = (imagined - target).square()  # (B, F, 3, H, W)
    mse = error.mean()
    loss = mse
    if moving_weight:
        weight = 1 + moving_weight * moving_mask(target, reference).float()  # (B, F, 1, H, W)
        loss = (error * weight).mean() / weight.mean()
    return loss, {"train/loss": loss.item(), "train/psnr": -10 * math.log10(max(mse.item(), 1e-10))}


@torch.no_grad()
def validate(model: WorldModel, clips: ClipBatch) -> dict[str, float]:
    """PSNR of held-out clips imagined open-loop: at the first and the last imagined frame, and overall
    (a model of one frame per chunk at the chunks' last frames).

    A generative model samples with a fixed seed, so the figures do not depend on what ran before.
    """
    model.eval()
    states = clips.states if grounded_state_dim(model) else None
    imagined = to_unit_float(rollout(model, clips.context, clips.actions, torch.Generator().manual_seed(0), states).frames)
    imagined_at = imagined_frame_mask(model, clips.future.shape[1])
    values = psnr(imagined[:, imagined_at], to_unit_float(clips.future)[:, imagined_at])  # (B, F')
    first, last = (int(i) + 1 for i in torch.nonzero(imagined_at)[[0, -1], 0])
    return {"wm/val_psnr": values.mean().item(), f"wm/val_psnr_h{first}": values[:, 0].mean().item(),
            f"wm/val_psnr_h{last}": values[:, -1].mean().item()}


@torch.no_grad()
def _write_video(model: WorldModel, heldout: EpisodeBank, path: Path, fps: int) -> Path:
    """The longest held-out episode, imagined from its first frame under its real actions; returns `path`."""
    model.eval()
    k = max(range(len(heldout)), key=lambda i: len(heldout.actions[i]))
    frames, actions = heldout.frames[k], heldout.actions[k]
    states = heldout.states[k][None, 1:] if grounded_state_dim(model) else None  # a grounded model at the recorded states
    imagined = rollout(model, frames[None, :1], actions[None], torch.Generator().manual_seed(0), states).frames[0]  # (T, H, W, 3)
    write_side_by_side(path, frames[1:].numpy(), imagined.numpy(), fps)
    return path


def _settings(config: WorldModelTrainConfig) -> dict:
    """`config` as JSON-able values (paths as strings)."""
    return {**dataclasses.asdict(config), "init": None if config.init is None else str(config.init),
            "extra_data": [str(path) for path in config.extra_data]}


def saved_train_config(run: Path) -> WorldModelTrainConfig:
    """The settings a run was started with (from RUN/config.json), for ``--resume``."""
    return from_json(WorldModelTrainConfig, saved_settings(run, "train"))

