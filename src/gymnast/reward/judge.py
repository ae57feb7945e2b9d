"""The embedded learned judge: a few frames of a video and the instruction in, P(success) out.

Legend: B videos, T frames, F frames the judge looks at, H/W image size, D feature width.

The judge looks at F = 4 frames: the first (what the scene and task were), one from the middle,
and the last two (where success shows, and whether it holds). Each goes through the small CNN of
the policy (`gymnast.policy.vision.SmallCNN`), is pooled to one vector and tagged with its
position; the instruction's MiniLM embedding joins them, and an MLP gives the logit.

Training examples are episode *prefixes*: a video cut at step t is labelled by whether the
episode had succeeded by t (the dataset records success per step). Cutting successful episodes
before their success gives true negatives that look almost like positives, the hard case a judge
of RL rollouts meets (the arm near the goal, not quite there). With a world model, each episode
is also re-imagined from its first frame under its real actions and labelled with the real
outcome, so the judge learns to see through imagined artifacts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from gymnast.policy.text import EMBEDDING_DIM, InstructionEncoder
from gymnast.policy.vision import SmallCNN, to_float_image
from gymnast.reward.base import RewardContext, RewardNeeds
from gymnast.utils.device import to_device

JUDGED_FRAMES = 4


def judged_frame_indices(length: int) -> list[int]:
    """Which of a video's `length` frames the judge looks at: first, middle, last but one, last."""
    last = length - 1
    return [0, last // 2, max(0, last - 1), last]


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

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", tuple(self.cameras))  # a list when read back from JSON


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


class LearnedJudge(ThresholdJudge, nn.Module):
    """`Reward` whose score is 1.0 when P(success) >= the threshold (see `probability` for the raw value)."""

    backend = "embedded-judge"

    def __init__(self, config: JudgeConfig = JudgeConfig()) -> None:
        super().__init__()
        if len(config.cameras) > 1:
            raise ValueError(f"the video judge sees one camera, not {','.join(config.cameras)}; "
                             "the per-frame judges (--kind frames or progress) see several")
        self.config = config
        self.vision = SmallCNN(config.width)
        self.position = nn.Parameter(torch.zeros(JUDGED_FRAMES, config.width))
        self.text = nn.Linear(EMBEDDING_DIM, config.width)
        self.head = nn.Sequential(nn.Linear((JUDGED_FRAMES + 1) * config.width, 256), nn.GELU(), nn.Linear(256, 1))
        self.encoder = InstructionEncoder()

    def forward(self, frames: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        """(B, F, H, W, 3) uint8 judged frames and (B, 384) instruction embeddings -> (B,) logits."""
        batch, device = frames.shape[0], self.position.device
        features = self.vision(to_float_image(to_device(frames.flatten(0, 1), device))).mean(dim=1)  # (B*F, D)
        features = features.view(batch, JUDGED_FRAMES, -1) + self.position  # (B, F, D)
        return self.head(torch.cat([features.flatten(1), self.text(to_device(text, device))], dim=1)).squeeze(1)

    @torch.no_grad()
    def probability(self, videos: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        """(B,) P(success) for (B, T, H, W, 3) uint8 videos."""
        check_videos(videos, instructions)
        picked = videos[:, judged_frame_indices(videos.shape[1])]  # (B, F, H, W, 3)
        return torch.sigmoid(self(picked, self.encoder(instructions))).cpu()

def check_videos(videos: torch.Tensor, instructions: Sequence[str]) -> None:
    """Raises ValueError unless `videos` is (B, T, H, W, 3) uint8 with B instructions."""
    if videos.ndim != 5 or videos.dtype != torch.uint8 or videos.shape[-1] != 3:
        raise ValueError(f"videos must be (B, T, H, W, 3) uint8, got {tuple(videos.shape)} {videos.dtype}")
    if len(instructions) != videos.shape[0]:
        raise ValueError(f"{videos.shape[0]} videos need as many instructions, got {len(instructions)}")


def judge_loss(judge: LearnedJudge, frames: torch.Tensor, text: torch.Tensor, labels: torch.Tensor):
    """Binary cross-entropy of (B, F, H, W, 3) judged frames against (B,) labels; (loss, metrics)."""
    return labelled_loss(judge(frames, text), labels)


def labelled_loss(logits: torch.Tensor, labels: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """Binary cross-entropy of (N,) logits, on the judge's device, against (N,) 0/1 labels from the
    host; (loss, {"train/loss", "train/accuracy"})."""
    labels = to_device(labels, logits.device)
    loss = F.binary_cross_entropy_with_logits(logits, labels.float())
    accuracy = ((logits > 0) == labels.bool()).float().mean()
    return loss, {"train/loss": loss.item(), "train/accuracy": accuracy.item()}
