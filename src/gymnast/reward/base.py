"""The `Reward` contract: a score for each rollout's video.

Legend: B rollouts, T frames, H/W image size, C' start frames, A action dimensions.

Frames are camera frames as the environments and world models produce them, (B, T, H, W, 3)
uint8, so a reward never needs to know where a video came from. A score of NaN means "could not
score" (a judge's malformed answer, a missing reference): RL leaves such rollouts out of its group
statistics and gives them zero advantage, rather than reading NaN as failure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import torch


@dataclass(frozen=True)
class RewardContext:
    """What a reward may need besides the video; each reward documents which fields it reads.

    Attributes:
        start: (B, C', H, W, 3) uint8 the real frames each rollout started from.
        reference_actions: (B, T_ref, A) float the dataset's actions from the same start (the
            verified reward imagines them); T_ref may differ from the rollout's T.
        success: (B,) bool whether a simulator reported success (software sim or real world).
        env_rewards: (B, T) float the simulator's per-step rewards; steps after an episode ended
            are NaN.
    """

    start: torch.Tensor | None = None
    reference_actions: torch.Tensor | None = None
    success: torch.Tensor | None = None
    env_rewards: torch.Tensor | None = None


class Reward(Protocol):
    """Scores B rollouts."""

    binary: bool
    """Scores are 0/1 verdicts (success or not), not degrees: RL's dynamic sampling filters groups
    by their success rate only for binary rewards."""

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) float32 scores for (B, T, H, W, 3) uint8 rollout videos; NaN where one cannot be scored."""
        ...
