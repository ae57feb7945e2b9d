"""A grounded world model's own reward: the task's progress read off the imagined state.

Legend: B rollouts, T actions, S state dimensions, A action dimensions.

The video model imagines the frames the policy acts on; the state model
(`gymnast.world_model.state_model`) imagines, from the rollout's real start state and under the
same actions, where the robot and the objects go, and its reward head says what that is worth.
A pixel judge has to see centimetres in a 96 px frame of a blurring imagined arm; this reward
reads them from a state that training held to the recorded one (docs/world_model.md measures
both on the signal RL receives).

The score is the predicted dense reward as `gymnast.reward.sim.SimDense` scores a real rollout:
the mean per-step reward in units of Meta-World's largest, each step from the first predicted
success on counting as the largest. `verdict` gives the 0/1 reading: success predicted at any step.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from gymnast.policy.text import InstructionEncoder
from gymnast.reward.base import RewardContext, RewardNeeds
from gymnast.world_model.state_model import StateModel, StateRollout


class StateReward:
    """`Reward` from a state model's reward head; reads `RewardContext.start_state`, ``start_action``
    (zeros where absent) and ``actions``.

    Args:
        model: the trained state model.
        threshold: predicted success probability counted as success.
    """

    binary = False
    needs = RewardNeeds(start_state=True)

    def __init__(self, model: StateModel, threshold: float = 0.5) -> None:
        self.model, self.threshold = model, threshold
        self.encoder = InstructionEncoder()

    def metrics(self) -> dict[str, float]:
        return {}  # counts nothing

    def imagine(self, instructions: Sequence[str], context: RewardContext) -> StateRollout:
        """The state model's rollout of `context.actions` (B, T, A) from `context.start_state` (B, S).

        Raises:
            ValueError: the context lacks them, or their shapes do not fit the model.
        """
        start, actions = context.start_state, context.actions
        if start is None or actions is None or start.ndim != 2 or start.shape[1] == 0:
            raise ValueError("the state reward needs RewardContext.start_state (B, S) and actions (B, T, A): "
                             "starts that carry their recorded state")
        expected = (self.model.config.state_dim, self.model.config.action_dim)
        if (start.shape[1], actions.shape[-1]) != expected or actions.shape[0] != start.shape[0]:
            raise ValueError(f"start_state {tuple(start.shape)} and actions {tuple(actions.shape)} do not fit the state "
                             f"model's (B, {expected[0]}) states and (B, T, {expected[1]}) actions")
        return self.model.imagine(start, actions, self.encoder(list(instructions)), context.start_action)

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) the predicted dense return of each rollout (see the module docstring); frames unused."""
        imagined = self.imagine(instructions, context)
        succeeded = (imagined.success > self.threshold).cummax(dim=1).values  # (B, T)
        return torch.where(succeeded, 1.0, imagined.rewards.clamp(0, 1)).mean(dim=1)

    def verdict(self, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) 1.0 where success is predicted at any step."""
        return (self.imagine(instructions, context).success > self.threshold).any(dim=1).float()
