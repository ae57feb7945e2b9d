"""Object-level fidelity: does the world model keep the object where the real world puts it?

Whole-frame PSNR barely notices a puck that vanishes or stays behind: it covers a few dozen
pixels. So a position probe (a small CNN) learns to read the object's xyz from a REAL frame,
trained only on real frames of training scenes. Then, for each held-out episode, the world model
imagines it open-loop from its first frame under its real actions, and the probe reads the object
off the imagined frame at steps h = 1, 8, 16, ... The figures, in centimetres from the true
position at step h:

- ``imagined_cm``: probe(imagined frame h), what the world model shows;
- ``real_cm``: probe(real frame h), the probe's own floor on the same frames;
- ``static_cm``: the start position, i.e. an object that never moved (a world model that
  freezes the object scores this);
- ``imagined_vs_real_cm``: probe(imagined) against probe(real) (the probe's bias cancels).

The object is Meta-World v3's first object, observation indices 4:7 (hand xyz 0:3, gripper 3,
object xyz 4:7, its quaternion 7:11, ...; `OBJECT_XYZ`).

Legend: B batch, N frames, K tasks, T steps, H/W image size, A action dimensions.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.tasks import check_task
from gymnast.policy.vision import to_float_image
from gymnast.utils.atomic import write_json
from gymnast.utils.device import bf16_autocast, module_device, to_device
from gymnast.world_model.base import WorldModel, load_world_model, rollout
from gymnast.world_model.data import split_episodes

logger = logging.getLogger(__name__)

OBJECT_XYZ = slice(4, 7)
"""The first object's xyz (metres) in Meta-World v3's 39-d observation (`Episode.env_states`)."""

OBJECT_TASKS = ("pick-place-v3", "push-v3", "peg-insert-side-v3")
"""Tasks with a small object that the robot moves (where "the puck vanished" happens)."""


@dataclass(frozen=True)
class ObjectProbeConfig:
    """How the position probe is trained and where the world model is measured."""

    tasks: tuple[str, ...] = OBJECT_TASKS
    """Tasks measured; the probe has one xyz head per task."""
    steps: int = 3000
    """Optimizer steps of the probe."""
    batch_size: int = 64
    """Real frames per step."""
    lr: float = 2e-3
    """Peak AdamW learning rate (linear warm-up over 5% of the steps, then cosine to zero)."""
    widths: tuple[int, ...] = (16, 32, 64, 64)
    """Channels of the stride-2 convolutions (96 px -> a 6x6 grid); the head reads every cell, so it
    keeps where things are. Narrower than the policy's `SmallCNN`: 7x fewer operations, more steps."""
    blur_fraction: float = 0.5
    """Share of training frames box-blurred (3x3): imagined frames are softer than real ones, and the
    probe should read the object's position, not be thrown by its sharpness."""
    bf16: bool = True
    """Train and apply the probe under bfloat16 autocast (faster on CPUs with bf16 support)."""
    horizons: tuple[int, ...] = (1, 8, 16, 32, 64, 128)
    """Imagined steps h measured (an episode counts at h only if it has at least h actions); most
    objects have barely moved by h = 32, so the later steps are the telling ones."""
    rollout_batch: int = 16
    """Held-out episodes imagined side by side."""
    seed: int = 0
    """Seed of the probe's weights and batches."""


@dataclass(frozen=True)
class ObjectEpisode:
    """One episode reduced to what the probe needs.

    Attributes:
        task: index into the config's tasks.
        frames: (T+1, H, W, 3) uint8.
        actions: (T, A) float32.
        xyz: (T+1, 3) float32 the object's true position in metres.
    """

    task: int
    frames: torch.Tensor
    actions: torch.Tensor
    xyz: torch.Tensor


class ObjectProbe(nn.Module):
    """Real frame -> object xyz: stride-2 convolutions, then a linear head per task over every feature cell.

    Targets are centred on each task's mean position and divided by one per-task scale (the RMS
    distance from that mean, at least 1 cm): isotropic, so the squared loss is the squared
    Euclidean error that the figures report.
    """

    def __init__(self, tasks: Sequence[str], image_size: int, widths: Sequence[int], mean: torch.Tensor,
                 scale: torch.Tensor) -> None:
        super().__init__()
        self.tasks = tuple(tasks)
        layers, size = [], image_size
        for c_in, c_out in zip((3, *widths), widths):
            layers += [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.GroupNorm(8, c_out), nn.GELU()]
            size = (size + 1) // 2
        self.encoder = nn.Sequential(*layers, nn.Flatten())  # (B, 3, H, W) -> (B, widths[-1] * size * size)
        self.head = nn.Linear(widths[-1] * size * size, 3 * len(self.tasks))
        self.register_buffer("mean", mean.float())  # (K, 3) metres
        self.register_buffer("scale", scale.float())  # (K,) metres

    def forward(self, images: torch.Tensor, task: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) float in [0, 1] and (B,) task indices -> (B, 3) normalised positions."""
        out = self.head(self.encoder(images * 2.0 - 1.0)).view(len(images), len(self.tasks), 3)  # (B, K, 3)
        return out[torch.arange(len(images)), task]

    def normalise(self, xyz: torch.Tensor, task: torch.Tensor) -> torch.Tensor:
        """(B, 3) metres -> (B, 3) the probe's target units."""
        return (xyz - self.mean[task]) / self.scale[task, None]

    @torch.no_grad()
    def locate(self, frames: torch.Tensor, task: int, bf16: bool = True, batch: int = 256) -> torch.Tensor:
        """(N, H, W, 3) uint8 frames of one task -> (N, 3) float32 object positions in metres."""
        out, device = [], module_device(self)
        for chunk in frames.split(batch):
            index = torch.full((len(chunk),), task, dtype=torch.long, device=device)
            with bf16_autocast(device, bf16):
                out.append(self(to_float_image(to_device(chunk, device)), index).float())
        return (torch.cat(out) * self.scale[task] + self.mean[task]).cpu()


def load_object_episodes(roots: Sequence[Path], tasks: Sequence[str], heldout_fraction: float, image_size: int,
                         progress: bool = True) -> tuple[list[ObjectEpisode], list[ObjectEpisode]]:
    """(training-scene, held-out-scene) episodes of `tasks` from every dataset, split by the scene hash.

    Raises:
        ValueError: an unknown task, frames of another size, or a task with no training episode.
    """
    for task in tasks:
        check_task(task)
    train, heldout, seen = [], [], set()
    for root in roots:
        dataset = EpisodeDataset(root)
        if dataset.image_shape[:2] != (image_size, image_size):
            raise ValueError(f"{root}: frames are {dataset.image_shape}, the world model makes {image_size}x{image_size}")
        seen |= {info.task for info in dataset.episodes}
        train_ids, heldout_ids = split_episodes(dataset.episodes, heldout_fraction)
        wanted = [(i, side) for ids, side in ((train_ids, train), (heldout_ids, heldout)) for i in ids
                  if dataset.episodes[i].task in tasks]
        for i, side in tqdm(wanted, desc=f"loading {Path(root).name}", disable=not progress):
            episode = dataset.load(i)
            side.append(ObjectEpisode(tasks.index(episode.info.task), torch.from_numpy(episode.frames),
                                      torch.from_numpy(episode.actions).float(),
                                      torch.from_numpy(episode.env_states[:, OBJECT_XYZ]).float()))
    for k, task in enumerate(tasks):
        if not any(e.task == k for e in train):
            raise ValueError(f"no episode of {task} in the training scenes of {', '.join(map(str, roots))} "
                             f"(their tasks: {', '.join(sorted(seen))})")
    return train, heldout


def train_probe(episodes: Sequence[ObjectEpisode], tasks: Sequence[str], config: ObjectProbeConfig,
                progress: bool = True) -> tuple[ObjectProbe, dict]:
    """Fits the probe on every frame of `episodes` (real frames); returns it (eval mode) and its training figures."""
    started = time.perf_counter()
    frames = torch.cat([e.frames for e in episodes])  # (N, H, W, 3)
    xyz = torch.cat([e.xyz for e in episodes])  # (N, 3)
    task = torch.cat([torch.full((len(e.frames),), e.task, dtype=torch.long) for e in episodes])  # (N,)
    mean = torch.stack([xyz[task == k].mean(0) for k in range(len(tasks))])  # (K, 3)
    scale = torch.stack([(xyz[task == k] - mean[k]).square().sum(1).mean().sqrt().clamp(min=0.01) for k in range(len(tasks))])
    torch.manual_seed(config.seed)
    probe = ObjectProbe(tasks, frames.shape[1], config.widths, mean, scale)
    optimizer = torch.optim.AdamW(probe.parameters(), lr=config.lr, weight_decay=1e-4)
    warmup = max(1, config.steps // 20)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: min((s + 1) / warmup, 0.5 * (1 + math.cos(math.pi * s / config.steps))))
    generator = torch.Generator().manual_seed(config.seed)
    losses = []
    for _ in tqdm(range(config.steps), desc="object probe", disable=not progress):
        index = torch.randint(len(frames), (config.batch_size,), generator=generator)
        images = to_float_image(frames[index])  # (B, 3, H, W)
        blur = torch.rand(len(index), generator=generator) < config.blur_fraction
        images = torch.where(blur[:, None, None, None], F.avg_pool2d(images, 3, 1, 1, count_include_pad=False), images)
        with bf16_autocast(module_device(probe), config.bf16):
            prediction = probe(images, task[index])
        loss = F.mse_loss(prediction.float(), probe.normalise(xyz[index], task[index]))
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
    tail = losses[-max(1, len(losses) // 10):]
    return probe.eval(), {"train_frames": len(frames), "train_episodes": len(episodes),
                          "final_loss": sum(tail) / len(tail), "seconds": round(time.perf_counter() - started, 1)}


def imagine_episodes(model: WorldModel, episodes: Sequence[ObjectEpisode], horizon: int, batch: int,
                     progress: bool = True) -> list[torch.Tensor]:
    """Each episode imagined open-loop from its first frame: (min(horizon, T), H, W, 3) uint8 per episode.

    Episodes run side by side; shorter ones are padded with zero actions at the end, which cannot
    change their earlier frames (frame t depends only on actions up to t), and cut back.
    """
    out = []
    for start in tqdm(range(0, len(episodes), batch), desc="imagining", disable=not progress):
        chunk = episodes[start : start + batch]
        steps = min(horizon, max(len(e.actions) for e in chunk))
        actions = torch.zeros(len(chunk), steps, chunk[0].actions.shape[1])  # (B, T, A)
        for j, e in enumerate(chunk):
            actions[j, : len(e.actions[:steps])] = e.actions[:steps]
        context = torch.stack([e.frames[:1] for e in chunk])  # (B, 1, H, W, 3)
        with torch.no_grad():
            frames = rollout(model, context, actions=actions).frames  # (B, T, H, W, 3)
        out.extend(frames[j, : min(steps, len(e.actions))] for j, e in enumerate(chunk))
    return out


def _distance_cm(a: torch.Tensor, b: torch.Tensor) -> list[float]:
    return ((a - b).norm(dim=-1) * 100).tolist()


def _mean(values: list[float]) -> float | None:
    return round(sum(values) / len(values), 2) if values else None


def measure_object_fidelity(wm: Path, data: Path, out: Path, extra_data: Sequence[Path] = (),
                            config: ObjectProbeConfig = ObjectProbeConfig(), progress: bool = True) -> dict:
    """Trains the probe on real training-scene frames, then measures `wm` on the held-out episodes.

    Held out are the world model's held-out scenes (its run's fraction; the scene hash is the same
    for every dataset). Writes the report to `out` and returns it.

    Raises:
        ValueError: unknown task, a task missing from the data, or frames of another size.
    """
    from gymnast.world_model.evaluate import heldout_fraction  # heavy (metrics, videos): only here

    started = time.perf_counter()
    tasks = tuple(config.tasks)
    model = load_world_model(wm)
    fraction = heldout_fraction(Path(wm))
    roots = [Path(data), *map(Path, extra_data)]
    train, heldout = load_object_episodes(roots, tasks, fraction, model.image_size, progress)
    probe, probe_report = train_probe(train, tasks, config, progress)
    imagined = imagine_episodes(model, heldout, max(config.horizons), config.rollout_batch, progress)
    cells = {task: {h: {"imagined": [], "real": [], "static": [], "imagined_vs_real": []} for h in config.horizons}
             for task in tasks}
    floor = {task: [] for task in tasks}
    for episode, frames in zip(heldout, imagined):
        task = tasks[episode.task]
        real = probe.locate(episode.frames, episode.task, config.bf16)  # (T+1, 3)
        floor[task] += _distance_cm(real, episode.xyz)
        steps = [h for h in config.horizons if h <= len(episode.actions)]
        if not steps:
            continue
        index = torch.tensor(steps)
        seen = probe.locate(frames[index - 1], episode.task, config.bf16)  # imagined frame h-1 follows action h-1
        truth = episode.xyz[index]
        for name, values in (("imagined", _distance_cm(seen, truth)), ("real", _distance_cm(real[index], truth)),
                             ("static", _distance_cm(episode.xyz[:1], truth)),
                             ("imagined_vs_real", _distance_cm(seen, real[index]))):
            for h, value in zip(steps, values):
                cells[task][h][name].append(value)
    report = {"tasks": {}}
    for task in tasks:
        episodes = sum(e.task == tasks.index(task) for e in heldout)
        if not episodes:
            logger.warning("%s: no held-out episode in %s", task, ", ".join(map(str, roots)))
        report["tasks"][task] = {
            "heldout_episodes": episodes, "probe_floor_cm": _mean(floor[task]), "probe_floor_frames": len(floor[task]),
            "horizons": {str(h): {"episodes": len(cell["imagined"]), **{f"{k}_cm": _mean(v) for k, v in cell.items()}}
                         for h, cell in cells[task].items()}}
    report |= {"probe": probe_report, "wm": str(wm), "data": [str(r) for r in roots], "heldout_fraction": fraction,
               "heldout_episodes": len(heldout), "config": asdict(config),
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(out, report)
    return report


def format_object_table(report: dict) -> str:
    """The report as a text table: per task and step, episodes and the four distances (cm)."""
    lines = [f"{'task':<20} {'h':>3} {'n':>3} {'imagined':>9} {'real':>6} {'static':>7} {'im-vs-real':>10}"]

    def cell(value: float | None) -> str:
        return "-" if value is None else f"{value:.1f}"

    for task, row in report["tasks"].items():
        for h, c in row["horizons"].items():
            lines.append(f"{task:<20} {h:>3} {c['episodes']:>3} {cell(c['imagined_cm']):>9} {cell(c['real_cm']):>6} "
                         f"{cell(c['static_cm']):>7} {cell(c['imagined_vs_real_cm']):>10}")
        lines.append(f"{task:<20} probe floor on {row['probe_floor_frames']} held-out real frames: "
                     f"{cell(row['probe_floor_cm'])} cm")
    return "\n".join(lines)
