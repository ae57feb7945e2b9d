"""The verified reward of VLA-RFT: how close is the policy's imagined future to the expert's?

Legend: B rollouts, T frames, H/W image size, A action dimensions.

From the same real start frame the world model is rolled out twice, each conditioned step by step
on its own actions: once under the policy's actions (the rollout being scored, `frames`) and once
under the reference actions recorded in the dataset. The reward is

    r = -(mean |policy frame - reference frame| + mean perceptual distance)

over the first min(T, T_ref) frames (pixels in [0, 1]; the perceptual distance is
`gymnast.world_model.metrics.PerceptualDistance`, LPIPS-like on ImageNet EfficientNet-Lite0
features, since LPIPS's own weights cannot be downloaded here). Identical actions give 0, and the
reward falls as the actions diverge. Comparing imagined with imagined (not with real frames)
cancels the world model's own errors, which VLA-RFT found to matter most.

Where it departs from the paper: the paper's public code appears to condition the reference
rollout on the first action chunk only; here it is conditioned on every reference action, as the
paper describes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from gymnast.reward.base import RewardContext, RewardNeeds
from gymnast.world_model.base import WorldModel, rollout
from gymnast.world_model.metrics import PerceptualDistance, to_unit_float


class VerifiedReward:
    """`Reward` that compares a rollout with the world model's rollout of the reference actions.

    Reads `RewardContext.start` and `RewardContext.reference_actions`. A rollout whose reference
    has no actions scores NaN.

    Args:
        model: the world model that imagined the policy's rollouts (the same one, or the
            comparison would measure two models' differences).
        perceptual: the perceptual distance (built once; loading it takes a second).
    """

    binary = False
    needs = RewardNeeds(world_model=True, reference_actions=True)

    def __init__(self, model: WorldModel, perceptual: PerceptualDistance | None = None) -> None:
        self.model = model
        self.perceptual = perceptual or PerceptualDistance()

    def metrics(self) -> dict[str, float]:
        return {}  # counts nothing

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        if context.start is None or context.reference_actions is None:
            raise ValueError("the verified reward needs RewardContext.start and RewardContext.reference_actions")
        batch, steps = frames.shape[:2]
        if context.start.shape[0] != batch or context.reference_actions.shape[0] != batch:
            raise ValueError(f"frames {tuple(frames.shape)}, start {tuple(context.start.shape)} and reference_actions "
                             f"{tuple(context.reference_actions.shape)} must have the same batch size")
        overlap = min(steps, context.reference_actions.shape[1])
        if overlap == 0:
            return torch.full((batch,), float("nan"))
        references, index = self._references(context.start, context.reference_actions[:, :overlap].float())
        policy, expert = to_unit_float(frames[:, :overlap]), to_unit_float(references)  # (B|U, T, 3, H, W)
        pixel = (policy - expert[index]).abs().mean(dim=(1, 2, 3, 4))
        perceptual = self.perceptual.against_references(policy, expert, index).mean(dim=1)
        return -(pixel + perceptual)

    def _references(self, start: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(U, T, H, W, 3) the distinct reference rollouts, each distinct (start, actions) imagined
        once, and (B,) which one each rollout compares with: a GRPO group shares its start and
        reference, so this saves G - 1 of every G imagined references (and their perceptual features)."""
        keys = torch.cat([start.reshape(len(start), -1).float(), actions.reshape(len(actions), -1)], dim=1)
        unique, index = torch.unique(keys, dim=0, return_inverse=True)
        first = torch.zeros(len(unique), dtype=torch.long).scatter_(0, index.flip(0), torch.arange(len(keys)).flip(0))
        return rollout(self.model, start[first], actions=actions[first]).frames, index
