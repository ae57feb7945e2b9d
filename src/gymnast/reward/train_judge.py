"""`gymnast train-judge`: fit the learned judge on real (and imagined) episodes, then measure it.

Held-out episodes are those of the world model's held-out scenes (`gymnast.world_model.data`), so
their imagined versions come from scenes the world model never saw either. The report counts, on
real and on imagined videos separately: positives = whole successful episodes; negatives = whole
failed episodes, and successful episodes cut before their success (halfway there, and
`NEAR_MISS_STEPS` short), the near misses a judge of RL rollouts must not pass.

Legend: B batch, T steps, H/W image size.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.reward.base import Reward, RewardContext
from gymnast.reward.judge import JudgeConfig, LearnedJudge, judge_loss, judged_frame_indices
from gymnast.utils.atomic import write_json
from gymnast.utils.checkpoint import load_model, resume_training, save_training, saved_settings, write_run_config
from gymnast.utils.metrics import MetricsLog
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.data import split_episodes

logger = logging.getLogger(__name__)

NEAR_MISS_STEPS = 10  # a held-out negative: a successful episode cut this many steps before its success


@dataclass(frozen=True)
class JudgeTrainConfig:
    """Learned-judge training settings."""

    steps: int = 1000
    """Optimizer steps (about 6 minutes on 2 CPU cores)."""
    batch_size: int = 32
    """Videos per step."""
    lr: float = 3e-4
    """Peak learning rate (AdamW, warm-up then cosine decay)."""
    warmup_steps: int = 50
    """Linear warm-up steps."""
    whole_share: float = 0.5
    """Share of training videos that are whole episodes; the rest are cut at a random step."""
    ambiguous_steps: int = 5
    """Cuts this close before a success are not used as negatives (the frames barely differ from the
    success frame, so they teach the judge to doubt real successes); the whole episode is used instead."""
    heldout_fraction: float = 0.1
    """Share of scenes held out (use the world model's, so imagined held-out videos are unseen)."""
    checkpoint_every: int = 500
    """Steps between checkpoints."""
    log_every: int = 25
    """Steps between metrics lines."""
    seed: int = 0
    """Seed of initialisation and sampling."""
    judge: JudgeConfig = field(default_factory=JudgeConfig)
    """Architecture."""


JUDGE_PRESETS = {
    "debug": JudgeTrainConfig(steps=4, batch_size=4, warmup_steps=1, checkpoint_every=2, log_every=1, judge=JudgeConfig(width=32)),
    "demo": JudgeTrainConfig(steps=400),
    "full": JudgeTrainConfig(),
}


@dataclass(frozen=True)
class Video:
    """One episode's video (real or imagined) with its per-frame success: (T+1, H, W, 3) uint8 and
    (T+1,) bool, frame t counting as success once the episode has succeeded by then."""

    frames: torch.Tensor
    success: torch.Tensor
    instruction: str
    imagined: bool


def load_videos(dataset: EpisodeDataset, indices: list[int], wm: Path | None, progress: bool) -> list[Video]:
    """Real videos of the episodes, plus their re-imaginings under the real actions with a world model."""
    model = load_world_model(wm) if wm else None
    videos = []
    for i in tqdm(indices, desc="loading episodes", disable=not progress):
        episode = dataset.load(i)
        frames = torch.from_numpy(episode.frames)
        reached = torch.cat([torch.zeros(1, dtype=torch.bool), torch.from_numpy(episode.successes).bool().cummax(0).values])
        videos.append(Video(frames, reached, episode.info.instruction, imagined=False))
        if model is not None:
            imagined = rollout(model, frames[None, :1], actions=torch.from_numpy(episode.actions)[None].float()).frames[0]
            videos.append(Video(torch.cat([frames[:1], imagined]), reached, episode.info.instruction, imagined=True))
    return videos


def heldout_videos(dataset: EpisodeDataset, fraction: float, wm: Path | None = None) -> list[Video]:
    """The videos of the held-out scenes' episodes (and their re-imaginings with a world model)."""
    return load_videos(dataset, split_episodes(dataset.episodes, fraction)[1], wm, progress=False)


def _sample(videos: list[Video], batch: int, whole_share: float, ambiguous: int, generator: torch.Generator):
    """(B, F, H, W, 3) judged frames of random (possibly cut) videos, their instructions and labels."""
    frames, texts, labels = [], [], []
    for _ in range(batch):
        video = videos[int(torch.randint(len(videos), (1,), generator=generator))]
        length = len(video.frames)
        if torch.rand((), generator=generator) >= whole_share:
            length = int(torch.randint(2, length + 1, (1,), generator=generator))
            first = int(video.success.float().argmax()) if video.success[-1] else len(video.frames)
            if first - ambiguous <= length - 1 < first:  # a few steps short of success: too close to call
                length = len(video.frames)
        frames.append(video.frames[judged_frame_indices(length)])
        texts.append(video.instruction)
        labels.append(video.success[length - 1])
    return torch.stack(frames), texts, torch.stack(labels)


def train_judge(data: Path, out: Path, config: JudgeTrainConfig, wm: Path | None = None, resume: bool = False,
                progress: bool = True) -> dict:
    """Trains the judge in `out`, writes `out/metrics.json` (held-out TPR/FPR) and returns it."""
    started = time.perf_counter()
    dataset = EpisodeDataset(data)
    config = dataclasses.replace(config, judge=dataclasses.replace(config.judge, image_size=dataset.image_shape[0]))
    train_ids, heldout_ids = split_episodes(dataset.episodes, config.heldout_fraction)
    train_videos = load_videos(dataset, train_ids, wm, progress)
    torch.manual_seed(config.seed)
    judge = LearnedJudge(config.judge)
    optimizer = torch.optim.AdamW(judge.parameters(), lr=config.lr, weight_decay=0.01)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    resolved = {"train": dataclasses.asdict(config), "model": judge.spec(), "data": str(data), "wm": str(wm) if wm else None}
    start = resume_training(out, judge, optimizer, schedule, sampler) if resume else 0
    write_run_config(out, resolved)
    metrics = MetricsLog(out, resume_step=start if resume else None)
    judge.train()
    bar = tqdm(range(start, config.steps), initial=start, total=config.steps, desc="train-judge", disable=not progress)
    for step in bar:
        frames, texts, labels = _sample(train_videos, config.batch_size, config.whole_share, config.ambiguous_steps, sampler)
        loss, values = judge_loss(judge, frames, judge.encoder(texts), labels)
        values["train/grad_norm"] = gradient_step(loss, judge, optimizer, schedule)
        done = step + 1
        if done % config.log_every == 0 or done == config.steps:
            metrics.log(done, values)
            bar.set_postfix(loss=f"{values['train/loss']:.3f}", acc=f"{values['train/accuracy']:.2f}")
        if done % config.checkpoint_every == 0 or done == config.steps:
            save_training(out, done, judge, resolved, optimizer, schedule, sampler)
    report = evaluate_judge(judge.eval(), heldout_videos(dataset, config.heldout_fraction, wm))
    report |= {"data": str(data), "wm": str(wm) if wm else None, "heldout_episodes": len(heldout_ids),
               "train_episodes": len(train_ids), "seconds": round(time.perf_counter() - started, 1)}
    write_json(out / "metrics.json", report)
    return report


def evaluate_judge(judge: Reward, videos: list[Video]) -> dict:
    """TPR, FPR and accuracy of any 0/1 judge, real and imagined apart; FPR over all negatives and over
    whole failed episodes. A NaN verdict (could not score) counts as "not success" and is counted."""
    report = {}
    for imagined in (False, True):
        cases = []  # (frames, instruction, label, whole episode?)
        for video in (v for v in videos if v.imagined == imagined):
            cases.append((video.frames, video.instruction, bool(video.success[-1]), True))
            if video.success[-1]:
                first = int(video.success.float().argmax())  # the first frame showing success
                for cut in {first // 2, first - NEAR_MISS_STEPS}:  # halfway there; a few steps short
                    if cut >= 2:
                        cases.append((video.frames[:cut], video.instruction, False, False))
        if not cases:
            continue
        verdicts = torch.stack([judge.score(f[None], [text], RewardContext())[0] for f, text, _, _ in cases])
        predicted = verdicts >= 0.5  # NaN compares False
        truth = torch.tensor([label for _, _, label, _ in cases])
        whole = torch.tensor([w for _, _, _, w in cases])
        prefix = "imagined" if imagined else "real"
        report |= {
            f"{prefix}_tpr": _rate(predicted, truth),
            f"{prefix}_fpr": _rate(predicted, ~truth),
            f"{prefix}_fpr_whole_failures": _rate(predicted, ~truth & whole),
            f"{prefix}_accuracy": round((predicted == truth).float().mean().item(), 4),
            f"{prefix}_positives": int(truth.sum()),
            f"{prefix}_negatives": int((~truth).sum()),
            f"{prefix}_whole_failures": int((~truth & whole).sum()),
            f"{prefix}_unscored": int(torch.isnan(verdicts).sum()),
        }
    return report


def _rate(predicted: torch.Tensor, among: torch.Tensor) -> float | None:
    """Share of `among` predicted positive (None when there are none)."""
    return round((predicted & among).sum().item() / among.sum().item(), 4) if among.any() else None


def saved_judge_config(run: Path) -> JudgeTrainConfig:
    """The settings a run was started with (RUN/config.json), for ``--resume``."""
    saved = saved_settings(run, "train")
    return JudgeTrainConfig(**{**saved, "judge": JudgeConfig(**saved["judge"])})


def load_judge(run: Path) -> LearnedJudge:
    """The newest checkpoint of a judge run (or a checkpoint directory), in eval mode."""
    return load_model(Path(run), LearnedJudge.from_spec)
