"""`gymnast train-judge`: fit the learned judge on real (and imagined) episodes, then measure it.

Three judges train here: the per-frame judge (`kind="frames"`, `gymnast.reward.judges.frames`), which
learns from every frame with Meta-World's per-step success flag; the video judge (`kind="video"`,
`gymnast.reward.judges.video`), which learns from whole videos and their prefixes; and the progress judge
(`kind="progress"`, `gymnast.reward.judges.progress`), which learns every frame's dense reward and
scores a video by degree, with no threshold (its report has correlations, not TPR/FPR).

Scenes are split three ways by a fixed hash: held-out scenes are the world model's
(`gymnast.world_model.data`), so their imagined versions come from scenes the world model never
saw either, and they alone make the reported figures; validation scenes, a share of the rest,
choose the decision threshold; the remaining scenes train. The report counts, on real and on
imagined videos separately: positives = whole successful episodes; negatives = whole failed
episodes, and successful episodes cut before their success (halfway there, and `NEAR_MISS_STEPS`
short), the near misses a judge of RL rollouts must not pass.

Legend: B batch, T steps, H/W image size.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.data.frames import Fit, model_image_size
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.frames import FrameJudge, frame_loss
from gymnast.reward.judges.measure import choose_threshold, evaluate_judge
from gymnast.reward.judges.progress import ProgressJudge, evaluate_progress, progress_loss
from gymnast.reward.judges.video import LearnedJudge, judge_loss, judged_frame_indices
from gymnast.reward.judges.videos import Video, load_videos
from gymnast.utils.atomic import read_json, write_json
from gymnast.utils.checkpoint import begin_training, load_model, save_training, write_run_config
from gymnast.utils.device import resolve_device
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.utils.settings import from_json, saved_settings
from gymnast.utils.trackers import TrackerNames
from gymnast.world_model.data import split_episodes

logger = logging.getLogger(__name__)

HARD_CANDIDATES = 4  # random negatives drawn per hard one kept (scored without gradients: ~1.2x the step)

Scorer = Callable[[torch.Tensor, torch.Tensor, list[str]], torch.Tensor]
"""(N, H, W, 3) first frames, (N, H, W, 3) frames and N instructions -> (N,) success logits."""

JUDGES = {"frames": FrameJudge, "video": LearnedJudge, "progress": ProgressJudge}
"""Judge kinds by name; a checkpoint names its class by `backend`."""


@dataclass(frozen=True)
class JudgeTrainConfig:
    """Learned-judge training settings."""

    kind: str = "frames"
    """frames: the per-frame judge (every frame a labelled example; a video succeeds where any frame
    does); video: the judge of four frames of a whole video, trained on videos and their prefixes;
    progress: every frame's dense reward, a video scored by its mean (a continuous reward)."""
    steps: int = 1000
    """Optimizer steps."""
    batch_size: int = 32
    """Examples per step: frames (half of them success frames) or videos."""
    lr: float = 3e-4
    """Peak learning rate (AdamW, warm-up then cosine decay)."""
    warmup_steps: int = 50
    """Linear warm-up steps."""
    whole_share: float = 0.5
    """Video judge: share of training videos that are whole episodes; the rest are cut at a random step."""
    ambiguous_steps: int = 5
    """Frames (or cuts) this close before a success are not used as negatives (they barely differ
    from the success frame, so they teach the judge to doubt real successes)."""
    hard_negatives: float = 0.0
    """Per-frame judge: share of each batch's negative frames that are the ones the judge itself
    scores highest among `HARD_CANDIDATES` times as many drawn at random (online hard-negative
    mining): the near misses, which a uniform draw over mostly easy frames rarely shows it. 0: all
    drawn at random. The video and progress judges have no verdict per frame to mine and ignore it."""
    heldout_fraction: float = 0.1
    """Share of scenes held out (use the world model's, so imagined held-out videos are unseen)."""
    validation_fraction: float = 0.1
    """Share of the other scenes that choose the decision threshold instead of training."""
    threshold_tpr: float | None = None
    """Choose the decision threshold for this true-positive rate on the validation scenes (the
    highest threshold that still passes this share of their successes, so the fewest false
    successes at that rate) instead of the most TPR - FPR: an operating point such as "TPR 0.95"."""
    hold_steps: int = 5
    """Per-frame judge: steps in a row that must show the task done for a video to count as a
    success (a run reaching the video's end counts as held); saved with the judge
    (`JudgeConfig.hold_steps`), and its threshold is chosen under it. 1 believes any single frame.
    Meta-World's successes last, and a judge's false successes are often a frame or two that the
    frames around them deny: on the three-camera headline's held-out real videos its judge's lowest
    FPR at TPR 0.95 is 0.053 over 1 step, 0.044 over 5 and 0.026 over 12 (docs/rewards.md,
    "Holding a success"); longer holds did not choose better thresholds on its validation scenes."""
    extra_data: tuple[Path, ...] = ()
    """More datasets besides DATA (e.g. a policy's own recorded rollouts), with the same image
    size; each is split by the same scene hashes, and every part (train, validation, held-out)
    takes its share of each."""
    camera: str | None = None
    """Camera to read from the datasets (e.g. ``front``); default: the first camera whose frames exist."""
    cameras: tuple[str, ...] = ()
    """Several cameras the per-frame judges see side by side, the primary first (e.g.
    ``front,gripper``); default: `camera` alone. Saved with the judge."""
    keys: FeatureKeys = FeatureKeys()
    """Which dataset features are the actions and the states (--action-key, --state-key); saved with the run."""
    fit: Fit = "resize"
    """How frames become the judge's square image when they are not square or larger than 256 px
    (they are then fitted to `judge.image_size`): resize (the whole frame, aspect ratio not kept) or
    crop (the central square). Square frames up to 256 px, a multiple of 8, set the image size and
    are used as they are. Use the world model's fit, so real and imagined frames look alike."""
    init: Path | None = None
    """Start from the weights of this judge run or checkpoint (fine-tuning, e.g. on a policy's newly
    recorded rollouts) instead of a random initialisation; its kind and architecture must be this
    run's. The optimizer, the schedule and the threshold start afresh."""
    checkpoint_every: int = 500
    """Steps between checkpoints."""
    log_every: int = 25
    """Steps between metrics lines."""
    tracker: TrackerNames = ()
    """Where the run logs besides RUN/metrics.jsonl: none, or any of tensorboard and wandb,
    comma-separated (gymnast.utils.trackers)."""
    seed: int = 0
    """Seed of initialisation and sampling."""
    device: str = "auto"
    """Where to train (and re-imagine episodes with --wm): auto (CUDA when torch sees a GPU, else
    the CPU), cpu, cuda or cuda:N. Videos stay on the host; each batch is copied over."""
    judge: JudgeConfig = field(default_factory=JudgeConfig)
    """Architecture."""

    def __post_init__(self) -> None:
        if self.kind not in JUDGES:
            raise ValueError(f"JudgeTrainConfig.kind must be one of {sorted(JUDGES)}, got {self.kind!r}")
        if not 0 <= self.validation_fraction < 1:
            raise ValueError(f"JudgeTrainConfig.validation_fraction must be in [0, 1), got {self.validation_fraction}")
        if not 0 <= self.hard_negatives <= 1:
            raise ValueError(f"JudgeTrainConfig.hard_negatives must be in [0, 1], got {self.hard_negatives}")
        if self.threshold_tpr is not None and not 0 < self.threshold_tpr <= 1:
            raise ValueError(f"JudgeTrainConfig.threshold_tpr must be in (0, 1], got {self.threshold_tpr}")
        if self.hold_steps < 1:
            raise ValueError(f"JudgeTrainConfig.hold_steps must be at least 1, got {self.hold_steps}")


JUDGE_PRESETS = {
    "debug": JudgeTrainConfig(steps=4, batch_size=4, warmup_steps=1, checkpoint_every=2, log_every=1, judge=JudgeConfig(width=32)),
    "demo": JudgeTrainConfig(steps=400),
    # Half the negatives mined: on the policy's rollouts, held-out TPR 0.92 -> 1.00 and FPR 0.054 ->
    # 0.041, its ranking of them unchanged, for about 1.2x the step (results/judge/cameras/README.md).
    "full": JudgeTrainConfig(steps=2000, batch_size=64, hard_negatives=0.5),
    # A wider judge and 4x the batch for one GPU: 10 minutes or less on an H100 (docs/gpu.md).
    "gpu": JudgeTrainConfig(steps=8000, batch_size=256, lr=5e-4, warmup_steps=200, hard_negatives=0.5,
                            judge=JudgeConfig(width=256)),
}


def split_scenes(dataset: EpisodeDataset, config: JudgeTrainConfig) -> tuple[list[int], list[int], list[int]]:
    """(train, validation, held-out) episode indices, each scene in one part only."""
    train, heldout = split_episodes(dataset.episodes, config.heldout_fraction)

    def validation(i: int) -> bool:
        info = dataset.episodes[i]
        return zlib.crc32(f"validation/{info.task}/{info.seed}".encode()) % 10_000 < config.validation_fraction * 10_000

    return [i for i in train if not validation(i)], [i for i in train if validation(i)], heldout


class FramePool:
    """Every labelled frame of some videos, for drawing balanced batches of success and other frames.

    Frames `ambiguous` steps or fewer before a video's first success are left out: they barely
    differ from the success frame, and as negatives they teach the judge to doubt real successes.
    With `progress`, the labels are the frames' progress targets instead of 0/1 (the same balanced
    draw, so that the rare success frames are learned too).
    """

    def __init__(self, videos: list[Video], ambiguous: int, progress: bool = False) -> None:
        self.videos, self.progress = videos, progress
        positives, negatives = [], []
        for v, video in enumerate(videos):
            steps = torch.arange(1, len(video.frames))
            first = int(video.shows.float().argmax()) if video.shows.any() else len(video.frames) + ambiguous
            near = (steps >= first - ambiguous) & (steps < first)
            shows = video.shows[1:]
            positives.append(torch.stack([torch.full_like(steps, v), steps], 1)[shows])
            negatives.append(torch.stack([torch.full_like(steps, v), steps], 1)[~shows & ~near])
        empty = torch.zeros(0, 2, dtype=torch.int64)
        self.positives, self.negatives = torch.cat([empty, *positives]), torch.cat([empty, *negatives])  # (n, 2) (video, frame)
        if not len(self.positives) or not len(self.negatives):
            raise ValueError(f"judge training needs frames with and without success; got {len(self.positives)} "
                             f"success frames and {len(self.negatives)} others (a dataset's field 'next.success' "
                             "says which steps succeeded; without it only each episode's last step does)")

    def sample(self, batch: int, generator: torch.Generator, hard_share: float = 0.0, score: Scorer | None = None):
        """(B, H, W, 3) first frames, (B, H, W, 3) frames, B instructions and (B,) labels; half
        successes. `hard_share` of the negatives are those `score` rates highest of
        `HARD_CANDIDATES` times as many drawn at random."""
        count = batch // 2
        hard = round((batch - count) * hard_share)

        def draw(pool: torch.Tensor, n: int) -> torch.Tensor:
            return pool[torch.randint(len(pool), (n,), generator=generator)]

        pick = [draw(self.positives, count), draw(self.negatives, batch - count - hard)]
        if hard:
            candidates = draw(self.negatives, hard * HARD_CANDIDATES)
            pick.append(candidates[score(*self._frames(candidates)[:3]).topk(hard).indices.cpu()])
        firsts, frames, texts, progress = self._frames(torch.cat(pick))
        labels = torch.stack(progress) if self.progress else torch.arange(batch) < count
        return firsts, frames, texts, labels

    def _frames(self, chosen: torch.Tensor):
        """(N, H, W, 3) first frames, (N, H, W, 3) frames, N instructions and N progress targets of
        (N, 2) (video, frame) pairs."""
        firsts, frames, texts, progress = [], [], [], []
        for v, t in chosen.tolist():
            firsts.append(self.videos[v].frames[0])
            frames.append(self.videos[v].frames[t])
            texts.append(self.videos[v].instruction)
            progress.append(self.videos[v].progress[t])
        return torch.stack(firsts), torch.stack(frames), texts, progress


def _scorer(judge: FrameJudge) -> Scorer:
    """The judge's current logits, without gradients (to rank candidate negatives)."""
    def score(first: torch.Tensor, frames: torch.Tensor, texts: list[str]) -> torch.Tensor:
        with torch.no_grad():
            return judge(first, frames, judge.encoder(texts)).float()
    return score


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


def judge_datasets(data: Path, config: JudgeTrainConfig) -> tuple[list[EpisodeDataset], JudgeTrainConfig]:
    """The datasets a judge learns from (`data`, then `config.extra_data`), read with its cameras and
    keys and fitted to the model's image size, and `config` with that size, the cameras and the hold
    rule filled in; anything that reads a judge run's scenes again (its split: `split_scenes`) reads
    them with this, as training did.

    Raises:
        ValueError: the datasets' frames differ in shape.
    """
    datasets = [EpisodeDataset(path, config.camera, config.cameras or None, keys=config.keys)
                for path in (data, *config.extra_data)]
    for other in datasets[1:]:
        if other.camera_shape != datasets[0].camera_shape:
            raise ValueError(f"{other.root}: frames are {other.camera_shape}, but {data} has {datasets[0].camera_shape}")
    size = model_image_size(datasets[0].camera_shape, config.judge.image_size)
    config = dataclasses.replace(config, judge=dataclasses.replace(config.judge, image_size=size, cameras=datasets[0].cameras,
                                                                   hold_steps=config.hold_steps))
    return [dataset.fitted(size, config.fit) for dataset in datasets], config


def run_scene_videos(run: Path, part: int) -> list[Video]:
    """The real videos of a judge run's training (`part` 0), validation (1) or held-out (2) scenes,
    read as its training read them."""
    datasets, config = judge_datasets(Path(read_json(run / "config.json")["data"]), saved_judge_config(run))
    return [video for dataset in datasets for video in load_videos(dataset, split_scenes(dataset, config)[part], None, False)]


def train_judge(data: Path, out: Path, config: JudgeTrainConfig, wm: Path | None = None, resume: bool = False,
                progress: bool = True) -> dict:
    """Trains the judge in `out`, chooses its threshold on the validation scenes, writes
    `out/metrics.json` (held-out TPR/FPR) and returns it."""
    started = time.perf_counter()
    datasets, config = judge_datasets(data, config)
    parts = [split_scenes(dataset, config) for dataset in datasets]  # per dataset: (train, validation, held-out)
    train_ids, validation_ids, heldout_ids = ([p[k] for p in parts] for k in range(3))
    if not any(train_ids):
        raise ValueError(f"{data}: no scene is left to train on after holding out {config.heldout_fraction:g} and "
                         f"validating on {config.validation_fraction:g} of them; record more episodes")

    def videos(chosen: list[list[int]], show: bool) -> list[Video]:
        return [video for dataset, ids in zip(datasets, chosen) for video in load_videos(dataset, ids, wm, show, device)]

    device = resolve_device(config.device)
    train_videos = videos(train_ids, progress)
    judge = build_judge(config if not resume else dataclasses.replace(config, init=None)).to(device)
    optimizer = torch.optim.AdamW(judge.parameters(), lr=config.lr, weight_decay=0.01)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    settings = {**dataclasses.asdict(config), "extra_data": [str(path) for path in config.extra_data],
                "init": None if config.init is None else str(config.init)}
    resolved = {"train": settings, "model": judge.spec(), "data": str(data), "wm": str(wm) if wm else None}
    start, metrics = begin_training(out, resolved, judge, optimizer, schedule, sampler, resume,
                                    tracker=config.tracker, kind="train-judge")
    pool = FramePool(train_videos, config.ambiguous_steps, config.kind == "progress") if config.kind != "video" else None
    per_frame_loss = progress_loss if config.kind == "progress" else frame_loss
    hard_share = config.hard_negatives if config.kind == "frames" else 0.0  # the others have no verdict per frame
    score = _scorer(judge)
    judge.train()
    bar = tqdm(range(start, config.steps), initial=start, total=config.steps, desc="train-judge", disable=not progress)
    for step in bar:
        if pool is not None:
            first, frames, texts, labels = pool.sample(config.batch_size, sampler, hard_share, score)
            loss, values = per_frame_loss(judge, first, frames, judge.encoder(texts), labels)
        else:
            frames, texts, labels = _sample(train_videos, config.batch_size, config.whole_share, config.ambiguous_steps, sampler)
            loss, values = judge_loss(judge, frames, judge.encoder(texts), labels)
        values["train/grad_norm"] = gradient_step(loss, judge, optimizer, schedule)
        done = step + 1
        if done % config.log_every == 0 or done == config.steps:
            metrics.log(done, values)
            bar.set_postfix({name.removeprefix("train/"): f"{value:.3f}" for name, value in values.items()
                             if name in ("train/loss", "train/accuracy", "train/mae")})
        if done % config.checkpoint_every == 0 and done < config.steps:
            save_training(out, done, judge, resolved, optimizer, schedule, sampler)
    del train_videos, pool  # the held-out and validation videos take their place in memory
    judge.eval()
    threshold = {}  # a progress judge scores by degree: no threshold to choose
    if judge.binary:
        threshold = choose_threshold(judge, videos(validation_ids, show=False), config.threshold_tpr)
        judge.config = dataclasses.replace(judge.config, threshold=threshold["threshold"])
    resolved["model"] = judge.spec()
    write_run_config(out, resolved)
    save_training(out, config.steps, judge, resolved, optimizer, schedule, sampler)
    measure = evaluate_judge if judge.binary else evaluate_progress
    report = measure(judge, videos(heldout_ids, show=False))
    report |= {"kind": config.kind, **{f"validation_{k}": v for k, v in threshold.items()},
               "data": [str(path) for path in (data, *config.extra_data)], "wm": str(wm) if wm else None,
               "heldout_episodes": sum(map(len, heldout_ids)), "validation_episodes": sum(map(len, validation_ids)),
               "train_episodes": sum(map(len, train_ids)),
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(out / "metrics.json", report)
    # The held-out figures go to the trackers; metrics.json, not metrics.jsonl, is their record.
    metrics.tracker.log_metrics(config.steps, {f"eval/{key}": value for key, value in report.items()
                                               if isinstance(value, (int, float)) and not isinstance(value, bool)})
    metrics.close()
    return report


def build_judge(config: JudgeTrainConfig) -> LearnedJudge | FrameJudge:
    """The judge training starts from: seeded by `config.seed`, with `config.init`'s weights when given.

    Raises:
        FileNotFoundError: `config.init` has no checkpoint.
        ValueError: `config.init` is another kind of judge or has another architecture (the
            threshold and the steps it holds aside, which are this run's).
    """
    torch.manual_seed(config.seed)
    judge = JUDGES[config.kind](config.judge)
    if config.init is None:
        return judge
    source = load_judge(config.init)
    unthresholded = [dataclasses.replace(model.config, threshold=0.5, hold_steps=1) for model in (source, judge)]
    if source.backend != judge.backend or unthresholded[0] != unthresholded[1]:
        raise ValueError(f"--init {config.init}: a {source.backend} judge with {unthresholded[0]}, but this run trains "
                         f"a {judge.backend} judge with {unthresholded[1]}")
    judge.load_state_dict(source.state_dict())
    logger.info("starting from the weights of %s", config.init)
    return judge


def saved_judge_config(run: Path) -> JudgeTrainConfig:
    """The settings a run was started with (RUN/config.json), for ``--resume``; runs from before
    the per-frame judge trained the video judge, and those from before `hold_steps` believed a
    single frame."""
    return from_json(JudgeTrainConfig, {"kind": "video", "hold_steps": 1, **saved_settings(run, "train")})


def load_judge(run: Path) -> LearnedJudge | FrameJudge:
    """The newest checkpoint of a judge run (or a checkpoint directory), in eval mode.

    Raises:
        ValueError: the checkpoint names no judge backend this version knows.
    """
    classes = {judge.backend: judge for judge in JUDGES.values()}

    def build(spec: dict) -> LearnedJudge | FrameJudge:
        backend = spec.get("backend")
        if backend not in classes:
            raise ValueError(f"{run}: model.backend is {backend!r}; known judges: {sorted(classes)}")
        return classes[backend].from_spec(spec)

    return load_model(Path(run), build)
