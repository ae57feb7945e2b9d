"""Simulator rewards, for RL in the software simulator and in the real world (the baselines).

They read what the simulator itself reported during the rollout (`RewardContext.success`,
`RewardContext.env_rewards`), never the video. World-Gymnast's software-simulator baseline needed
the dense one: with only success, whole groups of rollouts score the same and GRPO has no signal.

Legend: B rollouts, T steps.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from gymnast.reward.base import RewardContext, RewardNeeds

META_WORLD_MAX_STEP_REWARD = 10.0  # Meta-World v3 shapes every step's reward into [0, 10]


class SimSuccess:
    """`Reward`: 1.0 if the simulator reported success during the rollout, else 0.0."""

    binary = True
    needs = RewardNeeds(simulator_success=True, video=False)

    def metrics(self) -> dict[str, float]:
        return {}  # counts nothing

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        if context.success is None:
            raise ValueError("the sim reward needs RewardContext.success: the rollout must come from a simulator")
        return context.success.float().reshape(-1)


class SimDense:
    """`Reward`: Meta-World's dense reward, the mean over the horizon's steps scaled to [0, 1].

    An episode that ended in success has NaN rewards after its end; they count as the maximum
    step reward, as if the robot held the goal for the rest of the horizon. Otherwise hovering near
    the goal without finishing would pay more than finishing early (the episode stops at success).
    Steps after any other end are ignored.
    """

    binary = False
    needs = RewardNeeds(simulator_success=True, video=False)

    def metrics(self) -> dict[str, float]:
        return {}  # counts nothing

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        return torch.nanmean(self.step_rewards(frames, instructions, context), dim=1)

    def step_rewards(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B, T) each action's dense reward in [0, 1], the largest after a success, NaN after another end."""
        if context.env_rewards is None:
            raise ValueError("the dense sim reward needs RewardContext.env_rewards: the rollout must come from a simulator")
        rewards = context.env_rewards.float()  # (B, T)
        if context.success is not None:
            held = torch.isnan(rewards) & context.success.reshape(-1, 1).bool()
            rewards = torch.where(held, torch.full_like(rewards, META_WORLD_MAX_STEP_REWARD), rewards)
        return rewards / META_WORLD_MAX_STEP_REWARD
