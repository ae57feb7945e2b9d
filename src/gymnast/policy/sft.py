"""`gymnast sft`: behaviour cloning of the embedded VLA on successful expert demonstrations.

Only successful episodes of the scripted experts (clean or with action noise) are imitated, N per
task: the papers' SFT baselines are few-shot and clearly imperfect on the real robot, which
leaves RL room to show what it adds. Each training sample is one frame, its instruction and the
next K actions (a chunk running past the episode's end is masked out of the loss).

Legend: M samples, B batch, H/W image size, K chunk length, A action dimensions, N = K * A.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Literal

import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from gymnast.data.action_stats import ActionStats
from gymnast.data.frames import Fit, model_image_size
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.data.schema import EpisodeInfo
from gymnast.policy.action_tokenizer import ActionTokenizer
from gymnast.policy.base import state_inputs
from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig
from gymnast.policy.observation import shared_architecture
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.images import split_views
from gymnast.utils.checkpoint import begin_training, resolve_checkpoint, save_training
from gymnast.utils.device import resolve_device
from gymnast.utils.distributed import Parallel, data_parallel
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.utils.settings import from_json, saved_settings
from gymnast.utils.trackers import TrackerNames

logger = logging.getLogger(__name__)

DEMO_BEHAVIOURS = ("expert", "noisy_expert")


@dataclass(frozen=True)
class SFTConfig:
    """Behaviour cloning settings."""

    demos_per_task: int = 10
    """Successful expert episodes per task to imitate (few-shot keeps SFT imperfect)."""
    camera: str | None = None
    """Camera to read from the dataset (e.g. ``front``); default: the first camera whose frames exist."""
    cameras: tuple[str, ...] = ()
    """Several cameras the policy sees side by side, the primary first (e.g. ``front,gripper``; each
    fitted to the square image alone); default: `camera` alone. Saved with the policy, so that
    evaluation and RL render the same views."""
    robot_state: bool = False
    """The policy also reads the robot's state (the dataset's states, e.g. hand xyz and gripper; its
    dimensions are the dataset's), and is then given the simulator's ``obs["state"]`` wherever it
    acts. Saved with the policy (`PolicyArchitecture.state_dim`)."""
    keys: FeatureKeys = FeatureKeys()
    """Which dataset features are the actions and the states (--action-key, --state-key); saved with the run."""
    fit: Fit = "resize"
    """How frames become the policy's square image when they are not square or larger than 256 px
    (they are then fitted to `vla.image_size`): resize (the whole frame, aspect ratio not kept) or
    crop (the central square). Square frames up to 256 px, a multiple of 8, set the image size and
    are used as they are. Saved with the run."""
    steps: int = 2400
    """Optimizer steps (about 8 minutes on 2 CPU cores at the default size)."""
    batch_size: int = 64
    """Samples per step."""
    lr: float = 3e-4
    """Peak learning rate (AdamW, linear warm-up then cosine decay)."""
    weight_decay: float = 0.01
    """AdamW weight decay."""
    warmup_steps: int = 100
    """Linear warm-up steps."""
    shift_augment: int = 4
    """Random image shifts of up to this many pixels (padding by edge replication)."""
    bf16: bool = True
    """Run the image encoder under bfloat16 autocast (faster on recent CPUs)."""
    checkpoint_every: int = 500
    """Steps between checkpoints."""
    log_every: int = 50
    """Steps between metrics lines."""
    tracker: TrackerNames = ()
    """Where the run logs besides RUN/metrics.jsonl: none, or any of tensorboard and wandb,
    comma-separated (gymnast.utils.trackers)."""
    seed: int = 0
    """Seed of initialisation, batch order and augmentation."""
    tasks: str = ""
    """Restrict to these tasks (comma-separated); empty = every task in the dataset."""
    policy: Literal["tokens", "flow"] = "tokens"
    """Policy family: tokens (the tokenized VLA) or flow (the flow-matching VLA of VLA-RFT, with
    `vla`'s architecture and `flow_steps` integration steps; docs/policy.md)."""
    flow_steps: int = 5
    """Flow policy only: Euler steps from noise to an action chunk."""
    device: str = "auto"
    """Where to train: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N. The
    demonstrations stay on the host; each batch is copied over (bf16 autocast on either device)."""
    vla: VLAConfig = field(default_factory=VLAConfig)
    """Model architecture."""


SFT_PRESETS: dict[str, SFTConfig] = {
    "debug": SFTConfig(demos_per_task=1, steps=6, batch_size=4, warmup_steps=2, checkpoint_every=3, log_every=2,
                       vla=VLAConfig(width=32, layers=1, heads=2)),
    "demo": SFTConfig(steps=1000),
    "full": SFTConfig(),
}


@dataclass(frozen=True)
class DemoSet:
    """Training samples in memory: images (M, H, W, 3) uint8, chunks (M, K, A), valid (M, K) bool,
    instruction (M,) index into `instructions`, and the robot's states (M, D) float32 where known
    (a policy that reads them imitates with them)."""

    images: torch.Tensor
    chunks: torch.Tensor
    valid: torch.Tensor
    instruction: torch.Tensor
    instructions: list[str]
    episodes: list[EpisodeInfo]
    states: torch.Tensor | None = None


@dataclass(frozen=True)
class SamplesFrom:
    """Extra samples made from the chosen demonstrations, drawn 1:1 with them: ``make(dataset,
    indices, demos, chunk_size)`` (say, `gymnast.world_model.reimagine.imagined_demos`: the
    demonstrations as a world model imagines them); `saved` is what the run records of their
    source beside its inputs (e.g. ``{"imagined_by": WM}``)."""

    make: Callable[[EpisodeDataset, list[int], DemoSet, int], DemoSet]
    saved: dict[str, str]


def select_demos(dataset: EpisodeDataset, per_task: int, tasks: str = "") -> list[int]:
    """Indices of the first `per_task` successful expert episodes of each task (by seed, noise).

    Raises:
        ValueError: a task has fewer successful expert episodes than asked for.
    """
    infos = dataset.episodes
    wanted = {t.strip() for t in tasks.split(",") if t.strip()} or {info.task for info in infos}
    chosen = []
    for task in sorted(wanted):
        pool = sorted(
            (i for i, info in enumerate(infos) if info.task == task and info.success and info.behaviour in DEMO_BEHAVIOURS),
            key=lambda i: (infos[i].seed, infos[i].noise),
        )
        if len(pool) < per_task:
            raise ValueError(
                f"{dataset.root}: task {task!r} has {len(pool)} successful expert episodes, "
                f"--demos-per-task asks for {per_task}; collect more or ask for fewer"
            )
        chosen += pool[:per_task]
    return chosen


def load_demos(dataset: EpisodeDataset, indices: list[int], chunk_size: int) -> DemoSet:
    """Decodes the chosen episodes into (frame, instruction, next K actions) samples."""
    images, chunks, valid, instruction, instructions, infos, states = [], [], [], [], [], [], []
    for i in indices:
        episode = dataset.load(i)
        steps = episode.length
        actions = torch.from_numpy(episode.actions)  # (T, A)
        padded = torch.cat([actions, torch.zeros(chunk_size - 1, actions.shape[1])])
        chunks.append(padded.unfold(0, chunk_size, 1).transpose(1, 2))  # (T, K, A)
        valid.append(torch.arange(steps).unsqueeze(1) + torch.arange(chunk_size) < steps)  # (T, K)
        images.append(torch.from_numpy(episode.observed_frames[:steps]))  # every camera read, side by side
        states.append(torch.from_numpy(episode.states[:steps]).float())
        if episode.info.instruction not in instructions:
            instructions.append(episode.info.instruction)
        instruction.append(torch.full((steps,), instructions.index(episode.info.instruction)))
        infos.append(episode.info)
    return DemoSet(torch.cat(images), torch.cat(chunks), torch.cat(valid), torch.cat(instruction), instructions, infos,
                   torch.cat(states))


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator, views: int = 1) -> torch.Tensor:
    """Shifts each (H, W, 3) uint8 image by up to `pad` pixels (DrQ-style augmentation); an image of
    `views` cameras side by side has each camera's square shifted alone, as if each camera moved."""
    if pad == 0:
        return images
    if views > 1:
        batch, height, width, _ = images.shape
        shifted = random_shift(split_views(images, views), pad, generator)  # (B*V, H, W/V, 3)
        return shifted.view(batch, views, height, width // views, 3).transpose(1, 2).reshape(images.shape)
    batch, height, width, _ = images.shape
    padded = F.pad(images.permute(0, 3, 1, 2).float(), (pad,) * 4, mode="replicate")
    dx, dy = (torch.randint(0, 2 * pad + 1, (2, batch), generator=generator)).unbind(0)
    rows = (torch.arange(height).unsqueeze(0) + dy.unsqueeze(1))  # (B, H)
    cols = (torch.arange(width).unsqueeze(0) + dx.unsqueeze(1))  # (B, W)
    batch_index = torch.arange(batch)[:, None, None]
    shifted = padded.permute(0, 2, 3, 1)[batch_index, rows[:, :, None], cols[:, None, :]]  # (B, H, W, 3)
    return shifted.to(torch.uint8)


def train_sft(data: Path, out: Path, config: SFTConfig, resume: bool = False, progress: bool = True,
              init: Path | None = None, extra: DemoSet | None = None, samples_from: SamplesFrom | None = None) -> Path:
    """Trains (or resumes) an SFT run in `out`; returns the final checkpoint directory.

    Args:
        init: start from this policy run's weights (its architecture replaces ``config.vla``)
            instead of a fresh model: fine-tuning, as Iter-SFT does.
        extra: more samples (say, a policy's own successful rollouts), drawn 1:1 with the
            demonstrations: half of every batch comes from each.
        samples_from: the extra samples made from the chosen demonstrations instead (not with `extra`).
    """
    if samples_from is not None and extra is not None:
        raise ValueError("train_sft takes extra samples or samples_from, not both")
    dataset = EpisodeDataset(data, config.camera, config.cameras or None, keys=config.keys)
    size = model_image_size(dataset.camera_shape, config.vla.image_size)
    if init is not None:
        from gymnast.policy.load import load_policy

        model = load_policy(init)
        config = _with_architecture_of(model, config)
        if size != config.vla.image_size or dataset.action_dim != config.vla.action_dim:
            raise ValueError(f"{data} makes {size}px images and {dataset.action_dim}-D actions, but the policy "
                             f"in {init} sees {config.vla.image_size}px images and acts in {config.vla.action_dim}-D")
        if len(dataset.cameras) != len(config.vla.cameras):
            raise ValueError(f"{data} is read with cameras {','.join(dataset.cameras)}, but the policy in {init} "
                             f"sees {len(config.vla.cameras)}: {','.join(config.vla.cameras)}; pass --cameras to match")
    stats = dataset.action_stats  # read before training starts: a dataset without actions fails here
    config = dataclasses.replace(config, vla=dataclasses.replace(config.vla, image_size=size, action_dim=dataset.action_dim,
                                                                 cameras=dataset.cameras))
    dataset = dataset.fitted(size, config.fit)
    chosen = select_demos(dataset, config.demos_per_task, config.tasks)
    demos = load_demos(dataset, chosen, config.vla.chunk_size)
    if samples_from is not None:
        extra = samples_from.make(dataset, chosen, demos, config.vla.chunk_size)
    if config.robot_state and init is None:
        config = dataclasses.replace(config, vla=dataclasses.replace(config.vla, state_dim=state_dim_of(data, demos)))
    logger.info("SFT on %d demonstrations (%d samples, %d instructions)%s", len(demos.episodes), len(demos.images),
                len(demos.instructions), f" and {len(extra.images)} extra samples" if extra is not None else "")
    torch.manual_seed(config.seed)
    if init is None:
        model = build_sft_policy(config, stats.action_range())
        if model.state_dim:
            model.standardise_states(demos.states)
    with data_parallel(resolve_device(config.device)) as parallel:
        if parallel.world_size > 1 and config.policy == "flow":
            raise ValueError("sft --policy-type flow draws its noise per sample and does not train under torchrun yet; "
                             "run it as one process")
        model = model.to(parallel.device)  # before the optimizer: it keeps the parameters it is given
        return _train(out, config, model, demos, extra, _saved_inputs(data, init, extra, stats, demos, samples_from),
                      resume, progress, parallel)


def _saved_inputs(data: Path, init: Path | None, extra: DemoSet | None, stats: ActionStats, demos: DemoSet,
                  samples_from: SamplesFrom | None) -> dict:
    """What an SFT run saves beside its settings and model: its data, demonstrations, start and where
    its extra samples came from (``imagined_by``: the world model that imagined them, or None)."""
    return {"data": str(data), "action_stats": stats.to_dict(), "demos": [info.key for info in demos.episodes],
            "init": str(init) if init else None, "extra_samples": len(extra.images) if extra is not None else 0,
            "imagined_by": None, **(samples_from.saved if samples_from is not None else {})}


def _train(out: Path, config: SFTConfig, model: nn.Module, demos: DemoSet, extra: DemoSet | None, inputs: dict,
           resume: bool, progress: bool, parallel: Parallel) -> Path:
    """`train_sft`'s loop, in this process of the run (`gymnast.utils.distributed`): every process
    draws the global batch and trains on its share; rank 0 writes the run."""
    pool, draw = _batch_pool(demos, extra, config.batch_size)
    share = parallel.share(config.batch_size)
    loss_of = parallel.loss(model, lambda policy, *batch, **states: policy.imitation_loss(*batch, **states))
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    resolved = {"sft": dataclasses.asdict(config), "model": model.spec(), **inputs}
    start, metrics = begin_training(out, resolved, model, optimizer, schedule, sampler, resume, parallel.is_main,
                                    config.tracker, "sft")
    model.train()
    bar = tqdm(range(start, config.steps), initial=start, total=config.steps, desc="sft",
               disable=not (progress and parallel.is_main))
    started = time.perf_counter()
    checkpoint = None
    for step in bar:
        batch = draw(sampler)  # the global batch (and its augmentation): every process draws it
        images = random_shift(pool.images[batch], config.shift_augment, sampler, len(config.vla.cameras))[share]
        batch = batch[share]
        texts = [pool.instructions[i] for i in pool.instruction[batch].tolist()]
        valid = pool.valid[batch]
        states = state_inputs(model, None if pool.states is None else pool.states[batch])
        loss, values = loss_of(images, texts, pool.chunks[batch], valid, config.bf16, sampler, **states)
        # The loss is a mean over valid action steps, whose count differs between the processes' shares.
        count = valid.sum().item()
        loss, values = parallel.global_mean(loss, count), parallel.average(values, count)
        values["train/grad_norm"] = gradient_step(loss, model, optimizer, schedule)
        done = step + 1
        if not parallel.is_main:
            continue
        if done % config.log_every == 0 or done == config.steps:
            values |= {"train/lr": schedule.get_last_lr()[0], "time/step_s": (time.perf_counter() - started) / (done - start)}
            metrics.log(done, values)
            bar.set_postfix(loss=f"{values['train/loss']:.3f}")
        if done % config.checkpoint_every == 0 or done == config.steps:
            checkpoint = save_training(out, done, model, resolved, optimizer, schedule, sampler)
    if metrics is not None:
        metrics.close()
    parallel.barrier()  # the others return rank 0's last checkpoint once it is written
    return checkpoint or resolve_checkpoint(out)


def state_dim_of(data: Path, demos: DemoSet) -> int:
    """The robot state dimensions of the demonstrations, which a policy that reads the state learns from."""
    if demos.states is None or demos.states.shape[1] == 0:
        raise ValueError(f"{data} records no robot state (observation.state), so --robot-state has nothing to read; "
                         f"name the dataset's state feature with --state-key or leave --robot-state out")
    return demos.states.shape[1]


def build_sft_policy(config: SFTConfig, action_range: tuple[tuple[float, ...], tuple[float, ...]] | None = None) -> nn.Module:
    """A fresh policy of the family and architecture `config` names, acting in `action_range`
    ((low, high) per dimension, the dataset's: the tokenizer's bins or the flow's [-1, 1] span
    it; default [-1, 1], Meta-World's)."""
    low, high = action_range or ((-1.0,) * config.vla.action_dim, (1.0,) * config.vla.action_dim)
    if config.policy == "tokens":
        return EmbeddedVLA(config.vla, ActionTokenizer(low, high, config.vla.bins))
    shared = shared_architecture(config.vla)  # a flow policy is built from `SFTConfig.vla`'s fields
    return FlowVLA(FlowVLAConfig(**shared, steps=config.flow_steps, low=low, high=high))


def _with_architecture_of(model: nn.Module, config: SFTConfig) -> SFTConfig:
    """`config` describing the family and architecture of `model` (fine-tuning keeps them)."""
    if isinstance(model, EmbeddedVLA):
        return dataclasses.replace(config, policy="tokens", vla=model.config)
    shared = shared_architecture(model.config)
    return dataclasses.replace(config, policy="flow", flow_steps=model.config.steps,
                               vla=dataclasses.replace(config.vla, **shared))


def _batch_pool(demos: DemoSet, extra: DemoSet | None, batch_size: int):
    """(one DemoSet holding every sample, draw(generator) -> (batch_size,) indices into it): all
    from the demonstrations, or half from them and half from `extra`."""
    if extra is None:
        return demos, lambda generator: torch.randint(0, len(demos.images), (batch_size,), generator=generator)
    if demos.images.shape[1:] != extra.images.shape[1:] or demos.chunks.shape[1:] != extra.chunks.shape[1:]:
        raise ValueError(f"extra samples have images {tuple(extra.images.shape[1:])} and chunks {tuple(extra.chunks.shape[1:])}, "
                         f"the demonstrations {tuple(demos.images.shape[1:])} and {tuple(demos.chunks.shape[1:])}")
    instructions = list(dict.fromkeys(demos.instructions + extra.instructions))
    remap = torch.tensor([instructions.index(text) for text in extra.instructions], dtype=torch.long)
    both_states = demos.states is not None and extra.states is not None
    pool = DemoSet(torch.cat([demos.images, extra.images]), torch.cat([demos.chunks, extra.chunks]),
                   torch.cat([demos.valid, extra.valid]), torch.cat([demos.instruction, remap[extra.instruction]]),
                   instructions, demos.episodes + extra.episodes,
                   torch.cat([demos.states, extra.states]) if both_states else None)
    first, offset = batch_size // 2, len(demos.images)

    def draw(generator: torch.Generator) -> torch.Tensor:
        own = torch.randint(0, offset, (first,), generator=generator)
        more = offset + torch.randint(0, len(extra.images), (batch_size - first,), generator=generator)
        return torch.cat([own, more])

    return pool, draw


def saved_sft_config(run: Path) -> SFTConfig:
    """The settings an SFT run was started with (from RUN/config.json), for ``--resume``."""
    return from_json(SFTConfig, saved_settings(run, "sft"))

