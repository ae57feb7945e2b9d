"""What the learned judges share: their architecture settings, the 0/1 verdict from P(success) and
a threshold, the check of their inputs and their loss."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F

from gymnast.reward.base import RewardContext, RewardNeeds
from gymnast.utils.device import to_device


@dataclass(frozen=True)
class JudgeConfig:
    """Architecture of the learned judge."""

    width: int = 128
    """Feature width D."""
    image_size: int = 96
    """Frame height and width (of each camera's view)."""
    threshold: float = 0.5
    """P(success) from which a video counts as a success (`gymnast train-judge` chooses it on
    validation scenes)."""
    cameras: tuple[str, ...] = ("front",)
    """The cameras the judge sees, side by side in each frame, the primary first (their names in
    the datasets it was trained on)."""
    hold_steps: int = 1
    """Per-frame judge: steps in a row that must show the task done for a video to count as a
    success, a run reaching the video's last frame counting as held (the scene as it stays). 1
    believes any single frame (judges saved without this setting); `gymnast train-judge` sets its
    own (`JudgeTrainConfig.hold_steps`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", tuple(self.cameras))  # a list when read back from JSON
        if self.hold_steps < 1:
            raise ValueError(f"JudgeConfig.hold_steps must be at least 1, got {self.hold_steps}")


class ThresholdJudge:
    """What the learned judges share as a `Reward`: a 0/1 verdict from their P(success)
    (`probability`) and the threshold in their settings, and a spec that rebuilds them."""

    backend: str
    config: JudgeConfig
    binary = True
    needs = RewardNeeds()  # the video and the instructions only

    def probability(self, videos: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor: ...

    def metrics(self) -> dict[str, float]:
        return {}  # counts nothing

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext | None = None) -> torch.Tensor:
        """1.0 where the judge says success (P >= the threshold), else 0.0."""
        return (self.probability(frames, instructions) >= self.config.threshold).float()

    def spec(self) -> dict:
        return {"backend": self.backend, **asdict(self.config)}

    @classmethod
    def from_spec(cls, spec: dict):
        return cls(JudgeConfig(**{k: v for k, v in spec.items() if k != "backend"}))


def check_judge_sees(reward, cameras: Sequence[str], image_size: int, judge: str, source: str) -> None:
    """Raises ValueError unless a learned judge scores what `source` shows: the views of `cameras`
    side by side (() or one name: one camera, whatever its name), each `image_size` pixels square.

    Said before a run starts rather than at its first video; a reward other than a learned judge
    (a VLM, the simulator's, the verified reward) is not checked here.
    """
    for member in getattr(reward, "members", [reward]):  # a consensus: each of its judges
        if not isinstance(member, ThresholdJudge):
            continue
        config = member.config
        if _several(cameras) != _several(config.cameras) or image_size != config.image_size:
            raise ValueError(f"the judge {judge} scores {_views(config.cameras, config.image_size)}, but {source} "
                             f"shows {_views(cameras, image_size)}; train a judge on those views (`gymnast train-judge "
                             "--cameras` on a dataset recorded at that size) or give another --reward")


def _several(cameras: Sequence[str]) -> tuple[str, ...]:
    """The cameras by name where there are several; () for one camera, whatever its name."""
    return tuple(cameras) if len(cameras) > 1 else ()


def _views(cameras: Sequence[str], size: int) -> str:
    return f"{','.join(cameras) if len(cameras) > 1 else 'one camera'} at {size} px"


def check_videos(videos: torch.Tensor, instructions: Sequence[str]) -> None:
    """Raises ValueError unless `videos` is (B, T, H, W, 3) uint8 with B instructions."""
    if videos.ndim != 5 or videos.dtype != torch.uint8 or videos.shape[-1] != 3:
        raise ValueError(f"videos must be (B, T, H, W, 3) uint8, got {tuple(videos.shape)} {videos.dtype}")
    if len(instructions) != videos.shape[0]:
        raise ValueError(f"{videos.shape[0]} videos need as many instructions, got {len(instructions)}")


def labelled_loss(logits: torch.Tensor, labels: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """Binary cross-entropy of (N,) logits, on the judge's device, against (N,) 0/1 labels from the
    host; (loss, {"train/loss", "train/accuracy"})."""
    labels = to_device(labels, logits.device)
    loss = F.binary_cross_entropy_with_logits(logits, labels.float())
    accuracy = ((logits > 0) == labels.bool()).float().mean()
    return loss, {"train/loss": loss.item(), "train/accuracy": accuracy.item()}
