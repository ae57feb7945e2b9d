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

import torch
from torch import nn

from gymnast.policy.text import EMBEDDING_DIM, InstructionEncoder
from gymnast.policy.vision import SmallCNN, to_float_image
from gymnast.reward.judges.base import JudgeConfig, ThresholdJudge, check_videos, labelled_loss
from gymnast.utils.device import to_device

JUDGED_FRAMES = 4


def judged_frame_indices(length: int) -> list[int]:
    """Which of a video's `length` frames the judge looks at: first, middle, last but one, last."""
    last = length - 1
    return [0, last // 2, max(0, last - 1), last]


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


def judge_loss(judge: LearnedJudge, frames: torch.Tensor, text: torch.Tensor, labels: torch.Tensor):
    """Binary cross-entropy of (B, F, H, W, 3) judged frames against (B,) labels; (loss, metrics)."""
    return labelled_loss(judge(frames, text), labels)
