"""What a run's reward sees, and how often its verdict holds in the real world as the policy moves.

Legend: R rollouts (= B starts x G), T actions, H/W image size.

A practice run is a composition of separate choices: what the policy sees and what steps its
rollouts (the run's env kind), who gives the reward (the `Reward`) and what the reward sees. The
last is `RewardSight`: the rollout's own video, or the same actions from the same start in another
world, replayed in the real world (the simulator's verdict on imagined actions) or re-imagined by
the world model (an imagined verdict on real actions). Swapping one choice at a time gives the
learning ladder (`gymnast.experiment.ladder`), which tells which part of imagination stops GRPO
from learning.

`RewardSight.truth` gives, for the first round of every step, the real outcome of the rollouts'
actions, so that the run logs how often the reward it trains on agrees with the real world
(`reward_truth_metrics`) while the policy moves, not only at step 0. Where the rollouts or the
reward's replays are real the outcome is known for every rollout at no cost; otherwise a few
groups are replayed in the real world, counted apart from training's interactions.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch

from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL, EnvKind
from gymnast.reward.base import Reward, VerdictReward, read_verdict
from gymnast.rl.evaluate import replay_actions
from gymnast.rl.rollout import Rollouts, reward_context


@dataclass
class RewardSight:
    """What the reward of a run reads, and where the truth it is held to comes from.

    Args:
        envs: the run's envs (the real world and the world model among what they can build).
        env: the kind the rollouts run in.
        sees: the world the reward's video comes from: None for the rollouts' own, else a kind the
            same actions are replayed in from the same starts (REAL: the simulator's outcome of
            imagined actions; IMAGINED: the world model's re-imagining of real actions).
        truth_groups: groups of each step's first round whose actions are replayed in the real
            world to measure the reward against the real outcome, where it is not known anyway
            (0: none).
        replays: where imagined replays run when not in `envs`' world model: another world model,
            which did not show the policy the frames it acted on, so that a policy practising in
            imagination is judged on a re-imagining whose errors it could not have chosen its
            actions by (None: `envs`').
        video: whether the reward reads the replays' video. False: a simulator's replay renders only
            the frame before each policy call (what re-anchoring reads, `gymnast.rl.reanchor`), the
            frames inside a chunk repeating it; its outcome is the same.
    """

    envs: EnvFactory
    env: EnvKind
    sees: EnvKind | None = None
    truth_groups: int = 0
    replays: EnvFactory | None = None
    video: bool = True

    def __post_init__(self) -> None:
        another_model = self.replays is not None and self.sees is not None and self.sees.imagined
        if self.sees is not None and self.sees.name == self.env.name and not another_model:
            raise ValueError(f"the reward sees the rollouts of --env {self.env} themselves: leave --reward-sees out "
                             f"instead of replaying them in {self.sees}")
        if self.sees is not None and self.sees.imagined and self.envs.world_model is None:
            raise ValueError("--reward-sees imagined re-imagines the actions in the world model: give it with --wm RUN")

    @property
    def real_replays(self) -> bool:
        """Whether the reward's replays are real interactions (counted as training's)."""
        return self.sees is not None and self.sees.real_interactions

    def seen(self, rollouts: Rollouts) -> tuple[Rollouts, int]:
        """The rollouts as the reward reads them, and the actions the replays took (0 for their own).

        A replay keeps the rollouts' starts, actions and lengths; its frames (one per action), and
        in a simulator its success and rewards, replace the rollouts' own.
        """
        if self.sees is None:
            return rollouts, 0
        where = self.replays if self.replays is not None and self.sees.imagined else self.envs
        replay = replay_actions(where.get(self.sees, len(rollouts.starts)), rollouts.starts, rollouts.actions,
                                rollouts.lengths, every_frame=self.video)
        replayed = dataclasses.replace(rollouts, rendered=replay.frames, hold=1, success=replay.success,
                                       env_rewards=replay.rewards, disagreement=None, env_states=None)
        return replayed, replay.interactions

    def truth(self, rollouts: Rollouts, seen: Rollouts, size: int) -> tuple[torch.Tensor, int]:
        """(R,) float the real outcome (1/0) of each rollout's actions, NaN where not measured, and
        the real actions spent measuring it (0 where the outcome was known anyway).

        Args:
            rollouts: the round's rollouts, groups of `size` in order.
            seen: the same rollouts as the reward saw them (`seen`).
            size: G, rollouts per group.
        """
        if self.env.real_interactions:
            return rollouts.success.float(), 0
        if self.real_replays:
            return seen.success.float(), 0
        truth = torch.full((len(rollouts.starts),), float("nan"))
        groups = len(rollouts.starts) // size
        count = min(self.truth_groups, groups)
        if count == 0:
            return truth, 0
        chosen = torch.linspace(0, groups - 1, count).round().long()  # groups spread over the batch's tasks
        index = (chosen[:, None] * size + torch.arange(size)[None]).reshape(-1)  # (count * G,)
        picked = rollouts.select(index)
        replay = replay_actions(self.envs.get(REAL, len(index)), picked.starts, picked.actions, picked.lengths,
                                every_frame=False)  # the outcome alone is read
        truth[index] = replay.success.float()
        return truth, replay.interactions


def reward_verdicts(reward: Reward, seen: Rollouts, scores: torch.Tensor, size: int) -> torch.Tensor:
    """(R,) the reward's own 0/1 verdict on each rollout as it saw it, NaN where it gives none.

    A binary reward's score is its verdict; a continuous reward with a success reading (the state
    model's, `VerdictReward`) is asked for it, a group at a time as it was scored; a simulator's
    dense reward reads the simulator's success. A continuous reward without one (verified, a
    progress judge) gives no verdict.
    """
    if reward.binary:
        return (scores > 0.5).float().masked_fill(~torch.isfinite(scores), float("nan"))
    if isinstance(reward, VerdictReward):
        parts = []
        for first in range(0, len(seen.starts), size):
            block = seen.select(torch.arange(first, min(first + size, len(seen.starts))))
            parts.append(read_verdict(reward, block.rendered, block.instructions, reward_context(block)))
        return torch.cat(parts)
    if reward.needs.simulator_success and seen.success is not None:
        return seen.success.float()
    return torch.full_like(scores, float("nan"), dtype=torch.float32)


def reward_truth_metrics(verdict: torch.Tensor, truth: torch.Tensor, scores: torch.Tensor,
                         size: int) -> dict[str, float]:
    """How the reward the policy trains on agrees with the real outcome of the same rollouts.

    Args:
        verdict: (R,) the reward's 0/1 verdicts (`reward_verdicts`), NaN where it gives none.
        truth: (R,) the real outcomes (`RewardSight.truth`), NaN where not measured.
        scores: (R,) the reward's scores, what GRPO normalises within groups of `size`.
        size: G, rollouts per group.

    Returns:
        ``reward/truth_rollouts`` (rollouts whose real outcome is known), ``reward/truth_success``
        (their real success); where the reward gives verdicts, ``reward/agreement`` (verdict equals
        the real outcome), ``reward/false_success`` (the share of its successes that fail for
        real) and ``reward/missed_success`` (the share of real successes it calls failures); and
        ``reward/truth_signal``: the correlation of the group-normalised scores (GRPO's advantages)
        with the group-centred real outcomes, over groups where both vary: does practice on this
        reward push the policy where the real world would.
    """
    known = torch.isfinite(truth)
    values = {"reward/truth_rollouts": float(known.sum())}
    if not known.any():
        return values
    real = truth[known] > 0.5
    values["reward/truth_success"] = real.float().mean().item()
    judged = known & torch.isfinite(verdict)
    if judged.any():
        said, outcome = verdict[judged] > 0.5, truth[judged] > 0.5
        values["reward/agreement"] = (said == outcome).float().mean().item()
        if said.any():
            values["reward/false_success"] = (said & ~outcome).float().sum().item() / int(said.sum())
        if outcome.any():
            values["reward/missed_success"] = (~said & outcome).float().sum().item() / int(outcome.sum())
    signal = _advantage_truth_correlation(scores, truth, size)
    if signal is not None:
        values["reward/truth_signal"] = signal
    return values


def _advantage_truth_correlation(scores: torch.Tensor, truth: torch.Tensor, size: int) -> float | None:
    """Pearson correlation of group-normalised scores with group-centred real outcomes, pooled over
    the complete groups whose scores and outcomes both vary; None where there are none."""
    grouped_scores, grouped_truth = scores.view(-1, size).float(), truth.view(-1, size)
    usable = (torch.isfinite(grouped_scores).all(1) & torch.isfinite(grouped_truth).all(1)
              & (grouped_scores.std(1) > 0) & (grouped_truth.std(1) > 0))
    if not usable.any():
        return None
    s, t = grouped_scores[usable], grouped_truth[usable]
    advantages = ((s - s.mean(1, keepdim=True)) / s.std(1, keepdim=True)).reshape(-1)
    centred = (t - t.mean(1, keepdim=True)).reshape(-1)
    if len(advantages) < 3:
        return None
    return torch.corrcoef(torch.stack([advantages, centred]))[0, 1].item()
