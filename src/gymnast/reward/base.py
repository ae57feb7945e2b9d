"""The `Reward` contract: a score for each rollout's video, and what a reward declares it needs.

Legend: B rollouts, T frames, H/W image size, C' start frames, A action dimensions.

Frames are camera frames as the environments and world models produce them, (B, T, H, W, 3)
uint8, so a reward never needs to know where a video came from. A score of NaN means "could not
score" (a judge's malformed answer, a missing reference): RL leaves such rollouts out of its group
statistics and gives them zero advantage, rather than reading NaN as failure.

A reward also declares what it needs besides the video (`RewardNeeds`), so that a run checks its
env against it before it starts (`check_fits`) instead of failing mid-run or, worse, scoring
something else than it meant to.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch

from gymnast.envs.kinds import ENV_KINDS, EnvKind


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
        start_state: (B, S) float the recorded state each rollout started from (a grounded world
            model imagines on from it); S = 0 where the starts carry none.
        start_action: (B, A) float the action that led to each start (the last of its prefix; zeros
            at a first frame).
        actions: (B, T) float the actions each rollout executed (0 after its end).
        env_states: (B, T, E) float a simulator's full state after each action (NaN after the
            episode's end), or None where the rollout was imagined (or replayed in a world model).
    """

    start: torch.Tensor | None = None
    reference_actions: torch.Tensor | None = None
    success: torch.Tensor | None = None
    env_rewards: torch.Tensor | None = None
    start_state: torch.Tensor | None = None
    start_action: torch.Tensor | None = None
    actions: torch.Tensor | None = None
    env_states: torch.Tensor | None = None


@dataclass(frozen=True)
class RewardNeeds:
    """What a reward needs besides the instructions: the video (unless ``video`` is False) and more."""

    world_model: bool = False
    """It is built with a world model and scores only videos that model imagined (a real video
    against an imagined one would measure the model's errors, not the policy)."""
    simulator_success: bool = False
    """It reads a simulator's own outcome (`RewardContext.success`, ``env_rewards``)."""
    reference_actions: bool = False
    """It reads a demonstration's actions from each start (`RewardContext.reference_actions`)."""
    start_state: bool = False
    """It reads each rollout's recorded start state and actions (`RewardContext.start_state`,
    ``actions``): a grounded world model imagines the state on from there."""
    video: bool = True
    """It reads the rollouts' frames; False for a reward of the simulator's own outcome alone, so
    that a simulator need not render the frames inside each chunk when nothing else reads them."""


class Reward(Protocol):
    """Scores B rollouts."""

    binary: bool
    """Scores are 0/1 verdicts (success or not), not degrees: RL's dynamic sampling filters groups
    by their success rate only for binary rewards, and only a binary reward's score is a verdict."""

    needs: RewardNeeds
    """What it reads besides the video; `check_fits` holds it against an env."""

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) float32 scores for (B, T, H, W, 3) uint8 rollout videos; NaN where one cannot be scored."""
        ...

    def metrics(self) -> dict[str, float]:
        """What it counted so far (requests, retries, tokens...) as ``reward/...`` floats for the
        metrics log; empty for a reward that counts nothing."""
        ...


@runtime_checkable
class StepReward(Reward, Protocol):
    """A reward that scores every action of a rollout, not only the whole: the dense rewards
    (`SimDense`, the state model's reward head, the progress judge). RL's reward-to-go credit
    (`--credit reward-to-go`) gives each policy call the reward of what followed it."""

    def step_rewards(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B, T) float32 one reward per action, NaN for steps that do not count (after an episode
        ended without success); `score` is their mean over the steps that count."""
        ...


@runtime_checkable
class VerdictReward(Reward, Protocol):
    """A continuous reward that also reads a 0/1 verdict off what it scores (the state model's:
    success predicted at some step), so that its agreement with the real outcome can be measured."""

    def verdict(self, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) float 1.0 where the reward reads success, 0.0 where not."""
        ...


def read_verdict(reward: Reward, frames: torch.Tensor, instructions: Sequence[str],
                 context: RewardContext) -> torch.Tensor:
    """(B,) float the reward's 0/1 verdict on B rollouts, NaN where it could not score: a binary
    reward's score, or a `VerdictReward`'s own reading of success.

    Raises:
        ValueError: a continuous reward that reads no verdict (the verified reward, a progress judge).
    """
    if reward.binary:
        scores = reward.score(frames, instructions, context).float().reshape(-1)
        return (scores > 0.5).float().masked_fill(~torch.isfinite(scores), float("nan"))
    if isinstance(reward, VerdictReward):
        return reward.verdict(instructions, context).float().reshape(-1)
    raise ValueError(f"{type(reward).__name__} gives degrees, not a verdict of success")


def env_mismatch(needs: RewardNeeds, env: EnvKind, demonstrations: bool = True) -> str | None:
    """Why a reward that `needs` these cannot score rollouts of `env` (starting from scenes with
    `demonstrations` or not), or None when it can."""
    if needs.simulator_success and not env.reports_success:
        return f"it reads a simulator's own verdict, which --env {env} does not report"
    if needs.world_model and not env.imagined:
        return f"it compares videos imagined by its world model, which --env {env} does not imagine"
    if needs.reference_actions and not demonstrations:
        return "it reads a demonstration's actions from each start, and fresh scenes have none"
    return None


def check_fits(reward: Reward, name: str, env: EnvKind, demonstrations: bool = True) -> None:
    """Raises ValueError, naming the reward and the env, when `env` cannot give what `reward` needs.

    Args:
        reward: the reward, whose `needs` are checked.
        name: what the command line called it (``str(spec)``), for the message.
        env: the kind of env its rollouts run in.
        demonstrations: whether the starts carry a demonstration's actions (a dataset's scenes do,
            fresh scenes do not).
    """
    why = env_mismatch(reward.needs, env, demonstrations)
    if why is not None:
        fitting = " or ".join(kind.name for kind in ENV_KINDS.values() if env_mismatch(reward.needs, kind) is None)
        scenes = " from a dataset's scenes" if reward.needs.reference_actions else ""
        raise ValueError(f"--reward {name} cannot score rollouts of --env {env}: {why} (it fits --env {fitting}{scenes})")
