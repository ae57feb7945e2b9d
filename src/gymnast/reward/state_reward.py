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

On a simulator's rollouts, which carry the real state after every action
(`RewardContext.env_states`), the reward head reads those instead of imagined ones: the reward
model on reality, without the state model's dynamics between it and the truth.

With an ensemble of state models (``gymnast make-ensemble`` over `gymnast train-state` runs of
different seeds), the predicted rewards are the members' mean, and success counts only where every
member predicts it: an imagined success that some member does not see is treated as likely
hallucinated and earns no bonus (WoVR masks GRPO's update there). The members' spread of the
scores is reported as ``reward/state_disagreement``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from gymnast.policy.text import InstructionEncoder
from gymnast.reward.base import RewardContext, RewardNeeds
from gymnast.world_model.state_model import StateModel, StateRollout


class StateReward:
    """`Reward` from the reward head of one state model or the mean of an ensemble's; reads
    `RewardContext.start_state`, ``start_action`` (zeros where absent) and ``actions``.

    Args:
        models: the trained state model(s) (`gymnast.world_model.state_model.load_state_models`).
        threshold: predicted success probability counted as success.
    """

    binary = False
    needs = RewardNeeds(start_state=True)

    def __init__(self, models: StateModel | Sequence[StateModel], threshold: float = 0.5) -> None:
        self.models = [models] if isinstance(models, StateModel) else list(models)
        if not self.models:
            raise ValueError("StateReward needs at least one state model")
        self.threshold = threshold
        self.encoder = InstructionEncoder()
        self._disagreement: float | None = None

    def metrics(self) -> dict[str, float]:
        """The members' spread of the last scores (ensembles only)."""
        return {} if self._disagreement is None else {"reward/state_disagreement": self._disagreement}

    def imagine(self, instructions: Sequence[str], context: RewardContext) -> list[StateRollout]:
        """Each member's rollout of `context.actions` (B, T, A) from `context.start_state` (B, S), or,
        where the context holds the real states (`RewardContext.env_states`), each member's reward
        head on those.

        Raises:
            ValueError: the context lacks them, or their shapes do not fit the models.
        """
        start, actions = context.start_state, context.actions
        if start is None or actions is None or start.ndim != 2 or start.shape[1] == 0:
            raise ValueError("the state reward needs RewardContext.start_state (B, S) and actions (B, T, A): "
                             "starts that carry their recorded state")
        config = self.models[0].config
        expected = (config.state_dim, config.action_dim)
        if (start.shape[1], actions.shape[-1]) != expected or actions.shape[0] != start.shape[0]:
            raise ValueError(f"start_state {tuple(start.shape)} and actions {tuple(actions.shape)} do not fit the state "
                             f"model's (B, {expected[0]}) states and (B, T, {expected[1]}) actions")
        embedding = self.encoder(list(instructions))
        if context.env_states is not None:
            if context.env_states.shape[-1] != config.state_dim:
                raise ValueError(f"the simulator's states {tuple(context.env_states.shape)} do not fit the state "
                                 f"model's (B, T, {config.state_dim})")
            real = _held_after_end(context.env_states.float(), start.float())  # (B, T, S)
            return [model.read(start, real, embedding) for model in self.models]
        return [model.imagine(start, actions, embedding, context.start_action) for model in self.models]

    def _succeeded(self, rollouts: list[StateRollout]) -> torch.Tensor:
        """(B, T) bool: success predicted by every member at this step or an earlier one."""
        agreed = torch.stack([r.success for r in rollouts]).amin(dim=0) > self.threshold
        return agreed.cummax(dim=1).values

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) the predicted dense return of each rollout (see the module docstring); frames unused."""
        return self._score(self.imagine(instructions, context), context.actions.shape[1])

    def verdict(self, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) 1.0 where every member predicts success at some step."""
        return self._verdict(self.imagine(instructions, context), context.actions.shape[1])

    def read(self, instructions: Sequence[str], context: RewardContext, horizons: Sequence[int]
             ) -> dict[int, tuple[torch.Tensor, torch.Tensor]]:
        """`score` and `verdict` of the rollouts cut after each of `horizons` actions, from one
        imagination of the whole: a state model steps causally, so its first h steps are those it
        imagines for the rollout cut there."""
        rollouts = self.imagine(instructions, context)
        return {h: (self._score(rollouts, h), self._verdict(rollouts, h)) for h in horizons}

    def step_rewards(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B, T) the members' mean predicted reward of each action (the largest from an agreed
        success on); `score` is their mean."""
        return self._member_steps(self.imagine(instructions, context), context.actions.shape[1]).mean(dim=0)

    def _member_steps(self, rollouts: list[StateRollout], steps: int) -> torch.Tensor:
        """(members, B, steps) each member's predicted reward per action, in [0, 1], 1 from an agreed success on."""
        succeeded = self._succeeded(rollouts)[:, :steps]
        return torch.stack([torch.where(succeeded, 1.0, r.rewards[:, :steps].clamp(0, 1)) for r in rollouts])

    def _score(self, rollouts: list[StateRollout], steps: int) -> torch.Tensor:
        """(B,) the members' mean predicted dense return over the first `steps` steps."""
        returns = self._member_steps(rollouts, steps).mean(dim=2)  # (members, B)
        if len(rollouts) > 1:
            self._disagreement = float(returns.std(dim=0).mean())
        return returns.mean(dim=0)

    def _verdict(self, rollouts: list[StateRollout], steps: int) -> torch.Tensor:
        return self._succeeded(rollouts)[:, :steps].any(dim=1).float()


def _held_after_end(states: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
    """(B, T, S) real states with each rollout's last state held after its end (NaN rows there),
    the start state before its first action where it took none: the world stays where it ended."""
    held = states.clone()
    previous = start
    for t in range(held.shape[1]):
        missing = ~torch.isfinite(held[:, t]).all(dim=-1)  # (B,)
        held[missing, t] = previous[missing]
        previous = held[:, t]
    return held

